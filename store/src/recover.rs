//! Finishing or undoing a publish that a crash interrupted (its journal `.talus/publishing` is
//! still there). Run at the start of every command on a DIR, under the run lock.

use std::io;

use talus_base::{Error, Result};

use super::publish::Journal;
use super::Store;

/// What [`Store::recover`] did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Recovery {
    /// No publish was interrupted.
    Nothing,
    /// The interrupted publish was finished: DIR holds its complete set.
    RolledForward,
    /// Some of its sources are gone: DIR was left with no talus outputs.
    RolledBack,
    /// It could not be finished here (why: DIR or `.talus` read-only, a full disk, …): DIR may
    /// hold part of a set until a command that can write finishes it.
    Unfinished(String),
}

impl Store {
    /// For commands that only read DIR (`talus status`, `talus view`): finish a publish a crash
    /// interrupted, as every run does first, so that what they show is a whole set — where they
    /// can: under the run lock, taken only if free (a run holding it is publishing or will
    /// recover itself), and only where DIR can be written ([`Recovery::Unfinished`] says why
    /// not; the caller tells the user). The journal is checked either way ([`Store::recover`]).
    /// `ours` tells talus's outputs from the user's files (any command's).
    pub fn finish_interrupted_publish(
        &self,
        command: &str,
        ours: &dyn Fn(&str) -> bool,
    ) -> Result<Recovery> {
        if self.read_journal(ours)?.is_none() {
            return Ok(Recovery::Nothing);
        }
        let lock = match self.lock("recover", command) {
            Ok(l) => l,
            Err(Error::Busy { .. }) => return Ok(Recovery::Nothing),
            Err(Error::Output { source, .. }) => {
                return Ok(Recovery::Unfinished(source.to_string()))
            }
            Err(e) => return Err(e),
        };
        let done = match self.recover(ours) {
            Err(Error::Output { path, source }) => {
                Recovery::Unfinished(format!("{}: {source}", path.display()))
            }
            other => other?,
        };
        let _ = lock.release();
        Ok(done)
    }

    /// If a publish was interrupted, finish it when all its sources still exist (every step of
    /// it may be redone), else remove what it left so that DIR holds no outputs. A journal that
    /// names anything outside DIR, in `.talus`, or a file `ours` does not take for a talus
    /// output is refused before anything is done (exit 2, naming it).
    pub fn recover(&self, ours: &dyn Fn(&str) -> bool) -> Result<Recovery> {
        let Some(journal) = self.read_journal(ours)? else {
            return Ok(Recovery::Nothing);
        };
        if journal
            .files
            .iter()
            .all(|(src, _)| self.units().join(src).is_file())
        {
            self.apply(&journal)?;
            Ok(Recovery::RolledForward)
        } else {
            self.undo(&journal)?;
            Ok(Recovery::RolledBack)
        }
    }

    /// The journal of an interrupted publish, checked ([`Journal::check`]); None when there is
    /// none.
    fn read_journal(&self, ours: &dyn Fn(&str) -> bool) -> Result<Option<Journal>> {
        let path = self.journal_path();
        let bytes = match super::fsops::read_store_file(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(Error::input(&path, format!("cannot read: {e}"))),
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
                     report.html, timeseries.laz, timeseries.parquet, magnitude_frequency.csv, \
                     pairs/) and this file, \
                     then run the command again with --resume",
                    self.dir.display(),
                    if names.is_empty() { "nothing".to_string() } else { names.join(", ") },
                    if more > 0 { format!(" and {more} more") } else { String::new() }
                ),
                )
            })?;
        journal
            .check(&self.dir, &self.units(), ours)
            .map(Some)
            .map_err(|problem| {
                Error::input(
                    &path,
                    format!(
                        "a publish journal talus did not write (damaged or crafted): {problem}. \
                     Nothing was done; remove this file (and look at what {} holds) before \
                     running talus on it again",
                        self.dir.display()
                    ),
                )
            })
    }
}
