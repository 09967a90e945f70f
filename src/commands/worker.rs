//! `talus worker DIR`: one more executor of a run's plan (the execution step of
//! [`super::run`]).

use std::path::Path;

use crate::error::{Error, Result};

/// `talus worker DIR`: execute units of the run in DIR until every unit is done (the process
/// that holds DIR's lock publishes).
pub(crate) fn worker(dir: &Path, slots: usize, threads: Option<usize>) -> Result<()> {
    if slots == 0 {
        return Err(Error::Usage(
            "--slots: must be at least 1 (units the worker runs at a time)".into(),
        ));
    }
    let store = crate::store::Store::open(dir, false)?;
    let plan = crate::plan::Plan::load(&store.plan_path())?;
    let threads = match threads {
        Some(0) => return Err(Error::Usage("--threads: must be at least 1".into())),
        Some(t) => t.min(1024),
        None => std::thread::available_parallelism().map_or(1, |n| n.get()),
    };
    let label = format!("worker {}", std::process::id());
    let report = super::run::execute(&store, &plan, threads, slots, &label)?;
    eprintln!(
        "talus worker: {} unit(s) computed, {} found done, in {}",
        report.computed,
        report.reused,
        dir.display()
    );
    Ok(())
}
