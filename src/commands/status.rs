//! `talus status DIR`: where a run stands — its units, its Slurm jobs, whether its outputs are
//! published and whole.

use crate::error::Result;
use crate::exec::slurm::status::Report;
use crate::store::Store;

/// `talus status DIR`.
pub fn print(dir: &std::path::Path) -> Result<()> {
    let store = Store::open(dir, false)?;
    store.finish_interrupted_publish("talus status")?;
    let report = Report::gather(&store)?;
    print!("{}", report.render());
    Ok(())
}
