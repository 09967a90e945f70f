//! `record.json`: what a finished unit holds (each file's size and CRC-32), what its producer
//! wants kept (`meta`), and who wrote it when. It is written last, inside the unit's temporary
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

impl Record {
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
