//! The lifecycle of a run, which `compare` and `campaign` share and `talus worker` joins
//! (SPEC.md §3, §6):
//!
//! 1. check DIR against the inputs (`check_out_dir`) and prepare it (`open_store`): refuse
//!    one that holds something else, take its lock (one run per DIR), finish a publish a crash
//!    interrupted;
//! 2. plan: the command's own planning, over the helpers here ([`survey`], [`stable_areas`],
//!    [`measure_spacing`]); the plan written to the store ([`Store::plan_path`]);
//! 3. execute the units not done ([`execute`]; `--resume` reuses the store's units, whose names
//!    hold their keys; `--force` recomputes them), or submit them to Slurm;
//! 4. publish the outputs unit's files into DIR as one set, drop units no longer in the plan,
//!    and read the published summary.
//!
//! [`run`] is the whole of it; `talus worker` only executes ([`execute`]).

use std::path::Path;

use serde::de::DeserializeOwned;

use crate::error::{Error, Result};
use crate::exec::Executor;
use crate::io::{self, replay::Replay};
use crate::params::UserParams;
use crate::plan::inputs::SurveyFiles;
use crate::plan::{InputFile, Plan, StableAreas, Survey};
use crate::sampling;
use crate::store::Store;
use crate::units::unit_ref;

/// How a planned command runs: where, with which flags, and which files in DIR are its
/// outputs.
pub(crate) struct RunOptions<'a> {
    /// DIR.
    pub(crate) out: &'a Path,
    pub(crate) resume: bool,
    pub(crate) force: bool,
    /// Where the units run (SPEC.md §6).
    pub(crate) executor: &'a Executor,
    /// Tells talus's outputs (by their `/`-separated name in DIR) from the user's files.
    pub(crate) ours: &'a dyn Fn(&str) -> bool,
}

/// Run a planned command into DIR: check DIR against `inputs` (the files the user gave), open
/// its store, plan (`plan`, given the store and where to keep the points its spacing pass
/// decodes: [`measure_spacing`]), execute and publish; the published summary. On failure
/// nothing is left under a final output name, and a DIR this run created is removed when the
/// failure is the input's (nothing worth resuming). None when the run was submitted to Slurm
/// and not waited for.
pub(crate) fn run<T: DeserializeOwned>(
    opts: &RunOptions,
    inputs: &[&Path],
    plan: impl FnOnce(&Store, &mut Option<Replay>) -> Result<Plan>,
) -> Result<Option<T>> {
    check_out_dir(opts.out, opts.resume, opts.force, opts.ours, inputs)?;
    let (store, created) = open_store(opts.out, opts.resume, opts.force, opts.ours)?;
    let mut decoded = None;
    let result = run_planned(&store, opts.force, opts.ours, opts.executor, |store| {
        plan(store, &mut decoded)
    });
    drop(decoded);
    let Some(marker) = forget_if_input_error(result, created, opts.out)? else {
        return Ok(None);
    };
    say_removed_vegetation(&store)?;
    let text = std::fs::read(&marker).map_err(|e| Error::output(&marker, e))?;
    serde_json::from_slice(&text)
        .map(Some)
        .map_err(|e| Error::Internal(format!("summary.json: {e}")))
}

/// A survey of the plan: its files keyed by content.
pub(crate) fn survey(store: &Store, label: &str, files: &SurveyFiles) -> Result<Survey> {
    let inputs: Vec<InputFile> = files
        .infos
        .iter()
        .map(|i| input_file(store, &i.path))
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
        transform: files.first().transform,
        file_points: files.las_points(),
    })
}

/// The input file at `path` (canonical when it can be), keyed by its content.
pub(crate) fn input_file(store: &Store, path: &Path) -> Result<InputFile> {
    Ok(InputFile {
        path: std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
        key: store.content_key(path)?,
    })
}

/// The user's stable areas (`--stable`), read and checked against `surveys`, with their
/// content's key.
pub(crate) fn stable_areas(
    store: &Store,
    user: &UserParams,
    surveys: &[Survey],
) -> Result<Option<StableAreas>> {
    let Some(path) = &user.stable else {
        return Ok(None);
    };
    if !path.is_file() {
        return Err(Error::input(
            path,
            "cannot read the stable areas: no such file",
        ));
    }
    let key = store.content_key(path)?;
    StableAreas::read(path, key, surveys).map(Some)
}

/// The spacing and density grid of the survey file `file` (its header as the inputs read it)
/// read with `user`'s classes (`sampling::measure`). With `decoded` (see [`keeps_decoded`]),
/// the points the pass decodes are kept there ([`io::replay`]) until it is dropped: the survey's
/// tiling reads them instead of decoding the file a second time. Without, a measurement this
/// store cached for the file's content is taken as it is (`plan::measured::cached_spacing`): a resumed
/// run does not decode the file for it again.
pub(crate) fn measure_spacing(
    store: &Store,
    file: &io::CloudInfo,
    user: &UserParams,
    decoded: Option<&mut Option<Replay>>,
) -> Result<(sampling::Spacing, crate::spatial::DensityGrid)> {
    let (path, classes) = (file.path.as_path(), user.classes()?);
    let (key, filter) = (store.content_key(path)?, classes.to_string());
    let measured = match decoded {
        None => {
            if let Some(cached) = crate::plan::measured::cached_spacing(store, &key, &filter) {
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
    crate::plan::measured::cache_spacing(
        store,
        &key,
        &filter,
        &measured.spacing,
        &measured.density,
    );
    Ok((measured.spacing, measured.density))
}

/// Whether a run keeps the points its spacing pass decodes for its tiling: when the units run in
/// this process (a Slurm worker would decode the file itself), and the run starts anew (a
/// resumed run has most likely tiled the survey already: the copy would be written for nothing).
pub(crate) fn keeps_decoded(resume: bool, executor: &Executor) -> bool {
    !resume && matches!(executor, Executor::Local)
}

/// Points a tiling unit reads at most (`Plan::tiling_part`): the user's `--tiling-part`, else
/// [`crate::plan::TILING_PART`] on a cluster, where the parts spread over the nodes, and the
/// whole survey in a local run — its two slots already tile a pair's two surveys at once, and
/// the before survey is tiled from the points its spacing pass decoded ([`keeps_decoded`]),
/// which a part cannot read.
pub(crate) fn tiling_part(user: Option<u64>, executor: &Executor) -> u64 {
    user.unwrap_or(match executor {
        Executor::Local => u64::MAX,
        Executor::Slurm(_) => crate::plan::TILING_PART,
    })
}

/// Whether a run keeps the points its spacing pass decodes of `survey` for its tiling
/// ([`keeps_decoded`]), given the run's tiling part: a survey tiled in parts does not read
/// them (the copy would be written for nothing).
pub(crate) fn keeps_decoded_of(
    resume: bool,
    executor: &Executor,
    survey: &SurveyFiles,
    tiling_part: u64,
) -> bool {
    let las = survey.las_points();
    keeps_decoded(resume, executor) && (las.is_empty() || las.iter().sum::<u64>() <= tiling_part)
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
fn check_out_dir(
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
fn open_store(
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
        let planned = store.plan_path().exists();
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

/// Tell what `--vegetation remove` took out of the surveys of the run just published
/// (`super::removed`).
fn say_removed_vegetation(store: &Store) -> Result<()> {
    let plan = Plan::load(&store.plan_path())?;
    if let Some(note) = super::removed::vegetation(store, &plan)? {
        eprintln!("talus: {note}");
    }
    Ok(())
}

/// After a failed run in a DIR it created: remove DIR again when the failure is the input's
/// (nothing worth resuming).
fn forget_if_input_error<T>(result: Result<T>, created: bool, out: &Path) -> Result<T> {
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

/// Say which units of `plan` are computed again where DIR's previous run (its saved plan) had
/// them under other keys, and why (`Plan::recomputed`): an upgraded talus, a changed parameter
/// or input. Kept in the plan for `talus status`.
fn explain_recomputed(store: &Store, plan: &mut Plan) {
    let Ok(old) = Plan::load(&store.plan_path()) else {
        return;
    };
    plan.recomputed = plan.recomputed(&old, |i| store.done(&unit_ref(plan, i)).is_some());
    for r in &plan.recomputed {
        eprintln!(
            "talus: computing {} {} unit(s) again: {}",
            r.units, r.kind, r.reason
        );
    }
}

/// The run of a planned command in `store`: take DIR's lock (one run per DIR), finish a publish
/// a crash interrupted, plan (`plan`), write the plan, with `force` throw its units away, then
/// execute it with `executor`: locally, every unit not done, then publish the last unit's
/// `publish` list as one set (`ours` tells talus's outputs from the user's files) and drop units
/// no longer in the plan; on Slurm, submit the units not done (the final job publishes). Returns
/// the path of the published marker in its unit, or None when the run was submitted to Slurm and
/// not waited for (or only planned).
fn run_planned(
    store: &Store,
    force: bool,
    ours: &dyn Fn(&str) -> bool,
    executor: &Executor,
    plan: impl FnOnce(&Store) -> Result<Plan>,
) -> Result<Option<std::path::PathBuf>> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let lock = store.lock("run", &command)?;
    store.recover(ours)?;
    // Jobs of an earlier submission still queued or running would compute beside this run.
    if !matches!(executor, Executor::Local) || force {
        crate::exec::slurm::check_idle(store)?;
    }
    let mut plan = plan(store)?;
    if !force {
        explain_recomputed(store, &mut plan);
    }
    plan.save(&store.plan_path())?;
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
    if let Executor::Slurm(opts) = executor {
        return crate::exec::slurm::run(store, &plan, opts, &command, lock, ours);
    }
    let threads = plan.params.threads.value;
    execute(store, &plan, threads, threads.min(2), "run")?;
    crate::progress::trace(|| "executed".into());
    drop(sweep);
    let marker = crate::exec::publish::publish_and_gc(store, &plan, ours)?;
    crate::progress::trace(|| "published".into());
    drop(lock);
    Ok(Some(marker))
}

/// Execute every unit of `plan` not done in `store` on a pool of `threads` threads, `slots`
/// units at a time; `label` names this executor in the store's claims (`crate::exec::run`).
pub(crate) fn execute(
    store: &Store,
    plan: &Plan,
    threads: usize,
    slots: usize,
    label: &str,
) -> Result<crate::exec::Report> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
    pool.install(|| crate::exec::run(store, plan, slots, label))
}
