//! Resume manifest (SPEC.md §3 "Resume"): which units of a run (a tile, a stage of a tile, an
//! event) are finished, as human-readable JSON.
//!
//! Every finished unit is an immutable file plus an entry here; the manifest is replaced
//! atomically ([`crate::atomic`]) after each unit, so after a SIGKILL it lists exactly the units
//! whose files were completely written (the unit file is renamed into place before the entry is
//! saved). `key_hash` identifies the inputs and parameters of the whole run; a manifest with a
//! different key (or format version) is discarded by [`Manifest::open`], which is how `--resume`
//! falls back to starting over when something changed.

use crate::atomic::atomic_write;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Current manifest format version.
pub const MANIFEST_VERSION: u32 = 1;

/// One finished unit.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct UnitEntry {
    /// The unit's output file, relative to the run directory (caller's convention).
    pub file: String,
    /// Checksum of that file (e.g. [`file_checksum`]), so a damaged file can be detected.
    pub checksum: String,
    /// Hash of exactly what this unit depends on (its inputs and the parameters it uses).
    pub inputs_hash: String,
}

/// The resume state of a run.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Manifest {
    pub version: u32,
    pub key_hash: String,
    /// Finished units by name (sorted, so the JSON is stable and diffable).
    pub units: BTreeMap<String, UnitEntry>,
}

impl Manifest {
    /// An empty manifest for a run keyed by `key_hash`.
    pub fn new(key_hash: impl Into<String>) -> Self {
        Manifest {
            version: MANIFEST_VERSION,
            key_hash: key_hash.into(),
            units: BTreeMap::new(),
        }
    }

    /// Read a manifest. A missing file is [`Error::Io`] (kind `NotFound`); undecodable JSON is
    /// [`Error::Corrupt`].
    pub fn load(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        serde_json::from_slice(&bytes).map_err(|e| Error::corrupt(path, e.to_string()))
    }

    /// The manifest to resume from: the one at `path` if it exists, is readable, and has this
    /// format version and `key_hash`; otherwise a fresh empty one (the run starts over). Only
    /// real I/O failures (e.g. permission denied) are errors.
    pub fn open(path: &Path, key_hash: &str) -> Result<Self> {
        Self::load_or_new(path, key_hash, |m| {
            m.version == MANIFEST_VERSION && m.key_hash == key_hash
        })
    }

    /// The manifest at `path` when it exists, is readable and `keep` accepts it; otherwise a
    /// fresh empty one for `key_hash` (a missing or damaged manifest only costs the redo of its
    /// units). Only real I/O failures (e.g. permission denied) are errors.
    pub fn load_or_new(
        path: &Path,
        key_hash: &str,
        keep: impl FnOnce(&Manifest) -> bool,
    ) -> Result<Self> {
        match Manifest::load(path) {
            Ok(m) if keep(&m) => Ok(m),
            Ok(_) | Err(Error::Corrupt { .. }) => Ok(Manifest::new(key_hash)),
            Err(Error::Io { source, .. }) if source.kind() == std::io::ErrorKind::NotFound => {
                Ok(Manifest::new(key_hash))
            }
            Err(e) => Err(e),
        }
    }

    /// Write the manifest atomically (tmp + fsync + rename + fsync of the directory).
    pub fn save(&self, path: &Path) -> Result<()> {
        let mut json = serde_json::to_vec_pretty(self)
            .map_err(|e| Error::invalid(path, format!("cannot encode manifest: {e}")))?;
        json.push(b'\n');
        atomic_write(path, &json)
    }

    /// True when `unit` is recorded as finished with these inputs.
    pub fn is_done(&self, unit: &str, inputs_hash: &str) -> bool {
        self.units
            .get(unit)
            .is_some_and(|e| e.inputs_hash == inputs_hash)
    }

    /// Record `unit` as finished (replacing an older entry). Call [`Self::save`] to persist.
    pub fn record(&mut self, unit: impl Into<String>, entry: UnitEntry) {
        self.units.insert(unit.into(), entry);
    }

    /// Forget `unit` (e.g. its file turned out to be corrupt).
    pub fn forget(&mut self, unit: &str) -> Option<UnitEntry> {
        self.units.remove(unit)
    }
}

/// Checksum of a file's content as stored in [`UnitEntry::checksum`]: `crc32:` and 8 hex digits
/// (CRC-32/IEEE, the same checksum the tile format uses; fast, and meant to catch damage, not
/// tampering). Reads the file in 1 MiB blocks.
pub fn file_checksum(path: &Path) -> Result<String> {
    use std::io::Read;
    let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut h = crc32fast::Hasher::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).map_err(|e| Error::io(path, e))?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(format!("crc32:{:08x}", h.finalize()))
}

#[cfg(test)]
mod tests;
