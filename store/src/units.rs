//! Reading finished units: whether one is done (cheap), whether its bytes are intact
//! (expensive), and throwing one away.

use std::fs;
#[cfg(test)]
use std::io;
use std::path::{Path, PathBuf};

#[cfg(test)]
use talus_base::Error;
use talus_base::Result;

use super::fsops::{crc_and_size, move_to_trash, no_links, trash};
use super::record::Record;
use super::unit_ref::UnitRef;
use super::Store;

impl Store {
    /// The directory of finished `unit` (whether or not it exists).
    pub fn unit_dir(&self, unit: &UnitRef) -> Result<PathBuf> {
        unit.check()?;
        Ok(self.units().join(&unit.kind).join(&unit.name))
    }

    /// The record of finished `unit`: its directory exists, its `record.json` parses and names
    /// this unit, and every listed file exists with the recorded size. Nothing is read but the
    /// record and the files' metadata: a flipped byte is found only where the file is read (a
    /// tile's checksums, `talus status` against the record's CRC-32). No
    /// link is followed on the way (`units/<kind>/<name>/<file>`, a link planted anywhere along
    /// it makes the unit not done): whoever reads a done unit's files reads inside the store.
    pub fn done(&self, unit: &UnitRef) -> Option<Record> {
        let dir = self.unit_dir(unit).ok()?;
        let rel = Path::new(&unit.kind).join(&unit.name);
        no_links(&self.units(), &rel).ok()?;
        let record = Record::read(&dir, unit)?;
        let files_ok = record.files.iter().all(|f| {
            no_links(&dir, Path::new(&f.name)).is_ok()
                && fs::symlink_metadata(dir.join(&f.name))
                    .is_ok_and(|m| m.is_file() && m.len() == f.size)
        });
        files_ok.then_some(record)
    }

    /// The files of finished `unit` edited since its commit: modified after its record was
    /// written (an in-place edit of a published file, which is a hard link to the unit's) and
    /// no longer matching the record's size and CRC-32. Cheap: one `stat` per file, a read only
    /// of a file modified after the commit.
    pub fn edited_files(&self, unit: &UnitRef, record: &Record) -> Vec<String> {
        let Ok(dir) = self.unit_dir(unit) else {
            return Vec::new();
        };
        let Ok(committed) = fs::metadata(dir.join(super::RECORD_FILE)).and_then(|m| m.modified())
        else {
            return Vec::new();
        };
        record
            .files
            .iter()
            .filter(|f| {
                let path = dir.join(&f.name);
                let later = fs::metadata(&path)
                    .and_then(|m| m.modified())
                    .is_ok_and(|t| t > committed);
                later && crc_and_size(&path).map_or(true, |got| got != (f.crc32, f.size))
            })
            .map(|f| f.name.clone())
            .collect()
    }

    /// Re-read every file of finished `unit` and compare size and CRC-32 with `record`. A
    /// missing file is `false`; a file that exists but cannot be read is an error naming it.
    /// (The tests' check of what a unit holds; a run trusts a record and looks for edited
    /// files only, [`Store::edited_files`].)
    #[cfg(test)]
    pub(crate) fn verify(&self, unit: &UnitRef, record: &Record) -> Result<bool> {
        let dir = self.unit_dir(unit)?;
        for f in &record.files {
            let path = dir.join(&f.name);
            match crc_and_size(&path) {
                Ok((crc, size)) if crc == f.crc32 && size == f.size => {}
                Ok(_) => return Ok(false),
                Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
                Err(e) => return Err(Error::output(&path, e)),
            }
        }
        Ok(true)
    }

    /// Throw finished `unit` away: rename its directory into `tmp/` (readers then see it gone
    /// at once, never half-deleted) and delete it there. A unit that does not exist is fine.
    pub fn invalidate(&self, unit: &UnitRef) -> Result<()> {
        let dir = self.unit_dir(unit)?;
        trash(&self.tmp(), &dir).map(|_| ())
    }

    /// [`Store::invalidate`] without the deletion: the unit is gone from the store at once and
    /// its files wait in `tmp/` at the path returned (None: there was no such unit), for the
    /// caller to delete while other work goes on (unlinking a large tile file blocks for
    /// milliseconds), or for gc.
    pub fn invalidate_later(&self, unit: &UnitRef) -> Result<Option<PathBuf>> {
        move_to_trash(&self.tmp(), &self.unit_dir(unit)?)
    }
}
