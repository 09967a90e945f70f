//! The records of Slurm submissions, in `DIR/.talus/slurm/<n>/` (n = 1, 2, …: one directory per
//! submission, created exclusively, never rewritten by another submission):
//!
//! ```text
//! submission.json      the stages, each task's units (by name), sbatch arguments, the command
//! plan.json            the plan the tasks execute (a later command may replan DIR meanwhile)
//! NN-<stage>.sh        the sbatch script of each stage; NN-publish.sh last
//! submit.sh            the sbatch commands, chained (what talus runs; to review, or run by hand)
//! jobs.json            the job id of each stage's array, once all are submitted
//! logs/<stage>-<i>.out task i's output
//! tasks/<stage>-<i>.json task i's own report (written by that task only)
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{Arrays, Options, PUBLISH};
use crate::error::{Error, Result};
use crate::plan::Plan;
use crate::store::Store;

/// One submission's `submission.json`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub(crate) struct Submission {
    pub number: u32,
    /// The plan's run id.
    pub run: String,
    /// The command line that submitted.
    pub command: String,
    /// Unix seconds.
    pub created: u64,
    /// The talus binary the tasks run (on the shared filesystem).
    pub talus: PathBuf,
    /// DIR, absolute.
    pub dir: PathBuf,
    /// `--slurm-args`, given to every sbatch after talus's own options (so they override them).
    pub sbatch_args: Vec<String>,
    /// `--mem` of each task, MiB: the plan's memory budget.
    pub mem_mib: u64,
    /// `--cpus-per-task` when the user set `--threads`.
    pub cpus: Option<usize>,
    /// The arrays in submission order, the publishing one last.
    pub stages: Vec<StageRecord>,
}

/// One array of a submission.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub(crate) struct StageRecord {
    /// A stage's kind (`super::stage_order`), or [`PUBLISH`].
    pub kind: String,
    /// Its sbatch script, in the submission's directory.
    pub script: String,
    /// The unit names of each task (the publishing job: one task, the tails, which it computes
    /// before it publishes where the arrays' tasks did not).
    pub tasks: Vec<Vec<String>>,
    /// The arrays (indices in [`Submission::stages`]) it waits for, `afterok` (a submission
    /// recorded before this field: empty).
    #[serde(default)]
    pub after: Vec<usize>,
    /// The units of later stages each task computes when its own are done, where their inputs
    /// all are (`super::Tail`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tails: Vec<String>,
}

/// `jobs.json`: the job id of each array, in the order of [`Submission::stages`].
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub(crate) struct Jobs {
    pub ids: Vec<String>,
}

/// What one task reports about itself (`tasks/<stage>-<i>.json`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub(crate) struct TaskReport {
    /// `running`, `done`, `failed` or `interrupted` (SIGTERM: scancel, time limit).
    pub state: String,
    /// `SLURM_ARRAY_JOB_ID`_`SLURM_ARRAY_TASK_ID` and the task's own `SLURM_JOB_ID`.
    pub task_id: String,
    pub job_id: String,
    pub host: String,
    pub pid: u32,
    pub started: u64,
    pub ended: Option<u64>,
    /// Units this task computed (the others of its slice were found done).
    pub computed: usize,
    /// Tails (`super::Tail`) it computed when its own units were done.
    #[serde(default)]
    pub tails: usize,
    pub error: Option<String>,
}

/// `DIR/.talus/slurm`.
pub(crate) fn root(store: &Store) -> PathBuf {
    store.work().join("slurm")
}

/// The directory of submission `n`.
pub(crate) fn dir(store: &Store, n: u32) -> PathBuf {
    root(store).join(n.to_string())
}

/// [`dir`], refused when a link lies on the way to it or to its `tasks/` and `logs/` (what its
/// tasks read and write must stay inside DIR).
pub(crate) fn checked_dir(store: &Store, n: u32) -> Result<PathBuf> {
    for sub in ["tasks", "logs"] {
        let rel = Path::new("slurm").join(n.to_string()).join(sub);
        crate::store::no_links(store.work(), &rel)?;
    }
    Ok(dir(store, n))
}

/// The file of task `task` of stage `kind`'s report in submission directory `dir`.
pub(crate) fn task_report_path(dir: &Path, kind: &str, task: usize) -> PathBuf {
    dir.join("tasks").join(format!("{kind}-{task}.json"))
}

/// The output file of task `task` of stage `kind` in submission directory `dir`.
pub(crate) fn task_log_path(dir: &Path, kind: &str, task: usize) -> PathBuf {
    dir.join("logs").join(format!("{kind}-{task}.out"))
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<()> {
    let bytes = serde_json::to_vec_pretty(value)
        .map_err(|e| Error::Internal(format!("{}: {e}", path.display())))?;
    Ok(talus_tiling::atomic_write(path, &bytes)?)
}

/// A record of DIR's store (a regular file, never through a link: `store::read_store_file`).
fn read_json<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let bytes =
        crate::store::read_store_file(path).map_err(|e| Error::input(path, e.to_string()))?;
    serde_json::from_slice(&bytes)
        .map_err(|e| Error::input(path, format!("not a talus record: {e}")))
}

/// The numbers of DIR's submissions, ascending.
fn numbers(store: &Store) -> Result<Vec<u32>> {
    let root = root(store);
    let mut v: Vec<u32> = match std::fs::read_dir(&root) {
        Ok(rd) => rd
            .filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok())
            .collect(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(Error::output(&root, e)),
    };
    v.sort_unstable();
    Ok(v)
}

/// DIR's latest submission that has a `submission.json`, with its `jobs.json` if it was
/// submitted (None with `--plan-only`, or while it is being submitted).
pub(crate) fn latest(store: &Store) -> Result<Option<(u32, Submission, Option<Jobs>)>> {
    for n in numbers(store)?.into_iter().rev() {
        let d = checked_dir(store, n)?;
        if !d.join("submission.json").is_file() {
            continue;
        }
        let sub: Submission = read_json(&d.join("submission.json"))?;
        let jobs = if d.join("jobs.json").is_file() {
            Some(read_json(&d.join("jobs.json"))?)
        } else {
            None
        };
        return Ok(Some((n, sub, jobs)));
    }
    Ok(None)
}

/// Submission `n` of DIR and the plan its tasks execute.
pub(crate) fn load(store: &Store, n: u32) -> Result<(Submission, Plan)> {
    let d = checked_dir(store, n)?;
    let sub = read_json(&d.join("submission.json"))?;
    let plan = Plan::load(&d.join(crate::store::PLAN_FILE))?;
    Ok((sub, plan))
}

/// Create the next submission's directory with its records and scripts, for the arrays of
/// `plan` and then the publishing job (whose one task computes first the tails the arrays'
/// tasks left, `super::Tail`).
pub(crate) fn create(
    store: &Store,
    plan: &Plan,
    command: &str,
    opts: &Options,
    arrays: &Arrays,
    talus: &Path,
) -> Result<Submission> {
    let abs = super::absolute(store.dir())?;
    for p in [&abs, &talus.to_path_buf()] {
        if p.to_string_lossy().chars().any(|c| c.is_whitespace()) {
            return Err(Error::Usage(format!(
                "--executor slurm: {}: a path with blanks cannot go into an sbatch script",
                p.display()
            )));
        }
    }
    std::fs::create_dir_all(root(store)).map_err(|e| Error::output(root(store), e))?;
    // The next number, taken by creating its directory (two submitters never share one).
    let mut n = numbers(store)?.last().copied().unwrap_or(0) + 1;
    let d = loop {
        let d = dir(store, n);
        match std::fs::create_dir(&d) {
            Ok(()) => break d,
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => n += 1,
            Err(e) => return Err(Error::output(&d, e)),
        }
    };
    for sub in ["logs", "tasks"] {
        std::fs::create_dir_all(d.join(sub)).map_err(|e| Error::output(d.join(sub), e))?;
    }
    plan.save(&d.join(crate::store::PLAN_FILE))?;
    let name = |i: usize| plan.units[i].name.clone();
    let stages = &arrays.stages;
    let mut records: Vec<StageRecord> = stages
        .iter()
        .enumerate()
        .map(|(k, s)| StageRecord {
            kind: s.kind.to_string(),
            script: format!("{:02}-{}.sh", k + 1, s.kind),
            tasks: s
                .tasks
                .iter()
                .map(|t| t.iter().map(|&i| name(i)).collect())
                .collect(),
            after: s.after.clone(),
            tails: arrays.tails_of(k).into_iter().map(name).collect(),
        })
        .collect();
    // Every tail, in plan order: those the arrays' last tasks did not compute.
    let mut tails: Vec<usize> = arrays.tails.iter().flat_map(|t| t.units.clone()).collect();
    tails.sort_unstable();
    records.push(StageRecord {
        kind: PUBLISH.to_string(),
        script: format!("{:02}-{PUBLISH}.sh", stages.len() + 1),
        tasks: vec![tails.iter().map(|&i| name(i)).collect()],
        after: (0..stages.len()).collect(),
        tails: Vec::new(),
    });
    let threads = &plan.params.threads;
    let sub = Submission {
        number: n,
        run: plan.run.clone(),
        command: command.to_string(),
        created: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
        talus: talus.to_path_buf(),
        dir: abs,
        sbatch_args: opts.args.clone(),
        mem_mib: plan.params.memory_bytes.value.div_ceil(1 << 20),
        cpus: (threads.is_user()).then_some(threads.value),
        stages: records,
    };
    super::scripts::write(&d, &sub)?;
    write_json(&d.join("submission.json"), &sub)?;
    Ok(sub)
}

/// Record the job ids of submission `n`'s arrays.
pub(crate) fn save_jobs(store: &Store, n: u32, ids: &[String]) -> Result<()> {
    write_json(
        &dir(store, n).join("jobs.json"),
        &Jobs { ids: ids.to_vec() },
    )
}

/// Write a task's report (only that task writes its file).
pub(crate) fn save_task_report(path: &Path, report: &TaskReport) -> Result<()> {
    write_json(path, report)
}

/// A task's report, if it wrote one.
pub(crate) fn task_report(path: &Path) -> Option<TaskReport> {
    serde_json::from_slice(&crate::store::read_store_file(path).ok()?).ok()
}
