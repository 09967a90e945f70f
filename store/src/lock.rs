//! The run lock: `.talus/lock` says which run owns DIR (one run per DIR; its workers work under
//! that run's id). Unlike a claim, a lock from another host is never taken over by age: two runs
//! publishing into one DIR would mix their outputs, so only a lock whose owner is provably dead
//! (same host, pid gone or reused) is replaced, and otherwise the user decides.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use talus_base::{Error, Result};

use super::owner_file::{self, Acquired, Owner};
use super::unit_ref::check_component;
use super::Store;

/// The content of the lock file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LockInfo {
    #[serde(flatten)]
    pub owner: Owner,
    /// The run's id (claims live under `claims/<run>/`).
    pub run: String,
    /// The command line that took the lock.
    pub command: String,
    /// Anything the run wants `talus status` to show (e.g. its Slurm job ids).
    #[serde(default)]
    pub note: Option<String>,
}

impl LockInfo {
    /// One line for a user: "pid 1234 on vm, started 3 min ago: talus compare a b --out d".
    pub fn describe(&self) -> String {
        let mut s = format!("{}: {}", self.owner.describe(), self.command);
        if let Some(note) = &self.note {
            s.push_str(&format!(" [{note}]"));
        }
        s
    }
}

/// The held lock of a DIR; dropping it removes the lock file if it is still ours.
#[derive(Debug)]
pub struct Lock {
    path: PathBuf,
    token: String,
    released: bool,
}

impl Store {
    fn lock_path(&self) -> PathBuf {
        self.work.join("lock")
    }

    /// Take DIR's lock for run `run`, started by `command`. A stale lock (this host, dead pid)
    /// is replaced; a live one is `Error::Busy` describing its holder.
    pub fn lock(&self, run: &str, command: &str) -> Result<Lock> {
        check_component("run id", run)?;
        let info = LockInfo {
            owner: Owner::me(),
            run: run.to_string(),
            command: command.to_string(),
            note: None,
        };
        let path = self.lock_path();
        let bytes = lock_bytes(&info)?;
        match owner_file::acquire(&path, &self.tmp(), &bytes, |b, mtime| {
            Owner::stale(b, mtime, None)
        })? {
            Acquired::Ours => Ok(Lock {
                path,
                token: info.owner.token.clone(),
                released: false,
            }),
            Acquired::Held(held) => {
                let holder = match serde_json::from_slice::<LockInfo>(&held) {
                    Ok(other) => other.describe(),
                    Err(_) => "a lock file being written, or damaged".to_string(),
                };
                Err(Error::Busy {
                    dir: self.dir.clone(),
                    holder,
                })
            }
        }
    }

    /// Who holds DIR's lock now, if anyone (the file's content; the holder may be dead).
    pub fn lock_holder(&self) -> Option<LockInfo> {
        serde_json::from_slice(&super::fsops::read_store_file(&self.lock_path()).ok()?).ok()
    }
}

fn lock_bytes(info: &LockInfo) -> Result<Vec<u8>> {
    serde_json::to_vec_pretty(info).map_err(|e| Error::Internal(format!("lock: {e}")))
}

impl Lock {
    /// Release the lock now, reporting a failure (dropping releases too, silently).
    pub fn release(mut self) -> Result<()> {
        self.released = true;
        owner_file::release(&self.path, &self.token).map(|_| ())
    }
}

impl Drop for Lock {
    fn drop(&mut self) {
        if !self.released {
            let _ = owner_file::release(&self.path, &self.token);
        }
    }
}
