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
    /// For commands that only read DIR (`talus status`, `talus view`): finish a publish a crash
    /// interrupted, as every run does first, so that what they show is a whole set. Under the
    /// run lock, taken only if free: a run holding it is publishing or will recover itself.
    pub fn finish_interrupted_publish(&self, command: &str) -> Result<Recovery> {
        if !self.journal_path().exists() {
            return Ok(Recovery::Nothing);
        }
        let lock = match self.lock("recover", command) {
            Ok(l) => l,
            Err(Error::Busy { .. }) => return Ok(Recovery::Nothing),
            Err(e) => return Err(e),
        };
        let done = self.recover()?;
        lock.release()?;
        Ok(done)
    }

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
        let journal: Journal =
            serde_json::from_slice(&bytes).map_err(|e| {
                // Name what is there: the files a user must look at (talus's outputs among them may
                // be of two runs).
                let mut names: Vec<String> = super::fsops::sorted_names(&self.dir)
                    .unwrap_or_default()
                    .into_iter()
                    .filter(|n| n != ".talus")
                    .collect();
                let more = names.len().saturating_sub(12);
                names.truncate(12);
                Error::input(
                    &path,
                    format!(
                    "damaged publish journal ({e}): talus cannot tell which files in {} are the \
                     interrupted publish's. It holds: {}{}. Remove talus's outputs among them \
                     (m3c2.laz, events.geojson, events.csv, event_regions.geojson, summary.json, \
                     view.json, terrain.bin, meshes/; a campaign's campaign.csv, campaign.json, \
                     report.html, timeseries.laz, magnitude_frequency.csv, pairs/) and this file, \
                     then run the command again with --resume",
                    self.dir.display(),
                    if names.is_empty() { "nothing".to_string() } else { names.join(", ") },
                    if more > 0 { format!(" and {more} more") } else { String::new() }
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
