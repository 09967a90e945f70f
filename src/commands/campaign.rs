//! `talus campaign EPOCH... --out DIR` (SPEC.md §5): one plan for the whole campaign — each
//! survey tiled once on one tile grid, one parameter set derived from the first survey, one set of
//! core points (the first survey thinned) so that every core point has a time series, a `compare`
//! unit chain per pair, and the campaign unit over them — executed and published like `compare`.
//! Appending a survey and running again with `--resume` computes only what the new survey adds:
//! the grid, the parameters and the core points come from what does not change (the surveys'
//! union, the first survey), and every other unit's key is what it was. DIR, the store, executing
//! and publishing: `super::run`, as for `compare`.

use std::path::{Path, PathBuf};

use super::run::{
    keeps_decoded_of, measure_spacing, stable_areas, survey, tiling_part, RunOptions,
};
use crate::campaign::epochs::{self, EpochEntry};
use crate::error::{Error, Result};
use crate::params::{Params, UserParams};
use crate::plan::inputs::SurveyFiles;
use crate::plan::{Layout, Pair, Plan};
use crate::store::Store;

/// Everything `campaign` needs.
#[derive(Debug, Clone, Default)]
pub struct CampaignOptions {
    pub epochs: Vec<PathBuf>,
    pub out: PathBuf,
    pub config: Option<PathBuf>,
    pub user: UserParams,
    /// Each later epoch against the first too.
    pub baseline: bool,
    pub resume: bool,
    pub force: bool,
    /// Force the tile side (tests); None = plan from the memory budget.
    pub tile_size: Option<f64>,
    /// Keep the intermediate units' files after the run (`--keep-units`).
    pub keep_units: bool,
    /// Points a tiling unit reads at most (`--tiling-part`); None: `plan::TILING_PART` on
    /// Slurm, the whole survey locally (`run::tiling_part`).
    pub tiling_part: Option<u64>,
    /// Each pair's m3c2.laz and terrain positions of its own (`--pair-clouds`): the pairs are
    /// exactly compare's outputs, at about twice a campaign's disk.
    pub pair_clouds: bool,
    /// Where the units run (SPEC.md §6).
    pub executor: crate::exec::Executor,
}

/// What a finished campaign reports on the terminal.
pub struct Done {
    pub(crate) surveys: usize,
    pub(crate) pairs: usize,
    pub(crate) summary: serde_json::Value,
}

/// The epochs of the config file's `[[epoch]]` entries (paths relative to the config's folder).
fn entries(path: &Path, table: &toml::Table) -> Result<Vec<EpochEntry>> {
    let Some(v) = table.get("epoch") else {
        return Ok(Vec::new());
    };
    let list: Vec<EpochEntry> = v.clone().try_into().map_err(|e: toml::de::Error| {
        Error::input(path, format!("bad [[epoch]]: {}", e.message()))
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    Ok(list
        .into_iter()
        .map(|mut e| {
            if e.path.is_relative() && !e.path.exists() {
                e.path = base.join(&e.path);
            }
            e
        })
        .collect())
}

/// Run a campaign; None when it was submitted to Slurm and not waited for.
pub fn campaign(opts: &CampaignOptions) -> Result<Option<Done>> {
    let (config, entries) = match &opts.config {
        Some(p) => {
            let (u, rest) = UserParams::from_toml_file_with(p, &["epoch"])?;
            (u, entries(p, &rest)?)
        }
        None => (UserParams::default(), Vec::new()),
    };
    let user = opts.user.clone().over(config);
    let epochs = epochs::epochs(&opts.epochs, &entries, opts.config.as_deref())?;
    // Every survey's headers, checked before anything is written.
    let files: Vec<SurveyFiles> = epochs
        .iter()
        .map(|e| SurveyFiles::open(&e.arg))
        .collect::<Result<_>>()?;
    let first = files[0].bounds();
    for (e, f) in epochs.iter().zip(&files).skip(1) {
        if !first.overlaps_xy(&f.bounds()) {
            return Err(Error::input(
                &e.arg,
                format!(
                    "does not overlap the first survey ({}): a campaign compares surveys of one site",
                    epochs[0].arg.display()
                ),
            ));
        }
    }
    Params::resolve(&user, 1.0)?;
    let bounds: Vec<_> = files.iter().map(|f| f.bounds()).collect();
    user.check_lengths_within(&bounds)?;
    let given: Vec<&Path> = files
        .iter()
        .flat_map(|f| f.infos.iter().map(|i| i.path.as_path()))
        .collect();
    let run = RunOptions {
        out: &opts.out,
        resume: opts.resume,
        force: opts.force,
        executor: &opts.executor,
        ours: &crate::units::campaign::is_output,
    };
    let summary: Option<serde_json::Value> = super::run::run(&run, &given, |store, decoded| {
        plan(store, opts, &user, &epochs, &files, decoded)
    })?;
    let Some(summary) = summary else {
        return Ok(None);
    };
    Ok(Some(Done {
        surveys: epochs.len(),
        pairs: summary["pairs"].as_array().map_or(0, |p| p.len()),
        summary,
    }))
}

fn plan(
    store: &Store,
    opts: &CampaignOptions,
    user: &UserParams,
    epochs: &[epochs::Epoch],
    files: &[SurveyFiles],
    decoded: &mut Option<crate::io::replay::Replay>,
) -> Result<Plan> {
    // One parameter set: from the first survey, which an appended survey does not change.
    let (spacing, density_grid) = measure_spacing(
        store,
        files[0].first(),
        user,
        keeps_decoded_of(
            opts.resume,
            &opts.executor,
            &files[0],
            tiling_part(opts.tiling_part, &opts.executor),
        )
        .then_some(decoded),
    )?;
    let params = Params::resolve(user, spacing.effective_spacing)?;
    params.check_core_spacing(user)?;
    let surveys = epochs
        .iter()
        .zip(files)
        .map(|(e, f)| {
            let mut s = survey(store, &e.label, f)?;
            s.date = Some(e.date.iso());
            Ok(s)
        })
        .collect::<Result<Vec<_>>>()?;
    // One tile grid over every survey, for two of the densest surveys at once, and one
    // core-point lattice from the first survey (its core points are every pair's).
    let bounds: Vec<_> = files.iter().map(|f| f.bounds()).collect();
    let densest = files
        .iter()
        .map(|f| {
            let b = f.bounds();
            f.points() as f64 / ((b.max[0] - b.min[0]) * (b.max[1] - b.min[1])).max(1e-9)
        })
        .fold(0.0, f64::max);
    // The first survey's density grid, scaled to two of the largest surveys at once.
    let most = files.iter().map(|f| f.points()).max().unwrap_or(0) as f64;
    let density =
        crate::plan::layout::tile_density(&density_grid, 2.0 * most, 2.0 * densest, &params);
    let layout = Layout::plan(&bounds, &bounds[0], density, &params, opts.tile_size)?;
    let pairs = epochs::pairs(epochs.len(), opts.baseline)
        .into_iter()
        .map(|(b, a)| Pair {
            label: format!("{}_{}", epochs[b].label, epochs[a].label),
            before: b,
            after: a,
        })
        .collect();
    let mut plan = Plan::new(surveys, pairs, params, spacing, layout);
    plan.keep_units = opts.keep_units;
    plan.tiling_part = tiling_part(opts.tiling_part, &opts.executor);
    plan.lean_pairs = !opts.pair_clouds;
    plan.stable_areas = stable_areas(store, user, &plan.surveys)?;
    // The core points are the first survey's: within its bounds.
    let what = format!("the core points (from {})", epochs[0].arg.display());
    crate::plan::reach::check(&plan, Some((&what, &bounds[0])))?;
    crate::units::stage::plan_units(
        &mut plan,
        crate::units::stage::CoreSource::Campaign,
        Some("campaign"),
    )?;
    Ok(plan)
}
