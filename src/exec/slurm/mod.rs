//! The Slurm executor (SPEC.md §6): a plan's units submitted to a Slurm cluster, whose nodes
//! share DIR's filesystem, as job arrays — Slurm schedules, talus has no scheduler of its own.
//!
//! - **Stages.** The plan's kinds of units in pipeline order (tiling, cores, m3c2, stable, events,
//!   volumes, outputs, campaign) are the stages: every unit depends only on units of earlier
//!   stages ([`stages`] checks it). Each stage with units not done becomes one job array; task `i`
//!   runs its slice of the stage's units (`--tiles-per-task` tiles of the tile stages, one survey
//!   or pair otherwise) with `talus slurm-task`, i.e. [`crate::exec::run_units`] — the executor a
//!   local run and `talus worker` use, with the store's claims and per-unit records. A last
//!   one-task array publishes the outputs (takes DIR's lock, publishes as one set, drops old units).
//! - **Chaining.** Every array depends `afterok` on the arrays holding units its units depend on
//!   (not on every array before it: the first survey's orientation field runs beside the
//!   alignment, the segments of m3c2.laz beside the volumes), the publishing job on all of them, with
//!   `--kill-on-invalid-dep=yes`: a failed, cancelled or timed-out task cancels every job that
//!   depends on it at once instead of leaving them pending forever. The whole chain is submitted
//!   in one go (never onto a job id of an earlier submission, which Slurm may have forgotten:
//!   afterok on an unknown id runs at once).
//! - **Records.** `DIR/.talus/slurm/<n>/` per submission ([`record`]): `submission.json` (stages,
//!   each task's units, the sbatch arguments), a copy of the plan the tasks execute, the sbatch
//!   scripts and a `submit.sh` with the very sbatch commands, `jobs.json` (the arrays' job ids),
//!   `logs/` (each task's output) and `tasks/` (each task's own report, written by that task only).
//! - **Recovery.** Units are content-keyed and each has its own record, so running the command
//!   again with `--resume` plans again, finds what is done and submits only the rest; `talus
//!   status DIR` ([`status`]) names the units done, queued, running and failed with their job ids.
//!
//! The submitting process holds DIR's lock only while it plans and submits; the tasks never take
//! it, and the publishing job takes it when it runs (waiting while the submitter still holds it).

mod cluster;
pub(crate) mod record;
pub(crate) mod scaling;
mod scripts;
pub(crate) mod status;
pub(crate) mod task;

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::error::{Error, Result};
use crate::plan::Plan;
use crate::store::{Lock, Store};
use crate::units::stage::{registry, Registered};
use crate::units::unit_ref;

/// The name of the last job, which publishes the outputs.
pub(crate) const PUBLISH: &str = "publish";

/// At most this many tasks in one array (Slurm's default MaxArraySize is 1001: indices 0..=1000).
pub(crate) const MAX_TASKS: usize = 1000;

/// How `--executor slurm` runs.
#[derive(Debug, Clone)]
pub struct Options {
    /// `--slurm-args`, split like a shell would: given to every sbatch.
    pub args: Vec<String>,
    /// Wait for the last job and exit with the run's status.
    pub wait: bool,
    /// Write the plan and the scripts, submit nothing.
    pub plan_only: bool,
    /// Units of a tile stage (m3c2, volumes) per array task.
    pub tiles_per_task: usize,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            args: Vec::new(),
            wait: false,
            plan_only: false,
            tiles_per_task: 1,
        }
    }
}

/// One stage of a submission: the units (plan indices) of each array task, and the arrays
/// (indices among the submission's stages) holding units they depend on.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct StagePlan {
    pub kind: &'static str,
    pub tasks: Vec<Vec<usize>>,
    pub after: Vec<usize>,
}

/// A stage of one unit a task (not per tile, not in parts: a comparison's alignment, stable
/// ground, events, m3c2.laz's join; a campaign's, one a pair) computed at the end of the arrays
/// holding what its units read instead of by an array of its own: every task of those arrays,
/// once its own units are done, computes each tail unit whose inputs are all done — the last
/// task to end computes it at once, where an array of its own would wait a scheduling pass
/// (issue 47: 12 arrays in a row on the 120M-point pair's critical path, ≈ 1 s of scheduling
/// each on the test cluster, more on a busy one); no task waits on another's claim. A tail the
/// arrays leave (their last task did not see its inputs done) is computed by the first task that
/// reads it (`exec::run_units` computes a task's missing dependencies) or the publishing job.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Tail {
    pub kind: &'static str,
    pub units: Vec<usize>,
    /// The arrays (indices in [`Arrays::stages`]) whose tasks compute them when they end: those
    /// holding what they read that no other of them waits for.
    pub hosts: Vec<usize>,
}

/// A submission's job arrays and the stages computed at their ends.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Arrays {
    pub stages: Vec<StagePlan>,
    pub tails: Vec<Tail>,
}

impl Arrays {
    /// The tail units array `k`'s tasks compute when they end, in pipeline order.
    pub(crate) fn tails_of(&self, k: usize) -> Vec<usize> {
        (self.tails.iter())
            .filter(|t| t.hosts.contains(&k))
            .flat_map(|t| t.units.iter().copied())
            .collect()
    }
}

/// The stages in pipeline order (the registry's), each one job array.
pub(crate) fn stage_order() -> impl Iterator<Item = &'static dyn Registered> {
    registry().stages().iter().copied()
}

/// The arrays of `plan`'s units not done (`done[i]`): a stage's units in tasks of
/// `tiles_per_task` (tile stages) or one (the others), at most [`MAX_TASKS`] tasks (more units
/// per task when there are more); a stage of one unit a task that reads units in arrays is a
/// [`Tail`] of them instead. An error if a unit depends on a unit of its own or a later stage.
pub(crate) fn stages(plan: &Plan, done: &[bool], tiles_per_task: usize) -> Result<Arrays> {
    // The arrays' order relies on it: checked here as when the plan was made (a plan read from
    // a submission's folder), giving each unit's stage.
    let ranks = crate::units::stage::check_plan(plan)?;
    let mut cands: Vec<StagePlan> = Vec::new();
    let mut per_tile: Vec<bool> = Vec::new();
    for (r, stage) in stage_order().enumerate() {
        let todo: Vec<usize> = (0..plan.units.len())
            .filter(|&i| ranks[i] == r && !done[i])
            .collect();
        if todo.is_empty() {
            continue;
        }
        let kind = stage.kind();
        // Units one per tile are grouped `tiles_per_task` to a task.
        let mut per = if stage.scope().per_tile() {
            tiles_per_task.max(1)
        } else {
            1
        };
        per = per.max(todo.len().div_ceil(MAX_TASKS));
        per_tile.push(stage.scope().per_tile());
        cands.push(StagePlan {
            kind,
            tasks: todo.chunks(per).map(|c| c.to_vec()).collect(),
            after: Vec::new(),
        });
    }
    let n = cands.len();
    // What each array waits for, transitively, were every stage an array.
    let pre = waits(plan, &cands, &vec![false; n]);
    let mut reach = vec![vec![false; n]; n];
    for k in 0..n {
        // Arrays wait only for earlier ones: their closure is known.
        for &a in &pre[k] {
            let below = reach[a].clone();
            for (r, b) in reach[k].iter_mut().zip(below) {
                *r |= b;
            }
            reach[k][a] = true;
        }
    }
    // Decided in pipeline order: a tail's units pass the wait on to the arrays of what they
    // read (as units done already do), so a later tail reading one is hosted by those.
    let mut tailed = vec![false; n];
    let mut hosts: Vec<Vec<usize>> = vec![Vec::new(); n];
    for j in 0..n {
        let units: Vec<usize> = cands[j].tasks.iter().flatten().copied().collect();
        let one_each = cands[j].tasks.iter().all(|t| t.len() == 1);
        if per_tile[j] || !one_each || units.iter().any(|&u| plan.units[u].spec.part.is_some()) {
            continue;
        }
        let d = arrays_read(plan, &cands, &tailed, &units);
        if d.is_empty() {
            continue;
        }
        // The arrays among them that no other of them waits for: the last to end.
        let last: Vec<usize> = (d.iter().copied())
            .filter(|&a| !d.iter().any(|&b| b != a && reach[b][a]))
            .collect();
        // An array waiting for a host waits for its tails too (afterok on the host's last
        // task, which ends them): not where it would not have waited for this stage (the
        // first survey's orientation field beside the alignment).
        let delays = (0..n).any(|r| {
            r != j && !tailed[r] && pre[r].iter().any(|h| last.contains(h)) && !reach[r][j]
        });
        if delays {
            continue;
        }
        tailed[j] = true;
        hosts[j] = last;
    }
    let mut index = vec![None; n];
    let mut out: Vec<StagePlan> = Vec::new();
    for k in (0..n).filter(|&k| !tailed[k]) {
        index[k] = Some(out.len());
        out.push(cands[k].clone());
    }
    let after = waits(plan, &cands, &tailed);
    for k in (0..n).filter(|&k| !tailed[k]) {
        let i = index[k].expect("an array left");
        out[i].after = after[k].iter().filter_map(|&a| index[a]).collect();
    }
    let mut tails = Vec::new();
    for j in (0..n).filter(|&j| tailed[j]) {
        let units: Vec<usize> = cands[j].tasks.iter().flatten().copied().collect();
        let hs: Vec<usize> = hosts[j].iter().filter_map(|&h| index[h]).collect();
        tails.push(Tail {
            kind: cands[j].kind,
            units,
            hosts: hs,
        });
    }
    Ok(Arrays { stages: out, tails })
}

/// The arrays among `cands` holding what `units` read or run after (`Unit::after`: m3c2.laz
/// once the volumes released the tiles, a tail at their end), through the units of `tailed`
/// stages (and units done already) to what those read.
fn arrays_read(plan: &Plan, cands: &[StagePlan], tailed: &[bool], units: &[usize]) -> Vec<usize> {
    let array_of = arrays_of_units(plan, cands, tailed);
    let mut through = vec![None::<Vec<usize>>; plan.units.len()];
    let mut out = Vec::new();
    for &u in units {
        for &d in plan.units[u].deps.iter().chain(&plan.units[u].after) {
            out.extend(arrays_of(plan, &array_of, &mut through, d));
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// The array of each unit in one (`None`: done already, or a tail's).
fn arrays_of_units(plan: &Plan, cands: &[StagePlan], tailed: &[bool]) -> Vec<Option<usize>> {
    let mut array_of = vec![None; plan.units.len()];
    for (k, s) in cands.iter().enumerate() {
        if tailed.get(k).copied().unwrap_or(false) {
            continue;
        }
        for &u in s.tasks.iter().flatten() {
            array_of[u] = Some(k);
        }
    }
    array_of
}

/// What each of `cands` waits for (indices among them): the arrays holding what its units
/// read, through the units of `tailed` stages (and units done already) to what those read.
fn waits(plan: &Plan, cands: &[StagePlan], tailed: &[bool]) -> Vec<Vec<usize>> {
    let array_of = arrays_of_units(plan, cands, tailed);
    // A dependency done already that depends on units not done (a unit computed again: the
    // executor computes it before its readers) passes the wait on to those units' arrays.
    let mut through = vec![None::<Vec<usize>>; plan.units.len()];
    cands
        .iter()
        .map(|s| {
            let mut after = Vec::new();
            for &u in s.tasks.iter().flatten() {
                for &d in &plan.units[u].deps {
                    after.extend(arrays_of(plan, &array_of, &mut through, d));
                }
            }
            after.sort_unstable();
            after.dedup();
            after
        })
        .collect()
}

/// The arrays unit `d` waits on: its own where it is in one, else (done already) those of its
/// dependencies, memoised in `through`.
fn arrays_of(
    plan: &Plan,
    array_of: &[Option<usize>],
    through: &mut [Option<Vec<usize>>],
    d: usize,
) -> Vec<usize> {
    if let Some(k) = array_of[d] {
        return vec![k];
    }
    if let Some(known) = &through[d] {
        return known.clone();
    }
    let mut out = Vec::new();
    for &e in &plan.units[d].deps {
        out.extend(arrays_of(plan, array_of, through, e));
    }
    out.sort_unstable();
    out.dedup();
    through[d] = Some(out.clone());
    out
}

/// Split `--slurm-args` like a POSIX shell would (blanks separate words; single quotes keep
/// everything, double quotes everything but `\"` and `\\`, a backslash outside quotes keeps the
/// next character). No expansion of any kind.
pub(crate) fn split_args(s: &str) -> Result<Vec<String>> {
    let mut words = Vec::new();
    let mut cur = String::new();
    let mut in_word = false;
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        match c {
            c if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut cur));
                    in_word = false;
                }
            }
            '\'' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some('\'') => break,
                        Some(c) => cur.push(c),
                        None => return Err(unclosed(s)),
                    }
                }
            }
            '"' => {
                in_word = true;
                loop {
                    match chars.next() {
                        Some('"') => break,
                        Some('\\') => match chars.next() {
                            Some(c @ ('"' | '\\')) => cur.push(c),
                            Some(c) => {
                                cur.push('\\');
                                cur.push(c);
                            }
                            None => return Err(unclosed(s)),
                        },
                        Some(c) => cur.push(c),
                        None => return Err(unclosed(s)),
                    }
                }
            }
            '\\' => {
                in_word = true;
                match chars.next() {
                    Some(c) => cur.push(c),
                    None => cur.push('\\'),
                }
            }
            c => {
                in_word = true;
                cur.push(c);
            }
        }
    }
    if in_word {
        words.push(cur);
    }
    Ok(words)
}

fn unclosed(s: &str) -> Error {
    Error::Usage(format!("--slurm-args: unclosed quote in {s:?}"))
}

/// Refuse to go on while jobs of DIR's latest Slurm submission are queued or running (they would
/// compute beside this run, or on units `--force` throws away). Without Slurm's client commands
/// on this machine, or with no submission in DIR, there is nothing to check. Once Slurm says
/// they have all ended, the claims their tasks left (a task on a node that died: another host
/// cannot check its pid, so they would hold for the store's lease) are dropped.
pub(crate) fn check_idle(store: &Store) -> Result<()> {
    let Some((n, _sub, Some(jobs))) = record::latest(store)? else {
        return Ok(());
    };
    let states = match cluster::states(&jobs.ids) {
        Ok(s) => s,
        Err(cluster::Unavailable(why)) => {
            eprintln!(
                "talus: note: cannot ask Slurm about the jobs of submission {n} ({why}); going on"
            );
            return Ok(());
        }
    };
    // "518: 6 PENDING", one entry per array with tasks not ended.
    let mut active: Vec<String> = Vec::new();
    for id in &jobs.ids {
        let mut counts: Vec<(String, usize)> = Vec::new();
        for (task, s) in &states {
            if s.state.is_active() && task.split('_').next() == Some(id.as_str()) {
                match counts.iter_mut().find(|(n, _)| *n == s.state.0) {
                    Some(c) => c.1 += 1,
                    None => counts.push((s.state.0.clone(), 1)),
                }
            }
        }
        if !counts.is_empty() {
            let c: Vec<String> = counts.iter().map(|(n, k)| format!("{k} {n}")).collect();
            active.push(format!("{id}: {}", c.join(", ")));
        }
    }
    if active.is_empty() {
        let ended = |c: &crate::store::ClaimInfo| {
            task::array_job_of(&c.label).is_some_and(|job| jobs.ids.iter().any(|id| id == job))
        };
        let dropped = store.drop_claims(ended)?;
        if dropped > 0 {
            eprintln!(
                "talus: slurm: {dropped} claim(s) left by ended tasks of submission {n} dropped"
            );
        }
        return Ok(());
    }
    Err(Error::Usage(format!(
        "{}: jobs of its Slurm submission {n} are still queued or running ({}); wait for them \
         (talus status {}) or cancel them (scancel {}), then run the command again",
        store.dir().display(),
        active.join("; "),
        store.dir().display(),
        jobs.ids.join(" ")
    )))
}

/// Execute `plan` on Slurm: submit the stages with units not done and the publishing job, print
/// their job ids (stdout: one `stage job tasks` line each), release DIR's lock, and with `wait`
/// follow the jobs until the last one ends. Returns the marker's path once the outputs are
/// published (every unit was done already, or `wait` and the run succeeded), None otherwise.
pub(crate) fn run(
    store: &Store,
    plan: &Plan,
    opts: &Options,
    command: &str,
    lock: Lock,
    ours: &dyn Fn(&str) -> bool,
) -> Result<Option<PathBuf>> {
    let done: Vec<bool> = (0..plan.units.len())
        .map(|i| store.done(&unit_ref(plan, i)).is_some())
        .collect();
    let arrays = stages(plan, &done, opts.tiles_per_task)?;
    if arrays.stages.is_empty() && !opts.plan_only {
        let marker = crate::exec::publish::publish_and_gc(store, plan, ours)?;
        drop(lock);
        eprintln!(
            "talus: slurm: every unit of the plan is done: nothing to submit; outputs published"
        );
        return Ok(Some(marker));
    }
    let talus = std::env::current_exe()
        .map_err(|e| Error::Internal(format!("the path of this talus binary: {e}")))?;
    let sub = record::create(store, plan, command, opts, &arrays, &talus)?;
    let dir = record::dir(store, sub.number);
    if opts.plan_only {
        drop(lock);
        eprintln!(
            "talus: slurm: planned {} job(s), submitted nothing (--plan-only): the plan, the sbatch \
             scripts and submit.sh (the sbatch commands) are in {}",
            sub.stages.len(),
            dir.display()
        );
        for s in &sub.stages {
            println!(
                "{} {} {}",
                s.kind,
                dir.join(&s.script).display(),
                s.tasks.len()
            );
        }
        return Ok(None);
    }
    let ids = cluster::submit_chain(&dir, &sub)?;
    record::save_jobs(store, sub.number, &ids)?;
    // The tasks never need the lock; the publishing job takes it.
    drop(lock);
    eprintln!(
        "talus: slurm: submission {} of {} job array(s) in {} (scripts, logs, task reports)",
        sub.number,
        ids.len(),
        dir.display()
    );
    for (s, id) in sub.stages.iter().zip(&ids) {
        println!("{} {} {}", s.kind, id, s.tasks.len());
    }
    if !opts.wait {
        eprintln!(
            "talus: slurm: submitted; follow with `talus status {}`, the outputs appear when the \
             {PUBLISH} job {} ends",
            store.dir().display(),
            ids.last().map_or("", String::as_str)
        );
        return Ok(None);
    }
    wait(store, &sub, &ids)?;
    Ok(Some(crate::exec::publish::marker_path(store, plan)?))
}

/// How often `--wait` asks Slurm.
const POLL: Duration = Duration::from_secs(1);

/// Follow submission `sub` (arrays `ids`) until none of its tasks is queued or running; a line
/// on stderr as each stage ends. Ok when the publishing job completed; otherwise `Error::Jobs`
/// naming the tasks that failed, were cancelled or timed out.
fn wait(store: &Store, sub: &record::Submission, ids: &[String]) -> Result<()> {
    let started = Instant::now();
    let mut reported = vec![false; ids.len()];
    let mut last: HashMap<String, cluster::JobState> = HashMap::new();
    loop {
        if crate::interrupt::requested() {
            eprintln!(
                "talus: slurm: stopped waiting; the jobs go on (talus status {})",
                store.dir().display()
            );
            return Err(Error::Interrupted);
        }
        match cluster::states(ids) {
            Ok(s) => last = s,
            Err(cluster::Unavailable(why)) => {
                eprintln!("talus: slurm: squeue failed ({why}); asking again");
            }
        }
        let mut all_final = true;
        for (k, (stage, id)) in sub.stages.iter().zip(ids).enumerate() {
            let tasks: Vec<Option<&cluster::JobState>> = (0..stage.tasks.len())
                .map(|t| last.get(&format!("{id}_{t}")))
                .collect();
            // A task Slurm does not (or no longer) list counts as ended: its own report tells.
            let ended = tasks.iter().all(|s| s.is_none_or(|s| !s.state.is_active()));
            all_final &= ended;
            if ended && !reported[k] {
                reported[k] = true;
                let mut counts: Vec<(String, usize)> = Vec::new();
                for s in &tasks {
                    let name = s.map_or("not listed (never ran)".to_string(), |s| {
                        s.state.to_string()
                    });
                    match counts.iter_mut().find(|(n, _)| *n == name) {
                        Some(c) => c.1 += 1,
                        None => counts.push((name, 1)),
                    }
                }
                let counts: Vec<String> = counts.iter().map(|(n, c)| format!("{c} {n}")).collect();
                eprintln!(
                    "talus: slurm: {} (job {id}, {} task(s)): {} after {:.0} s",
                    stage.kind,
                    stage.tasks.len(),
                    counts.join(", "),
                    started.elapsed().as_secs_f64()
                );
            }
        }
        if all_final {
            break;
        }
        std::thread::sleep(POLL);
    }
    let report = status::Report::gather(store)?;
    let publish_ok = report.submission_ok();
    if publish_ok {
        return Ok(());
    }
    Err(Error::Jobs(format!(
        "the Slurm run failed:\n{}\nrun the same command with --resume to submit what is missing",
        report.failures().join("\n")
    )))
}

/// The absolute form of `dir` (scripts and tasks run elsewhere: no relative paths).
pub(crate) fn absolute(dir: &Path) -> Result<PathBuf> {
    std::fs::canonicalize(dir).map_err(|e| Error::output(dir, e))
}

#[cfg(test)]
mod tests {
    use super::scripts::quote;
    use super::{split_args, stages};
    use crate::plan::Spec;

    /// Each array waits for the arrays holding its units' dependencies, and through a
    /// dependency done already (or a tail) to the arrays of what that one depends on.
    #[test]
    fn arrays_wait_for_what_their_units_read() {
        let mut plan = crate::plan::tests::empty_plan();
        let t0 = plan.push(Spec::survey("tiling", 0), "t0", &[], vec![]);
        let t1 = plan.push(Spec::survey("tiling", 1), "t1", &[], vec![]);
        let align = plan.push(Spec::survey("align", 1), "a1", &[], vec![t0, t1]);
        let tile = crate::plan::tile_id([0, 0]);
        let field = plan.push(Spec::survey_tile("field", 0, tile), "f", &[], vec![t0]);
        let orient = plan.push(Spec::survey("orient", 0), "o", &[], vec![field]);
        let m3c2 = plan.push(Spec::tile("m3c2", 0, tile), "m", &[], vec![t0, t1, orient]);
        let stable = plan.push(Spec::pair("stable", 0), "s", &[], vec![m3c2]);
        let done = |d: &[usize]| {
            (0..plan.units.len())
                .map(|i| d.contains(&i))
                .collect::<Vec<_>>()
        };
        let arrays = stages(&plan, &done(&[]), 1).unwrap();
        let kinds = |a: &super::Arrays| a.stages.iter().map(|s| s.kind).collect::<Vec<_>>();
        let after = |kind: &str| -> Vec<&str> {
            let a = arrays.stages.iter().find(|a| a.kind == kind).unwrap();
            a.after.iter().map(|&k| arrays.stages[k].kind).collect()
        };
        // The orientation at the end of the field, the stable ground at the end of M3C2: no
        // array of their own. Not the alignment: at the tiling's end it would hold back the
        // field, which waits for the tiling and not for it.
        assert_eq!(kinds(&arrays), ["tiling", "align", "field", "m3c2"]);
        assert_eq!(after("tiling"), Vec::<&str>::new());
        assert_eq!(after("align"), ["tiling"]);
        assert_eq!(after("field"), ["tiling"]);
        // Through the orientation to the field it reads.
        assert_eq!(after("m3c2"), ["tiling", "field"]);
        let tails: Vec<(&str, Vec<usize>, Vec<usize>)> = (arrays.tails.iter())
            .map(|t| (t.kind, t.units.clone(), t.hosts.clone()))
            .collect();
        assert_eq!(
            tails,
            [
                ("orient", vec![orient], vec![2]),
                ("stable", vec![stable], vec![3])
            ]
        );
        assert!(arrays.tails_of(0).is_empty());
        let _ = align;
        // M3C2 done, the before survey's tiling to do again: stable at its end (it reads the
        // tiling through the M3C2 unit).
        let arrays = stages(&plan, &done(&[t1, align, field, orient, m3c2]), 1).unwrap();
        assert_eq!(kinds(&arrays), ["tiling"]);
        assert_eq!(arrays.tails_of(0), [stable]);
    }

    /// A tail whose inputs are in two arrays neither waits for is computed at the end of both;
    /// one whose inputs are in arrays one of which waits for the other, at the end of that one.
    #[test]
    fn a_tail_is_hosted_by_the_arrays_that_end_last() {
        let mut plan = crate::plan::tests::empty_plan();
        let t0 = plan.push(Spec::survey("tiling", 0), "t0", &[], vec![]);
        let tile = crate::plan::tile_id([0, 0]);
        let field = plan.push(Spec::survey_tile("field", 0, tile), "f", &[], vec![t0]);
        let m3c2 = plan.push(Spec::tile("m3c2", 0, tile), "m", &[], vec![t0]);
        let vol = plan.push(Spec::tile("volumes", 0, tile), "v", &[], vec![m3c2, t0]);
        plan.push(Spec::pair("outputs", 0), "o", &[], vec![field, vol, t0]);
        let arrays = stages(&plan, &vec![false; plan.units.len()], 1).unwrap();
        let kinds: Vec<&str> = arrays.stages.iter().map(|s| s.kind).collect();
        assert_eq!(kinds, ["tiling", "field", "m3c2", "volumes"]);
        assert_eq!(arrays.tails[0].hosts, [1, 3]);
        // A unit in parts is never a tail.
        let mut plan = crate::plan::tests::empty_plan();
        let t0 = plan.push(Spec::survey("tiling", 0), "t0", &[], vec![]);
        let part = |k| Spec::survey_part("aligned", 0, k);
        plan.push(part(0), "a", &[], vec![t0]);
        plan.push(part(1), "a", &[], vec![t0]);
        let arrays = stages(&plan, &vec![false; plan.units.len()], 1).unwrap();
        assert_eq!(arrays.stages.len(), 2);
        assert!(arrays.tails.is_empty());
    }

    #[test]
    fn slurm_args_split_like_a_shell() {
        let v = split_args(r#"-p long  -A geo --time=1:00:00 --comment='a b' "--x=\"y\"" c\ d"#)
            .unwrap();
        assert_eq!(
            v,
            [
                "-p",
                "long",
                "-A",
                "geo",
                "--time=1:00:00",
                "--comment=a b",
                "--x=\"y\"",
                "c d"
            ]
        );
        assert!(split_args("").unwrap().is_empty());
        assert_eq!(split_args("''").unwrap(), [""]);
        assert!(split_args("--comment='open").is_err());
    }

    #[test]
    fn quoted_words_come_back_through_the_splitter() {
        for w in ["plain", "a b", "it's", "", "--mem=2G", "$HOME", "x\"y"] {
            assert_eq!(split_args(&quote(w)).unwrap(), [w]);
        }
    }
}
