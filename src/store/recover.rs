//! Finishing or undoing a publish that a crash interrupted (its journal `.talus/publishing` is
//! still there). Run at the start of every command on a DIR, under the run lock.

use std::io;

use crate::error::{Error, Result};

use super::publish::Journal;
use super::Store;

/// What [`Store::recover`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Recovery {
    /// No publish was interrupted.
    Nothing,
    /// The interrupted publish was finished: DIR holds its complete set.
    RolledForward,
    /// Some of its sources are gone: DIR was left with no talus outputs.
    RolledBack,
}

impl Store {
    /// If a publish was interrupted, finish it when all its sources still exist (every step of
    /// it may be redone), else remove what it left so that DIR holds no outputs.
    pub fn recover(&self) -> Result<Recovery> {
        let path = self.journal_path();
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Recovery::Nothing),
            Err(e) => return Err(Error::output(&path, e)),
        };
        // The journal is written atomically, so one that does not parse was damaged from
        // outside; without it the store cannot tell its outputs from the user's files.
        let journal: Journal = serde_json::from_slice(&bytes).map_err(|e| {
            Error::output(
                &path,
                io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!(
                        "damaged publish journal ({e}); remove the outputs and this file by hand"
                    ),
                ),
            )
        })?;
        if journal.files.iter().all(|(src, _)| src.is_file()) {
            self.apply(&journal)?;
            Ok(Recovery::RolledForward)
        } else {
            self.undo(&journal)?;
            Ok(Recovery::RolledBack)
        }
    }
}
