//! Claims: `claims/<run>/<kind>/<name>` says which process computes a unit right now, so that
//! the threads of a run, `talus worker` processes and Slurm tasks on other hosts do not all
//! compute the same unit.
//!
//! A claim only saves work; correctness never depends on it: units are deterministic and a
//! second commit of the same unit keeps the first (see [`UnitWriter::commit`]). That is why a
//! claim from another host, whose pid cannot be checked, may be taken over after a lease.
//!
//! [`UnitWriter::commit`]: super::UnitWriter::commit

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use talus_base::{Error, Result};

use super::fsops::{no_links, out_err, read_store_file};
use super::owner_file::{self, Acquired, Owner};
use super::unit_ref::{check_component, UnitRef};
use super::Store;

/// The content of a claim file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClaimInfo {
    #[serde(flatten)]
    pub owner: Owner,
    /// Who claims, in the caller's words ("thread 3", "slurm 1234_7").
    pub label: String,
}

/// A held claim; dropping it removes the claim file.
#[derive(Debug)]
pub struct Claim {
    path: PathBuf,
    info: ClaimInfo,
    released: bool,
}

impl Store {
    /// Claim `unit` for this process in run `run` (see the module doc). `None` when a live claim
    /// of another process — or of another thread of this one — holds it. A claim whose owner on
    /// this host is dead, or from another host older than the lease, is taken over.
    pub fn claim(&self, run: &str, unit: &UnitRef, label: &str) -> Result<Option<Claim>> {
        check_component("run id", run)?;
        unit.check()?;
        let rel = Path::new("claims").join(run).join(&unit.kind);
        let dir = self.work.join(&rel);
        // No link on the way: a claim taken over is moved away and deleted, and a planted
        // `claims/<run>` → elsewhere would make that a file outside DIR.
        no_links(&self.work, &rel)?;
        std::fs::create_dir_all(&dir).map_err(out_err(&dir))?;
        no_links(&self.work, &rel)?;
        let path = dir.join(&unit.name);
        let info = ClaimInfo {
            owner: Owner::me(),
            label: label.to_string(),
        };
        let bytes = claim_bytes(&info)?;
        let lease = self.lease;
        match owner_file::acquire(&path, &self.tmp(), &bytes, |b, mtime| {
            Owner::stale(b, mtime, Some(lease))
        })? {
            Acquired::Ours => Ok(Some(Claim {
                path,
                info,
                released: false,
            })),
            Acquired::Held(_) => Ok(None),
        }
    }

    /// The current claim on `unit` in run `run`, if any (live or not: for `talus status`).
    pub fn claim_holder(&self, run: &str, unit: &UnitRef) -> Option<ClaimInfo> {
        check_component("run id", run).ok()?;
        unit.check().ok()?;
        let rel = Path::new("claims").join(run).join(&unit.kind);
        no_links(&self.work, &rel).ok()?;
        let path = self.work.join(rel).join(&unit.name);
        serde_json::from_slice(&read_store_file(&path).ok()?).ok()
    }
}

fn claim_bytes(info: &ClaimInfo) -> Result<Vec<u8>> {
    serde_json::to_vec_pretty(info).map_err(|e| Error::Internal(format!("claim: {e}")))
}

#[cfg(test)]
impl Claim {
    /// The claim file (the tests look at it).
    pub(crate) fn path(&self) -> &std::path::Path {
        &self.path
    }
}

impl Drop for Claim {
    fn drop(&mut self) {
        if !self.released {
            let _ = owner_file::release(&self.path, &self.info.owner.token);
        }
    }
}
