//! Talking to Slurm through its client commands: `sbatch` to submit, `squeue -t all` for the
//! states of tasks (it lists finished jobs until slurmctld forgets them, `MinJobAge`; `sacct`
//! needs accounting storage, which many clusters and test setups lack), `scancel` to take back a
//! half-submitted chain.

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

use super::record::Submission;
use super::scripts::sbatch_args;
use crate::error::{Error, Result};

/// A Slurm job state as squeue's `%T` prints it (PENDING, RUNNING, COMPLETED, FAILED, CANCELLED,
/// TIMEOUT, OUT_OF_MEMORY, NODE_FAIL, …).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct TaskState(pub String);

impl TaskState {
    /// Not ended yet (queued, running, completing, suspended, requeued, …).
    pub(crate) fn is_active(&self) -> bool {
        !matches!(
            self.0.as_str(),
            "COMPLETED"
                | "FAILED"
                | "CANCELLED"
                | "TIMEOUT"
                | "OUT_OF_MEMORY"
                | "NODE_FAIL"
                | "PREEMPTED"
                | "BOOT_FAIL"
                | "DEADLINE"
                | "REVOKED"
                | "SPECIAL_EXIT"
        )
    }

    pub(crate) fn is_completed(&self) -> bool {
        self.0 == "COMPLETED"
    }

    /// Waiting in the queue (for resources, or for its dependency).
    pub(crate) fn is_pending(&self) -> bool {
        self.0 == "PENDING"
    }
}

impl std::fmt::Display for TaskState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

/// What squeue says of one array task.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct JobState {
    pub state: TaskState,
    /// squeue's `%r`: Dependency, DependencyNeverSatisfied, TimeLimit, NonZeroExitCode, None, …
    pub reason: String,
    /// The task's own job id (`%A`; what `SLURM_JOB_ID` was in it).
    pub job: String,
}

/// Slurm could not be asked (no squeue on PATH, no controller).
#[derive(Debug)]
pub(crate) struct Unavailable(pub String);

fn squeue(ids: &str) -> std::result::Result<std::process::Output, Unavailable> {
    Command::new("squeue")
        .args(["-h", "-t", "all", "-r", "-j", ids, "-o", "%i|%T|%r|%A"])
        .output()
        .map_err(|e| Unavailable(format!("squeue: {e}")))
}

fn parse(text: &str, into: &mut HashMap<String, JobState>) {
    for line in text.lines() {
        let f: Vec<&str> = line.trim().split('|').collect();
        if f.len() == 4 {
            into.insert(
                f[0].to_string(),
                JobState {
                    state: TaskState(f[1].to_string()),
                    reason: f[2].to_string(),
                    job: f[3].to_string(),
                },
            );
        }
    }
}

/// The state of every task Slurm still knows of arrays `ids`, by `<array>_<task>`. A job id
/// slurmctld has forgotten (or never had) is simply absent.
pub(crate) fn states(
    ids: &[String],
) -> std::result::Result<HashMap<String, JobState>, Unavailable> {
    let mut out = HashMap::new();
    if ids.is_empty() {
        return Ok(out);
    }
    let o = squeue(&ids.join(","))?;
    if o.status.success() {
        parse(&String::from_utf8_lossy(&o.stdout), &mut out);
        return Ok(out);
    }
    // One unknown id fails the whole query: ask for each id alone.
    for id in ids {
        let o = squeue(id)?;
        if o.status.success() {
            parse(&String::from_utf8_lossy(&o.stdout), &mut out);
        } else {
            let err = String::from_utf8_lossy(&o.stderr);
            if !err.contains("Invalid job id") {
                // Its last line says it (the others: its retries, DNS lookups).
                let last = err.trim().lines().last().unwrap_or("").to_string();
                return Err(Unavailable(last));
            }
        }
    }
    Ok(out)
}

/// Submit every array of `sub` (scripts in `dir`), each `afterok` on the arrays it waits for
/// (`StageRecord::after`); their job ids. If an sbatch fails, the arrays already submitted are cancelled: no half chain is left.
pub(crate) fn submit_chain(dir: &Path, sub: &Submission) -> Result<Vec<String>> {
    let mut ids: Vec<String> = Vec::new();
    for k in 0..sub.stages.len() {
        let after: Vec<String> = sub.stages[k]
            .after
            .iter()
            .filter_map(|&j| ids.get(j).cloned())
            .collect();
        let args = sbatch_args(sub, k, &after);
        let out = Command::new("sbatch").args(&args).current_dir(dir).output();
        let failure = match out {
            Ok(o) if o.status.success() => {
                let text = String::from_utf8_lossy(&o.stdout);
                // --parsable: "id" or "id;cluster".
                let id = text.trim().split(';').next().unwrap_or("").to_string();
                if !id.is_empty() && id.chars().all(|c| c.is_ascii_digit()) {
                    ids.push(id);
                    continue;
                }
                format!("sbatch printed {:?}, not a job id", text.trim())
            }
            Ok(o) => format!(
                "sbatch {} failed: {}",
                args.join(" "),
                String::from_utf8_lossy(&o.stderr).trim()
            ),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(Error::Usage(
                    "--executor slurm: no sbatch on PATH (Slurm's client commands are needed \
                     where talus submits)"
                        .into(),
                ))
            }
            Err(e) => format!("sbatch: {e}"),
        };
        if !ids.is_empty() {
            let _ = Command::new("scancel").args(&ids).output();
        }
        return Err(Error::Jobs(format!(
            "{failure}{}",
            if ids.is_empty() {
                String::new()
            } else {
                format!(
                    " (cancelled the arrays already submitted: {})",
                    ids.join(" ")
                )
            }
        )));
    }
    Ok(ids)
}
