//! The work area of a DIR as a store of immutable units, filled concurrently by many processes
//! (threads of a run, `talus worker DIR` processes, Slurm array tasks on hosts sharing DIR over
//! NFS) — in the spirit of tantivy's segments: every unit is written aside and published by one
//! atomic rename, nothing shared is ever rewritten in place by several writers.
//!
//! ```text
//! DIR/.talus/
//!   lock                          one run per DIR                      (lock.rs)
//!   plan.json                     the run's plan (PLAN_FILE), written by the commands
//!   units/<kind>/<name>/          one finished unit: files + record.json (writer.rs, units.rs);
//!                                 an intermediate one released: its record alone (release.rs)
//!   tmp/                          units being written, trash, temporaries (fsops.rs, gc.rs)
//!   claims/<run>/<kind>/<name>    who computes a unit now              (claim.rs)
//!   cache/inputs.json             content keys of inputs by identity    (content_key.rs)
//!   publishing                    journal of a publish into DIR         (publish.rs, recover.rs)
//! ```
//!
//! A unit's name carries its content key, so a unit never changes: it exists complete or not at
//! all, and two processes computing it produce the same bytes (the first commit is kept). Its
//! one later change: released after a published run, its record is replaced (atomically) by one
//! naming no files, and the files go.
//! Claims only avoid duplicate work; the lock keeps two runs from publishing into one DIR.
//! Everything outside `.talus` is the user's, except the outputs [`Store::publish`] places.

mod claim;
mod content_key;
mod fsops;
mod gc;
mod lock;
mod owner_file;
mod process;
mod publish;
mod record;
mod recover;
mod release;
mod unit_ref;
mod units;
mod writer;

#[cfg(test)]
mod claim_tests;
#[cfg(test)]
mod content_key_tests;
#[cfg(test)]
mod hostile_tests;
#[cfg(test)]
mod lock_tests;
#[cfg(test)]
mod publish_tests;
#[cfg(test)]
mod timing_tests;
#[cfg(test)]
mod unit_tests;

use std::path::{Path, PathBuf};
use std::time::Duration;

pub use claim::{Claim, ClaimInfo};
pub use fsops::{crc_and_size, link_error, no_links, open_store_file, read_store_file, Sweep};
pub use gc::GcReport;
pub use lock::{Lock, LockInfo};
pub use owner_file::Owner;
pub use record::{Record, RecordFile, Timing, RECORD_FILE};
pub use recover::Recovery;
pub use unit_ref::{check_component, check_rel_path, UnitRef};
pub use writer::UnitWriter;

use fsops::out_err;
use talus_base::{Error, Result};

/// The file name of a run's plan: in `.talus` ([`Store::plan_path`]) and in a Slurm
/// submission's folder. Every process that executes the run's units reads it.
pub const PLAN_FILE: &str = "plan.json";

/// How long a claim from another host (whose pid cannot be checked) holds without renewal: ten
/// renewals (`claim::RENEW_EVERY`) missed, room for hosts' clocks minutes apart. A task on a
/// node that died leaves a claim another host takes over after this.
pub const DEFAULT_LEASE: Duration = Duration::from_secs(10 * 60);

/// The store of one DIR.
#[derive(Clone, Debug)]
pub struct Store {
    dir: PathBuf,
    work: PathBuf,
    lease: Duration,
    /// See [`content_key::RACY`]; tests shorten it.
    racy: Duration,
}

impl Store {
    /// Open the store of `dir`, creating `dir` and `.talus/{units,tmp,claims,cache}` when
    /// `create`. Writability is probed now (a file in `tmp/`), before any work is spent: a file
    /// where DIR should be, a missing store without `create`, or an unwritable DIR is
    /// `Error::Output` naming the path. A symbolic link or a special file in `.talus/` is refused
    /// (`Store::check_work_area`).
    pub fn open(dir: &Path, create: bool) -> Result<Store> {
        match std::fs::metadata(dir) {
            Ok(m) if !m.is_dir() => {
                return Err(Error::output(
                    dir,
                    std::io::Error::new(
                        std::io::ErrorKind::NotADirectory,
                        "exists and is not a directory",
                    ),
                ))
            }
            Ok(_) => {}
            Err(e) if !create && e.kind() == std::io::ErrorKind::NotFound => {
                return Err(Error::input(dir, "no such directory: no talus run here"))
            }
            Err(e) if !create => return Err(Error::input(dir, format!("cannot read: {e}"))),
            Err(_) => std::fs::create_dir_all(dir).map_err(out_err(dir))?,
        }
        let store = Store::at(dir);
        if create {
            fsops::no_links(dir, Path::new(".talus"))?;
        }
        for sub in ["units", "tmp", "claims", "cache"] {
            let p = store.work.join(sub);
            if create {
                std::fs::create_dir_all(&p).map_err(out_err(&p))?;
            } else if !p.is_dir() {
                return Err(store.not_a_run(&p));
            }
        }
        store.check_work_area()?;
        let probe = fsops::write_tmp(&store.tmp(), "probe", b"ok")?;
        std::fs::remove_file(&probe).map_err(out_err(&probe))?;
        Ok(store)
    }

    /// Open the store of `dir` for reading only (`talus status`, `talus view`, `plan-stats`):
    /// nothing is created or probed, so a finished result on a read-only mount, under a
    /// read-only `.talus/` or on a full disk can be inspected. The same checks of `.talus/` as
    /// [`Store::open`].
    pub fn inspect(dir: &Path) -> Result<Store> {
        match std::fs::metadata(dir) {
            Ok(m) if !m.is_dir() => {
                return Err(Error::input(
                    dir,
                    "is a file, not a directory: not the --out directory of a talus compare or \
                     campaign",
                ))
            }
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(Error::input(dir, "no such directory: no talus run here"))
            }
            Err(e) => return Err(Error::input(dir, format!("cannot read: {e}"))),
        }
        let store = Store::at(dir);
        if !store.work.is_dir() {
            return Err(store.not_a_run(&store.work));
        }
        store.check_work_area()?;
        Ok(store)
    }

    fn at(dir: &Path) -> Store {
        Store {
            dir: dir.to_path_buf(),
            work: dir.join(".talus"),
            lease: DEFAULT_LEASE,
            racy: content_key::RACY,
        }
    }

    fn not_a_run(&self, missing: &Path) -> Error {
        Error::input(
            &self.dir,
            format!(
                "no talus run here ({} is missing): not the --out directory of a talus compare \
                 or campaign",
                missing.strip_prefix(&self.dir).unwrap_or(missing).display()
            ),
        )
    }

    /// `.talus` and everything directly in it must be a directory or a regular file: a symbolic
    /// link there (to `/home`, say, as `tmp/`) would let talus's clean-up remove files outside
    /// DIR, and a FIFO (as `lock` or `plan.json`) would block it. Deeper entries are checked
    /// where they are used (unit directories by [`Store::done`], claims by [`Store::claim`]).
    fn check_work_area(&self) -> Result<()> {
        fsops::no_links(&self.dir, Path::new(".talus"))?;
        let entries = std::fs::read_dir(&self.work)
            .map_err(|e| Error::input(&self.work, format!("cannot read: {e}")))?;
        for entry in entries {
            let path = entry
                .map_err(|e| Error::input(&self.work, format!("cannot read: {e}")))?
                .path();
            let m = std::fs::symlink_metadata(&path)
                .map_err(|e| Error::input(&path, format!("cannot read: {e}")))?;
            if m.file_type().is_symlink() {
                return Err(fsops::link_error(&path));
            }
            if !m.is_dir() && !m.is_file() {
                return Err(Error::input(
                    &path,
                    "is neither a file nor a directory (a FIFO, socket or device) in talus's \
                     work area: remove it",
                ));
            }
        }
        Ok(())
    }

    #[cfg(test)]
    /// The same store with another lease for claims from other hosts (default 10 min).
    pub(crate) fn with_lease(mut self, lease: Duration) -> Store {
        self.lease = lease;
        self
    }

    /// DIR, the user's output directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// DIR/.talus.
    pub fn work(&self) -> &Path {
        &self.work
    }

    /// DIR/.talus/plan.json: the plan of DIR's run ([`PLAN_FILE`]).
    pub fn plan_path(&self) -> PathBuf {
        self.work.join(PLAN_FILE)
    }

    fn units(&self) -> PathBuf {
        self.work.join("units")
    }

    fn tmp(&self) -> PathBuf {
        self.work.join("tmp")
    }

    /// The bytes of `cache/<name>`, when there is such a file (a cache only ever saves work: an
    /// unreadable entry is no entry). Read as every store file is: never through a link.
    pub fn cached(&self, name: &str) -> Option<Vec<u8>> {
        fsops::read_store_file(&self.work.join("cache").join(name)).ok()
    }

    /// Keep `bytes` as `cache/<name>`, written whole under a temporary name and renamed. Failing
    /// to write a cache is not an error: it only ever saves work.
    pub fn cache(&self, name: &str, bytes: &[u8]) {
        let _ = fsops::replace_file(&self.tmp(), &self.work.join("cache").join(name), bytes);
    }

    /// A fresh path in `.talus/tmp` whose name starts with `what`, for a scratch file of this
    /// process: the caller removes it; [`Store::gc`] does once this process is gone.
    pub fn scratch_path(&self, what: &str) -> PathBuf {
        fsops::tmp_name(&self.tmp(), what)
    }
}
