//! Releasing a finished unit's files once the run that read them is published: the units of an
//! intermediate stage (tiles, per-tile M3C2 results) take several times the inputs' size on
//! disk, and a campaign lives on one disk for years. The unit's record stays — rewritten
//! atomically with no files and `released` set — so the unit still counts as done for the units
//! that read it (their keys, the plan, `talus status`), and the executor computes it again, the
//! same bytes, before a unit that needs its files runs (`exec::run_units`).

use talus_base::{Error, Result};

use super::fsops::{remove_any, replace_file, sorted_names};
use super::record::{Record, RECORD_FILE};
use super::unit_ref::UnitRef;
use super::Store;

impl Store {
    /// Release finished `unit`: its record rewritten with only the files `kept` (`released`),
    /// then every other entry of its directory removed. Returns the bytes freed (0 for a unit
    /// not done or already released). A crash between the two steps leaves files no record
    /// names, removed by the next release; a crash before the first leaves the unit as it was.
    pub fn release(&self, unit: &UnitRef, kept: &[&str]) -> Result<u64> {
        let Some(record) = self.done(unit) else {
            return Ok(0);
        };
        let dir = self.unit_dir(unit)?;
        let (keep, free): (Vec<_>, Vec<_>) = record
            .files
            .iter()
            .cloned()
            .partition(|f| kept.contains(&f.name.as_str()));
        let freed: u64 = free.iter().map(|f| f.size).sum();
        if !record.released {
            let bare = Record {
                files: keep.clone(),
                released: true,
                ..record
            };
            let bytes = serde_json::to_vec_pretty(&bare)
                .map_err(|e| Error::Internal(format!("record of {unit}: {e}")))?;
            let path = dir.join(RECORD_FILE);
            // The record keeps the time of the commit: when the unit was computed.
            let committed = std::fs::metadata(&path).and_then(|m| m.modified()).ok();
            replace_file(&self.tmp(), &path, &bytes)?;
            if let Some(t) = committed {
                let _ = std::fs::File::options()
                    .write(true)
                    .open(&path)
                    .and_then(|f| f.set_modified(t));
            }
        }
        for name in sorted_names(&dir)? {
            if name != RECORD_FILE && !keep.iter().any(|f| f.name == name) {
                remove_any(&dir.join(&name))?;
            }
        }
        Ok(freed)
    }
}
