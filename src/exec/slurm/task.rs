//! One Slurm array task (`talus slurm-task DIR --submission N --stage KIND`, what the sbatch
//! scripts run): the units of its slice of the stage, executed like `talus worker` does
//! ([`crate::exec::run_units`]: claims, per-unit records, units already done skipped), with its
//! own report in `tasks/<stage>-<i>.json`. The publishing task takes DIR's lock and publishes.

use std::path::Path;
use std::time::{Duration, Instant};

use super::record::{self, TaskReport};
use super::PUBLISH;
use crate::error::{Error, Result};
use crate::plan::Plan;
use crate::store::Store;

/// How long the publishing task waits for DIR's lock (the submitter holds it for a moment after
/// its last sbatch; a `--wait`ing submitter does not hold it).
const LOCK_PATIENCE: Duration = Duration::from_secs(600);

fn now() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

/// Threads for the units: the CPUs Slurm gave the task.
fn threads() -> usize {
    ["SLURM_CPUS_PER_TASK", "SLURM_CPUS_ON_NODE"]
        .iter()
        .find_map(|v| std::env::var(v).ok()?.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .min(1024)
}

/// Run task `task` (default `SLURM_ARRAY_TASK_ID`) of stage `stage` of submission `number`.
pub(crate) fn run(dir: &Path, number: u32, stage: &str, task: Option<usize>) -> Result<()> {
    let store = Store::open(dir, false)?;
    // The stage names the task's report file: a name, never a path.
    crate::store::check_component("stage", stage)
        .map_err(|_| Error::Usage(format!("slurm-task: --stage {stage:?} is not a stage")))?;
    let (sub, plan) = record::load(&store, number)?;
    let task = match task {
        Some(t) => t,
        None => std::env::var("SLURM_ARRAY_TASK_ID")
            .ok()
            .and_then(|v| v.parse().ok())
            .ok_or_else(|| {
                Error::Usage("slurm-task: no --task and no SLURM_ARRAY_TASK_ID".into())
            })?,
    };
    let s = sub.stages.iter().find(|s| s.kind == stage).ok_or_else(|| {
        Error::Usage(format!(
            "slurm-task: no stage {stage} in submission {number}"
        ))
    })?;
    let names = s.tasks.get(task).ok_or_else(|| {
        Error::Usage(format!(
            "slurm-task: stage {stage} of submission {number} has {} task(s), not {}",
            s.tasks.len(),
            task + 1
        ))
    })?;
    let env = |v: &str| std::env::var(v).unwrap_or_else(|_| "-".into());
    let sdir = record::dir(&store, number);
    let report_path = record::task_report_path(&sdir, stage, task);
    let mut report = TaskReport {
        state: "running".into(),
        task_id: format!("{}_{}", env("SLURM_ARRAY_JOB_ID"), task),
        job_id: env("SLURM_JOB_ID"),
        host: crate::store::Owner::me().host,
        pid: std::process::id(),
        started: now(),
        ended: None,
        computed: 0,
        tails: 0,
        error: None,
    };
    record::save_task_report(&report_path, &report)?;
    let started = Instant::now();
    let result = if stage == PUBLISH {
        // The tails no task computed (found done: nothing to do), then the outputs published.
        let computed = match names.is_empty() {
            true => Ok(0),
            false => units(&store, &plan, names, &report.task_id),
        };
        computed.and_then(|n| publish(&store, &plan).map(|_| n))
    } else {
        units(&store, &plan, names, &report.task_id).and_then(|n| {
            report.tails = tails(&store, &plan, &s.tails, &report.task_id)?;
            Ok(n)
        })
    };
    report.ended = Some(now());
    match &result {
        Ok(n) => {
            report.state = "done".into();
            report.computed = *n;
        }
        Err(Error::Interrupted) => report.state = "interrupted".into(),
        Err(e) => {
            report.state = "failed".into();
            report.error = Some(e.to_string());
        }
    }
    record::save_task_report(&report_path, &report)?;
    let n = result?;
    let tails = match report.tails {
        0 => String::new(),
        t => format!(", and {t} tail(s) of later stages"),
    };
    eprintln!(
        "talus slurm-task: {stage} task {task} of submission {number}: {} unit(s) computed of {}{tails} in {:.1} s",
        n,
        names.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The label a Slurm task claims its units under: `slurm <array job>_<task>`, the same in every
/// attempt of the task (`Store::claim_attempt`).
fn claim_label(task_id: &str) -> String {
    format!("slurm {task_id}")
}

/// The array job of a claim label a Slurm task wrote ([`claim_label`]), if it is one.
pub(crate) fn array_job_of(label: &str) -> Option<&str> {
    label.strip_prefix("slurm ")?.split('_').next()
}

/// The plan indices of the units `names` of the submission.
fn indices(plan: &Plan, names: &[String]) -> Result<Vec<usize>> {
    (names.iter())
        .map(|n| {
            plan.units
                .iter()
                .position(|u| &u.name == n)
                .ok_or_else(|| Error::Internal(format!("unit {n} is not in the submission's plan")))
        })
        .collect()
}

/// Execute the units `names` of `plan`; how many this task computed.
fn units(store: &Store, plan: &Plan, names: &[String], task_id: &str) -> Result<usize> {
    execute(store, plan, &indices(plan, names)?, task_id)
}

/// Execute the units `idx` of `plan` (and whichever of their dependencies are not done); how
/// many this task computed.
fn execute(store: &Store, plan: &Plan, idx: &[usize], task_id: &str) -> Result<usize> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads())
        .build()
        .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
    let label = claim_label(task_id);
    // Slurm counts a task's requeues (after its node failed, or by hand); the first run has none.
    let attempt = std::env::var("SLURM_RESTART_COUNT")
        .ok()
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or(0);
    let report =
        pool.install(|| crate::exec::run_units(store, plan, Some(idx), 1, &label, Some(attempt)))?;
    Ok(report.computed)
}

/// Compute each of the tails `names` (`super::Tail`) not done whose inputs (and what it runs
/// after) are all done: the last task of the arrays it reads sees them so, at once. One whose
/// inputs are not all done is left to a later task (or to a reader, or the publishing job); one
/// another live process holds is left to it. The ready ones go to the executor together (one
/// look at the store's records per pass, not per tail), in passes until a pass computes none
/// (tails may read tails); two tasks ending together with the same ready tails share them
/// through the claims (the executor takes first what nobody holds), the one done first then
/// waiting for the other's. A unit found done stays done: each is looked up once. How many it
/// computed.
fn tails(store: &Store, plan: &Plan, names: &[String], task_id: &str) -> Result<usize> {
    let idx = indices(plan, names)?;
    let mut known_done = vec![false; plan.units.len()];
    let mut done = |u: usize| {
        if !known_done[u] {
            known_done[u] = store.done(&crate::units::unit_ref(plan, u)).is_some();
        }
        known_done[u]
    };
    let held = |i: usize| {
        store
            .claim_holder(&plan.run, &crate::units::unit_ref(plan, i))
            .is_some_and(|c| !c.owner.gone(Some(crate::store::DEFAULT_LEASE)))
    };
    let mut n = 0;
    loop {
        let mut ready = Vec::new();
        for &i in &idx {
            let u = &plan.units[i];
            if !done(i) && u.deps.iter().chain(&u.after).all(|&d| done(d)) && !held(i) {
                ready.push(i);
            }
        }
        if ready.is_empty() {
            return Ok(n);
        }
        let computed = execute(store, plan, &ready, task_id)?;
        if computed == 0 {
            return Ok(n);
        }
        n += computed;
    }
}

/// Take DIR's lock (waiting while another process holds it), publish, drop old units.
fn publish(store: &Store, plan: &Plan) -> Result<()> {
    let command = std::env::args().collect::<Vec<_>>().join(" ");
    let since = Instant::now();
    let lock = loop {
        match store.lock("run", &command) {
            Ok(l) => break l,
            Err(Error::Busy { .. }) if since.elapsed() < LOCK_PATIENCE => {
                crate::interrupt::check()?;
                std::thread::sleep(Duration::from_millis(500));
            }
            Err(e) => return Err(e),
        }
    };
    let ours = crate::exec::publish::outputs_of(plan)?;
    store.recover(&ours)?;
    crate::exec::publish::publish_and_gc(store, plan, &ours)?;
    lock.release()
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_claim_label_names_its_array_job() {
        let label = super::claim_label("518_7");
        assert_eq!(super::array_job_of(&label), Some("518"));
        assert_eq!(super::array_job_of("thread 3"), None);
    }
}
