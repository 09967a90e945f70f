//! `record.json`: what a finished unit holds (each file's size and CRC-32), what its producer
//! wants kept (`meta`), how long it ran (`timing`, beside the meta: a producer's field of any
//! name is its own), and who wrote it when. It is written last, inside the unit's temporary
//! directory, before the directory is renamed into `units/`: a unit directory without a record
//! that parses is damage, never a unit.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::unit_ref::{check_rel_path, UnitRef};

/// The record's file name inside a unit directory.
pub const RECORD_FILE: &str = "record.json";

/// One file of a unit.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RecordFile {
    /// Relative to the unit's directory, `/`-separated.
    pub name: String,
    pub size: u64,
    pub crc32: u32,
}

/// The record of a finished unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub unit: UnitRef,
    /// Sorted by name.
    pub files: Vec<RecordFile>,
    /// Whatever the producer keeps with the unit (counts, bounds, ...).
    pub meta: serde_json::Value,
    /// How long the unit ran and its peak resident memory, as its executor measured them (none
    /// in a record written without: [`Record::timing`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timing: Option<Timing>,
    /// Unix seconds when the unit was committed.
    pub created: u64,
    /// `host:pid` of the process that committed it.
    pub writer: String,
    /// Its files were released after the run that used them ([`super::Store::release`]): the
    /// unit is done for the units that read it, and is computed again (the same bytes) before
    /// a unit that needs its files runs.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub released: bool,
}

/// How long a unit ran and the highest resident memory of its process meanwhile.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    pub seconds: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub peak_rss_bytes: Option<u64>,
}

impl Record {
    /// The unit's timing: its own field, or — in a record written by talus 0.2.0 or earlier,
    /// whose executor spliced it into the meta — the meta's `seconds` and `peak_rss_bytes`.
    /// `None` when neither holds it (a damaged record).
    pub fn timing(&self) -> Option<Timing> {
        self.timing.or_else(|| Timing::deserialize(&self.meta).ok())
    }

    /// Read the record of the unit directory `dir`, if it is a regular file (no link), parses,
    /// belongs to `unit` and names only files inside the directory (a damaged or crafted record
    /// must not point a reader elsewhere).
    pub(crate) fn read(dir: &Path, unit: &UnitRef) -> Option<Record> {
        let bytes = super::fsops::read_store_file(&dir.join(RECORD_FILE)).ok()?;
        let record: Record = serde_json::from_slice(&bytes).ok()?;
        let names_ok = record
            .files
            .iter()
            .all(|f| check_rel_path("file", &f.name).is_ok() && f.name != RECORD_FILE);
        (record.unit == *unit && names_ok).then_some(record)
    }

    /// The entry of file `name`, if the unit has it.
    #[cfg(test)]
    pub(crate) fn file(&self, name: &str) -> Option<&RecordFile> {
        self.files.iter().find(|f| f.name == name)
    }
}
