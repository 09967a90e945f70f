//! Writing a unit: files go into a fresh directory under `tmp/`, then [`UnitWriter::commit`]
//! writes the record, fsyncs everything and renames the directory to `units/<kind>/<name>` —
//! the one atomic step after which the unit exists. A writer killed at any point before it
//! leaves only a directory in `tmp/`, which nothing takes for a unit and gc removes.

use std::collections::BTreeMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use talus_base::{Error, Result};

use super::fsops::{crc_and_size, out_err, remove_any, sync_dir, sync_files, tmp_name, trash};
use super::process;
use super::record::{Record, RecordFile, Timing, RECORD_FILE};
use super::unit_ref::{check_rel_path, UnitRef};
use super::Store;

/// A unit being written (see the module doc). Dropping it uncommitted deletes its directory.
#[derive(Debug)]
pub struct UnitWriter {
    store: Store,
    unit: UnitRef,
    dir: PathBuf,
    files: BTreeMap<String, (u32, u64)>,
    committed: bool,
}

impl Store {
    /// Start writing `unit` in a fresh directory of `tmp/`, named with the unit and a unique
    /// owner suffix (host, pid, pid start, counter, time: never the same twice on any host).
    pub fn begin(&self, unit: &UnitRef) -> Result<UnitWriter> {
        unit.check()?;
        let dir = tmp_name(&self.tmp(), &format!("unit.{}.{}", unit.kind, unit.name));
        fs::create_dir(&dir).map_err(out_err(&dir))?;
        Ok(UnitWriter {
            store: self.clone(),
            unit: unit.clone(),
            dir,
            files: BTreeMap::new(),
            committed: false,
        })
    }
}

impl UnitWriter {
    /// Where to write `file` (a `/`-separated relative name; its directories are created).
    pub fn path(&self, file: &str) -> Result<PathBuf> {
        check_rel_path("unit file", file)?;
        if file == RECORD_FILE {
            return Err(Error::Internal(format!(
                "unit {}: {RECORD_FILE} is the store's own file",
                self.unit
            )));
        }
        let path = self.dir.join(file);
        if let Some(parent) = path.parent() {
            fs::create_dir_all(parent).map_err(out_err(parent))?;
        }
        Ok(path)
    }

    /// Note `file` as written, with the CRC-32 and size its writer computed while writing.
    pub fn add(&mut self, file: &str, crc32: u32, size: u64) {
        self.files.insert(file.to_string(), (crc32, size));
    }

    /// Note `file` as written, reading it once for its CRC-32 and size.
    pub fn add_file(&mut self, file: &str) -> Result<()> {
        let path = self.path(file)?;
        let (crc, size) = crc_and_size(&path).map_err(out_err(&path))?;
        self.add(file, crc, size);
        Ok(())
    }

    /// Finish the unit: check that the directory holds exactly the noted files with their sizes,
    /// write `record.json`, fsync files and directories, and rename the directory into `units/`.
    /// If another process finished the same unit first (units are deterministic, so its content
    /// is ours) its directory is kept and ours deleted; a damaged one in the way is thrown away.
    /// `timing` is kept beside the meta ([`Record::timing`]).
    pub fn commit(self, meta: serde_json::Value, timing: Option<Timing>) -> Result<Record> {
        let mut files = Vec::with_capacity(self.files.len());
        for (name, &(crc32, size)) in &self.files {
            check_rel_path("unit file", name)?;
            let path = self.dir.join(name);
            let actual = fs::metadata(&path).map_err(out_err(&path))?.len();
            if actual != size {
                return Err(Error::Internal(format!(
                    "{}: noted with {size} bytes, holds {actual}",
                    path.display()
                )));
            }
            files.push(RecordFile {
                name: name.clone(),
                size,
                crc32,
            });
        }
        let mut dirs = Vec::new();
        let mut present = Vec::new();
        walk(&self.dir, "", &mut dirs, &mut present)?;
        if let Some(stray) = present.iter().find(|f| !self.files.contains_key(*f)) {
            return Err(Error::Internal(format!(
                "{}: written but not noted with add/add_file (a unit holds exactly its listed files)",
                self.dir.join(stray).display()
            )));
        }
        sync_files(
            &files
                .iter()
                .map(|f| self.dir.join(&f.name))
                .collect::<Vec<_>>(),
        )?;
        let record = Record {
            unit: self.unit.clone(),
            files,
            meta,
            timing,
            created: process::now_secs(),
            writer: format!("{}:{}", process::host(), std::process::id()),
            released: false,
        };
        let bytes = serde_json::to_vec_pretty(&record)
            .map_err(|e| Error::Internal(format!("record of {}: {e}", self.unit)))?;
        let rpath = self.dir.join(RECORD_FILE);
        fs::File::create_new(&rpath)
            .and_then(|mut f| f.write_all(&bytes).and_then(|()| f.sync_all()))
            .map_err(out_err(&rpath))?;
        for d in &dirs {
            sync_dir(d)?;
        }
        self.publish_dir(record)
    }

    /// The rename into `units/`, and what to do when the name is taken.
    fn publish_dir(mut self, record: Record) -> Result<Record> {
        let kind_dir = self.store.units().join(&self.unit.kind);
        fs::create_dir_all(&kind_dir).map_err(out_err(&kind_dir))?;
        let target = kind_dir.join(&self.unit.name);
        // A damaged unit in the way is trashed and the rename retried; a second damaged one
        // appearing in between (another writer's commit racing ours) is not worth a third try.
        for _ in 0..3 {
            match fs::rename(&self.dir, &target) {
                Ok(()) => {
                    self.committed = true;
                    sync_dir(&kind_dir)?;
                    sync_dir(&self.store.units())?;
                    return Ok(record);
                }
                Err(e) if !target.exists() => return Err(Error::output(&target, e)),
                Err(_) => {}
            }
            if let Some(theirs) = self.store.done(&self.unit) {
                // Dropping `self` deletes our directory.
                return Ok(theirs);
            }
            trash(&self.store.tmp(), &target)?;
        }
        Err(Error::Internal(format!(
            "{}: kept being replaced by damaged units while committing",
            target.display()
        )))
    }
}

impl Drop for UnitWriter {
    fn drop(&mut self) {
        if !self.committed {
            let _ = remove_any(&self.dir);
        }
    }
}

/// Every directory (including `dir`) and every file (relative names) below `dir`.
fn walk(dir: &Path, rel: &str, dirs: &mut Vec<PathBuf>, files: &mut Vec<String>) -> Result<()> {
    dirs.push(dir.to_path_buf());
    for entry in fs::read_dir(dir).map_err(out_err(dir))? {
        let entry = entry.map_err(out_err(dir))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let name = if rel.is_empty() {
            name
        } else {
            format!("{rel}/{name}")
        };
        let path = entry.path();
        if entry.file_type().map_err(out_err(&path))?.is_dir() {
            walk(&path, &name, dirs, files)?;
        } else if name != RECORD_FILE {
            files.push(name);
        }
    }
    Ok(())
}
