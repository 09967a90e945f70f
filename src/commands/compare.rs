//! `talus compare`: a one-pair plan (SPEC.md §2, §3), executed in this process and published.
//!
//! 1. check the inputs (headers, counts, overlap, meshes) and the user's values, before anything
//!    is written;
//! 2. measure the point spacing, resolve the parameters, key every input by its content, plan the
//!    tiles and the units;
//!
//! in the lifecycle every planned command shares (`super::run`: DIR and its store, the plan
//! written, executed and published).

use std::path::{Path, PathBuf};

use super::run::{
    input_file, keeps_decoded_of, measure_spacing, stable_areas, survey, tiling_part, RunOptions,
};
use crate::error::{Error, Result};
use crate::io::{self, CloudInfo};
use crate::params::{Params, UserParams};
use crate::plan::inputs::SurveyFiles;
use crate::plan::{Layout, Pair, Plan};
use crate::store::Store;
use crate::units::outputs::{is_output, Summary};
use crate::units::stage::{plan_units, CoreSource};

/// Everything `compare` needs.
#[derive(Debug, Clone, Default)]
pub struct CompareOptions {
    pub before: PathBuf,
    pub after: PathBuf,
    pub out: PathBuf,
    pub config: Option<PathBuf>,
    pub core_points: Option<PathBuf>,
    pub user: UserParams,
    pub resume: bool,
    pub force: bool,
    pub before_mesh: Option<PathBuf>,
    pub after_mesh: Option<PathBuf>,
    /// Force the tile side (tests of tiling invariance); None = plan from the memory budget.
    pub tile_size: Option<f64>,
    /// Stop after M3C2: m3c2.laz (without smoothed values and event ids), summary.json and the
    /// viewer's terrain; no events, volumes or meshes.
    pub m3c2_only: bool,
    /// Keep the intermediate units' files after the run (`--keep-units`).
    pub keep_units: bool,
    /// Points a tiling unit reads at most (`--tiling-part`); None: `plan::TILING_PART` on
    /// Slurm, the whole survey locally (`run::tiling_part`).
    pub tiling_part: Option<u64>,
    /// Where the units run (SPEC.md §6).
    pub executor: crate::exec::Executor,
}

/// The headers of the inputs, checked (before anything is written).
struct Inputs {
    before: SurveyFiles,
    after: SurveyFiles,
    cores: Option<CloudInfo>,
}

fn check_inputs(opts: &CompareOptions, user: &UserParams) -> Result<Inputs> {
    let before = SurveyFiles::open(&opts.before)?;
    let after = SurveyFiles::open(&opts.after)?;
    if !before.bounds().overlaps_xy(&after.bounds()) {
        let (b, a) = (before.bounds(), after.bounds());
        let show = crate::geom::show;
        return Err(Error::Epochs(format!(
            "{} and {}: the epochs do not overlap (x {}..{}, y {}..{} vs x {}..{}, y {}..{})",
            opts.before.display(),
            opts.after.display(),
            show(b.min[0]),
            show(b.max[0]),
            show(b.min[1]),
            show(b.max[1]),
            show(a.min[0]),
            show(a.max[0]),
            show(a.min[1]),
            show(a.max[1]),
        )));
    }
    let cores = match &opts.core_points {
        Some(p) => Some(io::open(p)?.info().clone()),
        None => None,
    };
    match (&opts.before_mesh, &opts.after_mesh) {
        (Some(_), None) | (None, Some(_)) => {
            let p = opts.before_mesh.as_ref().or(opts.after_mesh.as_ref());
            return Err(Error::input(
                p.cloned().unwrap_or_default(),
                "--before-mesh and --after-mesh go together: give both surfaces",
            ));
        }
        _ => {}
    }
    for mesh in [&opts.before_mesh, &opts.after_mesh].into_iter().flatten() {
        match std::fs::metadata(mesh) {
            Err(_) => return Err(Error::input(mesh, "no such mesh file")),
            Ok(m) if !m.is_file() => return Err(io::not_regular(mesh)),
            Ok(_) => {}
        }
    }
    // Validate the user's values before measuring anything.
    Params::resolve(user, 1.0)?;
    user.check_lengths_within(&[before.bounds(), after.bounds()])?;
    Ok(Inputs {
        before,
        after,
        cores,
    })
}

/// Plan the comparison of `opts` in `store`; the before survey's decoded points kept in
/// `decoded` ([`measure_spacing`]).
fn plan(
    store: &Store,
    opts: &CompareOptions,
    user: &UserParams,
    inputs: &Inputs,
    decoded: &mut Option<io::replay::Replay>,
) -> Result<Plan> {
    let (spacing, density_grid) = measure_spacing(
        store,
        inputs.before.first(),
        user,
        keeps_decoded_of(
            opts.resume,
            &opts.executor,
            &inputs.before,
            tiling_part(opts.tiling_part, &opts.executor),
        )
        .then_some(decoded),
    )?;
    crate::progress::trace(|| "spacing measured".into());
    let params = Params::resolve(user, spacing.effective_spacing)?;
    params.check_core_spacing(user)?;
    let surveys = vec![
        survey(store, "before", &inputs.before)?,
        survey(store, "after", &inputs.after)?,
    ];
    let input = |p: &PathBuf| input_file(store, p);
    let core_points = opts.core_points.as_ref().map(input).transpose()?;
    let meshes = match (&opts.before_mesh, &opts.after_mesh) {
        (Some(b), Some(a)) => Some([input(b)?, input(a)?]),
        _ => None,
    };
    let mut bounds = vec![inputs.before.bounds(), inputs.after.bounds()];
    bounds.extend(inputs.cores.as_ref().map(|c| c.bounds));
    let all = crate::io::Bounds::union(&bounds);
    let area = ((all.max[0] - all.min[0]) * (all.max[1] - all.min[1])).max(f64::MIN_POSITIVE);
    // Both surveys are held at once.
    let held = (inputs.before.points() + inputs.after.points()) as f64;
    let density = crate::plan::layout::tile_density(&density_grid, held, held / area, &params);
    let layout = Layout::plan(&bounds, &all, density, &params, opts.tile_size)?;
    let pairs = vec![Pair {
        label: "pair".into(),
        before: 0,
        after: 1,
    }];
    let mut plan = Plan::new(surveys, pairs, params, spacing, layout);
    plan.core_points = core_points;
    plan.meshes = meshes;
    plan.m3c2_only = opts.m3c2_only;
    plan.keep_units = opts.keep_units;
    plan.tiling_part = tiling_part(opts.tiling_part, &opts.executor);
    plan.stable_areas = stable_areas(store, user, &plan.surveys)?;
    let cores = opts.core_points.as_ref().zip(inputs.cores.as_ref());
    let cores = cores.map(|(p, c)| (format!("the core points {}", p.display()), c.bounds));
    crate::plan::reach::check(&plan, cores.as_ref().map(|(s, b)| (s.as_str(), b)))?;
    let source = match plan.core_points {
        Some(_) => CoreSource::UserFile,
        None => CoreSource::PerPair,
    };
    plan_units(&mut plan, source, None)?;
    crate::progress::trace(|| "planned".into());
    Ok(plan)
}

/// Run a comparison (`super::run::run`). None when the run was submitted to Slurm and not
/// waited for.
pub fn compare(opts: &CompareOptions) -> Result<Option<Summary>> {
    let config = match &opts.config {
        Some(p) => UserParams::from_toml_file(p)?,
        None => UserParams::default(),
    };
    let user = opts.user.clone().over(config);
    let inputs = check_inputs(opts, &user)?;
    crate::progress::trace(|| "inputs checked".into());
    let mut given: Vec<&Path> = inputs
        .before
        .infos
        .iter()
        .chain(&inputs.after.infos)
        .map(|i| i.path.as_path())
        .collect();
    given.extend(
        [&opts.core_points, &opts.before_mesh, &opts.after_mesh]
            .into_iter()
            .flatten()
            .map(PathBuf::as_path),
    );
    let run = RunOptions {
        out: &opts.out,
        resume: opts.resume,
        force: opts.force,
        executor: &opts.executor,
        ours: &is_output,
    };
    super::run::run(&run, &given, |store, decoded| {
        plan(store, opts, &user, &inputs, decoded)
    })
}
