//! `talus status DIR`: where a run stands — its units, its Slurm jobs, whether its outputs are
//! published and whole.

use crate::error::Result;
use crate::exec::slurm::status::Report;
use crate::store::{Recovery, Store};

/// `talus status DIR`.
pub(crate) fn print(dir: &std::path::Path) -> Result<()> {
    // Reading only: a finished result on a read-only mount or a full disk can be inspected.
    let store = Store::inspect(dir)?;
    let recovery =
        store.finish_interrupted_publish("talus status", &crate::exec::publish::any_output)?;
    let report = Report::gather(&store)?;
    print!("{}", report.render());
    if let Recovery::Unfinished(why) = recovery {
        println!("{}", unfinished_note(dir, &why));
    }
    Ok(())
}

/// What a reading command says when it found a publish cut short and could not finish it.
pub(crate) fn unfinished_note(dir: &std::path::Path, why: &str) -> String {
    format!(
        "note: a publish into {} was cut short and could not be finished here ({why}): the \
         outputs may be part of a set; any talus command on it where it can be written (`talus \
         status {}`) finishes it",
        dir.display(),
        dir.display()
    )
}
