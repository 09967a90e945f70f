//! `talus compare`: a one-pair plan (SPEC.md §2, §3), executed in this process and published.
//!
//! 1. check the inputs (headers, counts, overlap, meshes) and the user's values, before anything
//!    is written;
//! 2. open DIR's store, take its lock (one run per DIR), finish a publish a crash interrupted;
//! 3. measure the point spacing, resolve the parameters, key every input by its content, plan the
//!    tiles and the units, write the plan;
//! 4. execute the units not done ([`crate::exec`]; `--resume` reuses the store's units, whose
//!    names hold their keys; `--force` recomputes them);
//! 5. publish the outputs unit's files into DIR as one set, drop units no longer in the plan.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::io::{self, CloudInfo};
use crate::params::{Params, UserParams};
use crate::plan::inputs::SurveyFiles;
use crate::plan::{InputFile, Layout, Pair, Plan, Survey, PLAN_VERSION};
use crate::sampling;
use crate::store::Store;
use crate::units::outputs::{is_output, Summary};
use crate::units::stage::{plan_units, CoreSource};
use crate::units::unit_ref;

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

/// A survey of the plan: its files keyed by content.
pub fn survey(store: &Store, label: &str, files: &SurveyFiles) -> Result<Survey> {
    let inputs: Vec<InputFile> = files
        .infos
        .iter()
        .map(|i| {
            Ok(InputFile {
                path: std::fs::canonicalize(&i.path).unwrap_or_else(|_| i.path.clone()),
                key: store.content_key(&i.path)?,
            })
        })
        .collect::<Result<_>>()?;
    let keys: Vec<&str> = inputs.iter().map(|f| f.key.as_str()).collect();
    Ok(Survey {
        label: label.into(),
        arg: files.arg.clone(),
        key: crate::plan::key_of(&keys),
        date: None,
        files: inputs,
        points: files.points(),
        bounds: files.bounds(),
        format: files.format(),
        crs: files.first().crs.describe(),
        scale: files.scale(),
        epsg: files.first().crs.epsg_code(),
    })
}

/// The user's stable areas (`--stable`), read and checked against `surveys`, with their
/// content's key.
pub(super) fn stable_areas(
    store: &Store,
    user: &UserParams,
    surveys: &[crate::plan::Survey],
) -> Result<Option<crate::plan::StableAreas>> {
    let Some(path) = &user.stable else {
        return Ok(None);
    };
    if !path.is_file() {
        return Err(crate::error::Error::input(
            path,
            "cannot read the stable areas: no such file",
        ));
    }
    let key = store.content_key(path)?;
    crate::plan::StableAreas::read(path, key, surveys).map(Some)
}

/// The spacing and density grid of the survey file `file` (its header as the inputs read it)
/// read with `user`'s classes ([`sampling::measure`]). With `decoded` (see [`keeps_decoded`]),
/// the points the pass decodes are kept there ([`io::replay`]) until it is dropped: the survey's
/// tiling reads them instead of decoding the file a second time. Without, a measurement this store cached for the file's
/// content is taken as it is (`Store::cached_spacing`): a resumed run does not decode the file
/// for it again.
pub(super) fn measure_spacing(
    store: &Store,
    file: &io::CloudInfo,
    user: &UserParams,
    decoded: Option<&mut Option<io::replay::Replay>>,
) -> Result<(sampling::Spacing, crate::spatial::DensityGrid)> {
    let (path, classes) = (file.path.as_path(), user.classes()?);
    let (key, filter) = (store.content_key(path)?, classes.to_string());
    let measured = match decoded {
        None => {
            if let Some(cached) = store.cached_spacing(&key, &filter) {
                return Ok(cached);
            }
            sampling::measure(path, Some(&classes))?
        }
        Some(decoded) => {
            // The header read when the inputs were opened gives the transform: opening the file
            // again would start a decoder for nothing.
            let copy = store.scratch_path("decoded");
            let mut keep = io::replay::Recorder::create(path, Some(&classes), file.transform, copy);
            let measured = sampling::measure_keeping(path, Some(&classes), &mut |p| keep.push(p))?;
            *decoded = keep.finish(&measured.info, measured.classes.clone());
            measured
        }
    };
    store.cache_spacing(&key, &filter, &measured.spacing, &measured.density);
    Ok((measured.spacing, measured.density))
}

/// Whether a run keeps the points its spacing pass decodes for its tiling: when the units run in
/// this process (a Slurm worker would decode the file itself), and the run starts anew (a
/// resumed run has most likely tiled the survey already: the copy would be written for nothing).
pub(super) fn keeps_decoded(resume: bool, executor: &crate::exec::Executor) -> bool {
    !resume && matches!(executor, crate::exec::Executor::Local)
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
        keeps_decoded(opts.resume, &opts.executor).then_some(decoded),
    )?;
    crate::progress::trace(|| "spacing measured".into());
    let params = Params::resolve(user, spacing.effective_spacing)?;
    params.check_core_spacing(user)?;
    let surveys = vec![
        survey(store, "before", &inputs.before)?,
        survey(store, "after", &inputs.after)?,
    ];
    let input = |p: &PathBuf| -> Result<InputFile> {
        Ok(InputFile {
            path: std::fs::canonicalize(p).unwrap_or_else(|_| p.clone()),
            key: store.content_key(p)?,
        })
    };
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
    let mut plan = Plan {
        version: PLAN_VERSION,
        run: String::new(),
        surveys,
        pairs: vec![Pair {
            label: "pair".into(),
            before: 0,
            after: 1,
        }],
        params,
        spacing,
        layout,
        core_points,
        stable_areas: None,
        meshes,
        m3c2_only: opts.m3c2_only,
        keep_units: opts.keep_units,
        recomputed: Vec::new(),
        units: Vec::new(),
    };
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

/// Names under `dir` (`/`-separated, `.talus` left out) that `ours` takes for talus outputs.
fn output_names(dir: &Path, rel: &str, ours: &dyn Fn(&str) -> bool, found: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir.join(rel)) else {
        return;
    };
    let mut names: Vec<String> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    for n in names {
        if rel.is_empty() && n == ".talus" {
            continue;
        }
        let name = if rel.is_empty() {
            n
        } else {
            format!("{rel}/{n}")
        };
        if dir.join(&name).is_dir() {
            output_names(dir, &name, ours, found);
        } else if ours(&name) {
            found.push(name);
        }
    }
}

/// What `--resume` and `--force` may never do: replace a file talus did not write. Before
/// anything is written, refuse (exit 2) when an input lies where talus publishes an output (a
/// survey copied to DIR/m3c2.laz would be overwritten by the result), and when DIR has no talus
/// store yet but holds files with the names of talus outputs (they are the user's: talus wrote
/// nothing there).
pub fn check_out_dir(
    out: &Path,
    resume: bool,
    force: bool,
    ours: &dyn Fn(&str) -> bool,
    inputs: &[&Path],
) -> Result<()> {
    let Ok(dir) = std::fs::canonicalize(out) else {
        return Ok(());
    };
    for input in inputs {
        let Ok(p) = std::fs::canonicalize(input) else {
            continue;
        };
        if let Ok(rel) = p.strip_prefix(&dir) {
            let rel = rel.to_string_lossy().replace('\\', "/");
            if ours(&rel) {
                return Err(Error::Usage(format!(
                    "{}: this input lies where talus writes its output {rel} in {}: the result \
                     would replace it; move it out of the output directory or choose another --out",
                    input.display(),
                    out.display()
                )));
            }
        }
    }
    if (resume || force) && !dir.join(".talus").is_dir() {
        let mut found = Vec::new();
        output_names(&dir, "", ours, &mut found);
        if !found.is_empty() {
            return Err(user_outputs(out, &found));
        }
    }
    Ok(())
}

/// Prepare DIR: refuse one that holds something else unless `resume` or `force`, saying what
/// would work (`ours` tells talus's outputs by name); whether this run created DIR.
pub fn open_store(
    out: &Path,
    resume: bool,
    force: bool,
    ours: &dyn Fn(&str) -> bool,
) -> Result<(Store, bool)> {
    let existed = out.exists();
    if existed && !out.is_dir() {
        return Err(Error::Usage(format!(
            "{}: --out exists and is not a directory",
            out.display()
        )));
    }
    if existed && !resume && !force {
        refuse_unless_empty(out, ours)?;
    }
    Ok((Store::open(out, true)?, !existed))
}

/// A plain run (neither `--resume` nor `--force`) into an existing DIR: fine when it is empty,
/// or holds only the work area of a run that stopped before planning (or is starting: the
/// lock decides then); else refused with advice that holds — a live run holding DIR is named
/// as such (two runs started at once: the second is told "in use", not to resume), a finished
/// or stopped run can be resumed or forced, files of the user's with the names of talus
/// outputs are refused by both, and other files of the user's only stand beside `--force`'s
/// outputs.
fn refuse_unless_empty(out: &Path, ours: &dyn Fn(&str) -> bool) -> Result<()> {
    let entries: Vec<String> = std::fs::read_dir(out)
        .map_err(|e| Error::input(out, format!("cannot read: {e}")))?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n != ".talus")
        .collect();
    if out.join(".talus").is_dir() {
        let store = Store::inspect(out)?;
        if let Some(held) = store.lock_holder().filter(|l| !l.owner.gone(None)) {
            return Err(Error::Busy {
                dir: out.to_path_buf(),
                holder: held.describe(),
            });
        }
        let planned = store.work().join("plan.json").exists();
        if entries.is_empty() && !planned {
            return Ok(());
        }
        return Err(Error::Usage(format!(
            "{}: holds a talus run; use --resume to continue it or --force to compute it again \
             (files talus did not write are kept either way)",
            out.display()
        )));
    }
    if entries.is_empty() {
        return Ok(());
    }
    let mut found = Vec::new();
    output_names(out, "", ours, &mut found);
    if !found.is_empty() {
        // --resume and --force refuse these too (check_out_dir).
        return Err(user_outputs(out, &found));
    }
    Err(Error::Usage(format!(
        "{}: the output directory is not empty and holds no talus run; choose an empty or new \
         --out, or use --force to write talus's outputs beside what it holds (left as it is)",
        out.display()
    )))
}

/// Files of the user's with the names of talus outputs, in a DIR without a talus run: never
/// replaced, whatever the flags.
fn user_outputs(out: &Path, found: &[String]) -> Error {
    let shown: Vec<&str> = found.iter().take(6).map(String::as_str).collect();
    Error::Usage(format!(
        "{}: holds {} file(s) with the names of talus outputs ({}{}) but no talus run (.talus/): \
         they are not talus's to replace; move them or choose another --out",
        out.display(),
        found.len(),
        shown.join(", "),
        if found.len() > shown.len() {
            ", …"
        } else {
            ""
        }
    ))
}

/// The path of the plan in a store.
pub fn plan_path(store: &Store) -> PathBuf {
    store.work().join("plan.json")
}

/// Run a comparison. On failure nothing is left under a final output name, and a DIR this run
/// created is removed when the failure is the input's (nothing worth resuming). None when the
/// run was submitted to Slurm and not waited for.
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
    check_out_dir(&opts.out, opts.resume, opts.force, &is_output, &given)?;
    let (store, created) = open_store(&opts.out, opts.resume, opts.force, &is_output)?;
    let mut decoded = None;
    let result = run_planned(&store, opts.force, &is_output, &opts.executor, |store| {
        plan(store, opts, &user, &inputs, &mut decoded)
    });
    drop(decoded);
    let Some(marker) = forget_if_input_error(result, created, &opts.out)? else {
        return Ok(None);
    };
    say_removed_vegetation(&store)?;
    let text = std::fs::read(&marker).map_err(|e| Error::output(&marker, e))?;
    serde_json::from_slice(&text)
        .map(Some)
        .map_err(|e| Error::Internal(format!("summary.json: {e}")))
}

/// Tell what `--vegetation remove` took out of the surveys of the run just published
/// (`super::removed`).
pub fn say_removed_vegetation(store: &Store) -> Result<()> {
    let plan = Plan::load(&plan_path(store))?;
    if let Some(note) = super::removed::vegetation(store, &plan)? {
        eprintln!("talus: {note}");
    }
    Ok(())
}

/// After a failed run in a DIR it created: remove DIR again when the failure is the input's
/// (nothing worth resuming).
pub fn forget_if_input_error<T>(result: Result<T>, created: bool, out: &Path) -> Result<T> {
    match result {
        Ok(v) => Ok(v),
        Err(e) => {
            if created && matches!(e, Error::Input { .. } | Error::Usage(_) | Error::Epochs(_)) {
                let _ = std::fs::remove_dir_all(out);
            }
            Err(e)
        }
    }
}

/// The run of a planned command in `store`: take DIR's lock (one run per DIR), finish a publish
/// a crash interrupted, plan (`plan`), write the plan, with `force` throw its units away, then
/// execute it with `executor`: locally, every unit not done, then publish the last unit's
/// `publish` list as one set (`ours` tells talus's outputs from the user's files) and drop units
/// no longer in the plan; on Slurm, submit the units not done (the final job publishes). Returns
/// the path of the published marker in its unit, or None when the run was submitted to Slurm and
/// not waited for (or only planned).
/// Say which units of `plan` are computed again where DIR's previous run (its saved plan) had
/// them under other keys, and why (`Plan::recomputed`): an upgraded talus, a changed parameter
/// or input. Kept in the plan for `talus status`.
fn explain_recomputed(store: &Store, plan: &mut Plan) {
    let Ok(old) = Plan::load(&plan_path(store)) else {
        return;
    };
    plan.recomputed = plan.recomputed(&old, |i| {
        store.done(&crate::units::unit_ref(plan, i)).is_some()
    });
    for r in &plan.recomputed {
        eprintln!(
            "talus: computing {} {} unit(s) again: {}",
            r.units, r.kind, r.reason
        );
    }
}

pub fn run_planned(
    store: &Store,
    force: bool,
    ours: &dyn Fn(&str) -> bool,
    executor: &crate::exec::Executor,
    plan: impl FnOnce(&Store) -> Result<Plan>,
) -> Result<Option<PathBuf>> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let lock = store.lock("run", &command)?;
    store.recover(ours)?;
    // Jobs of an earlier submission still queued or running would compute beside this run.
    if !matches!(executor, crate::exec::Executor::Local) || force {
        crate::exec::slurm::check_idle(store)?;
    }
    let mut plan = plan(store)?;
    if !force {
        explain_recomputed(store, &mut plan);
    }
    plan.save(&plan_path(store))?;
    // Every unit gone from the store at once; their files deleted beside the run (a tile file's
    // unlink blocks for milliseconds), at the latest before publishing.
    let mut trash = Vec::new();
    if force {
        for i in 0..plan.units.len() {
            trash.extend(store.invalidate_later(&unit_ref(&plan, i))?);
        }
    }
    let sweep = crate::store::Sweep::start(trash);
    crate::progress::trace(|| "plan saved".into());
    if let crate::exec::Executor::Slurm(opts) = executor {
        return crate::exec::slurm::run(store, &plan, opts, &command, lock, ours);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(plan.params.threads.value)
        .build()
        .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
    let slots = plan.params.threads.value.min(2);
    pool.install(|| crate::exec::run(store, &plan, slots, "run"))?;
    crate::progress::trace(|| "executed".into());
    drop(sweep);
    let marker = crate::exec::publish::publish_and_gc(store, &plan, ours)?;
    crate::progress::trace(|| "published".into());
    drop(lock);
    Ok(Some(marker))
}
