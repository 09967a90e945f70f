//! Owner files: a file whose existence means "this process owns that" (a claim on a unit, the
//! run lock of a DIR), created exclusively, taken over only when its owner is provably gone.
//!
//! Creation links a complete, fsynced temporary to the final name (`link(2)` fails if the name
//! exists; it is atomic on local file systems and on NFS, where it is the classic lock-file
//! idiom), so no reader ever sees a half-written owner file. On a file system without hard
//! links it falls back to `create_new` (O_EXCL) and then writes, and a reader may briefly see an
//! empty file; [`Owner::stale`] counts an unreadable file as held until it is a minute old.
//!
//! Take-over: rename the stale file to a unique name in `tmp/` (of two processes renaming the
//! same file only one succeeds), check that what was moved is the very file judged stale (it may
//! be a fresh one another process created in between: then it is linked back), then create anew.
//! The one race left (a third process creating the name in the instant a wrongly moved fresh
//! file is away) makes two owners of one claim: both compute the unit, and since units are
//! deterministic and [`commit`](super::UnitWriter::commit) keeps the first, only time is lost.

use std::fs;
use std::io;
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::time::{Duration, SystemTime};

use serde::{Deserialize, Serialize};

use talus_base::{Error, Result};

use super::fsops::{out_err, parent, sync_dir, tmp_name, write_tmp};
use super::process;

/// How long an owner file that cannot be parsed counts as "being written" rather than damaged.
const UNPARSEABLE_GRACE: Duration = Duration::from_secs(60);

/// The owner recorded in a claim or lock file.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Owner {
    pub pid: u32,
    pub host: String,
    /// Unix seconds when the owner took the file.
    pub started: u64,
    /// The pid's start time in clock ticks since boot (`/proc/<pid>/stat` field 22), so a reused
    /// pid does not count as the owner.
    #[serde(default)]
    pub pid_start: Option<u64>,
    /// Unix seconds of the last renewal of a lease, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub renewed: Option<u64>,
    /// Unique per acquisition: tells this owner's file from any later one with the same pid.
    pub token: String,
}

impl Owner {
    /// This process, now.
    pub fn me() -> Owner {
        Owner {
            pid: std::process::id(),
            host: process::host().to_string(),
            started: process::now_secs(),
            pid_start: process::own_start(),
            renewed: None,
            token: process::unique(),
        }
    }

    /// Whether the owner is known to be gone: on this host, its pid is dead (or reused); from
    /// another host, when `lease` is given, it took or last renewed the file longer than the
    /// lease ago (by its own clock, recorded in the file: no file-system clock is involved).
    pub fn gone(&self, lease: Option<Duration>) -> bool {
        if self.host == process::host() {
            return !process::alive(self.pid, self.pid_start);
        }
        let Some(lease) = lease else { return false };
        let last = self.started.max(self.renewed.unwrap_or(0));
        process::now_secs().saturating_sub(last) > lease.as_secs()
    }

    /// Whether owner-file content `bytes` is stale (see [`Owner::gone`]); unparseable content is
    /// stale only once the file has stood for a minute.
    pub(crate) fn stale(bytes: &[u8], mtime: Option<SystemTime>, lease: Option<Duration>) -> bool {
        match serde_json::from_slice::<Owner>(bytes) {
            Ok(owner) => owner.gone(lease),
            Err(_) => mtime
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > UNPARSEABLE_GRACE),
        }
    }

    /// A short human description: "pid 1234 on vm, started 3 min ago".
    pub(crate) fn describe(&self) -> String {
        let age = process::now_secs().saturating_sub(self.started);
        let age = if age < 120 {
            format!("{age} s")
        } else if age < 7200 {
            format!("{} min", age / 60)
        } else {
            format!("{} h", age / 3600)
        };
        format!("pid {} on {}, started {age} ago", self.pid, self.host)
    }
}

/// What [`acquire`] found.
pub(crate) enum Acquired {
    /// The file is now ours.
    Ours,
    /// A live owner holds it; its content.
    Held(Vec<u8>),
}

/// Create `path` holding `content`, or take it over when `stale(content, mtime)` says its owner
/// is gone. `tmp` is a directory on the same file system for temporaries.
pub(crate) fn acquire(
    path: &Path,
    tmp: &Path,
    content: &[u8],
    stale: impl Fn(&[u8], Option<SystemTime>) -> bool,
) -> Result<Acquired> {
    // Each round either creates the file, or finds a live owner, or removes one stale file;
    // many rounds only happen when many processes fight over a stale file at once.
    for _ in 0..16 {
        if create_exclusive(path, tmp, content)? {
            return Ok(Acquired::Ours);
        }
        let (bytes, mtime) = match read_with_mtime(path) {
            Ok(x) => x,
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            // A link or a FIFO planted as the owner file: the folder's problem, not the disk's.
            Err(e) if e.kind() == io::ErrorKind::InvalidData => {
                return Err(Error::input(path, e.to_string()))
            }
            Err(e) => return Err(Error::output(path, e)),
        };
        if !stale(&bytes, mtime) {
            return Ok(Acquired::Held(bytes));
        }
        let moved = tmp_name(tmp, "stale");
        match fs::rename(path, &moved) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            Err(e) => return Err(Error::output(path, e)),
        }
        let moved_bytes = fs::read(&moved).unwrap_or_default();
        if moved_bytes != bytes {
            // A fresh file someone created after our read: give it back (same inode, so its
            // owner's release still finds it) and let it hold.
            let _ = fs::hard_link(&moved, path);
            let _ = fs::remove_file(&moved);
            return Ok(Acquired::Held(moved_bytes));
        }
        let _ = fs::remove_file(&moved);
    }
    Err(Error::Internal(format!(
        "{}: could neither create nor take over this file in 16 attempts",
        path.display()
    )))
}

/// Create `path` with `content` unless it exists; true when created.
fn create_exclusive(path: &Path, tmp: &Path, content: &[u8]) -> Result<bool> {
    let t = write_tmp(tmp, "owner", content)?;
    let linked = fs::hard_link(&t, path);
    // NFS may report a failure for a link that was made (a retransmitted request): the temporary
    // then has two links, which is the reliable sign.
    let made = match &linked {
        Ok(()) => true,
        Err(_) => fs::metadata(&t).map(|m| m.nlink() == 2).unwrap_or(false),
    };
    let _ = fs::remove_file(&t);
    if made {
        sync_dir(parent(path))?;
        return Ok(true);
    }
    match linked {
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(false),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Err(Error::output(path, e)),
        // A file system without hard links: exclusive create, then write.
        _ => {
            use std::io::Write;
            let mut f = match fs::File::create_new(path) {
                Ok(f) => f,
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => return Ok(false),
                Err(e) => return Err(Error::output(path, e)),
            };
            f.write_all(content)
                .and_then(|()| f.sync_all())
                .map_err(out_err(path))?;
            sync_dir(parent(path))?;
            Ok(true)
        }
    }
}

fn read_with_mtime(path: &Path) -> io::Result<(Vec<u8>, Option<SystemTime>)> {
    use std::io::Read;
    // Not through a link, not a FIFO: see `open_store_file`.
    let mut f = super::fsops::open_store_file(path)?;
    let mtime = f.metadata().ok().and_then(|m| m.modified().ok());
    let mut bytes = Vec::new();
    f.read_to_end(&mut bytes)?;
    Ok((bytes, mtime))
}

/// Whether `path` still holds the owner file with `token`.
pub(crate) fn is_ours(path: &Path, token: &str) -> bool {
    super::fsops::read_store_file(path)
        .ok()
        .and_then(|b| serde_json::from_slice::<Owner>(&b).ok())
        .is_some_and(|o| o.token == token)
}

/// Rewrite `path` with `content` if it is still the owner file with `token` (a renewal: see
/// `claim::renewer`). True when rewritten.
pub(crate) fn renew(path: &Path, tmp: &Path, token: &str, content: &[u8]) -> Result<bool> {
    if !is_ours(path, token) {
        return Ok(false);
    }
    super::fsops::replace_file(tmp, path, content)?;
    Ok(true)
}

/// Remove `path` if it is still the owner file with `token` (a file taken over by another
/// process after a lease ran out, or replaced by hand, is left alone). True when removed.
pub(crate) fn release(path: &Path, token: &str) -> Result<bool> {
    if !is_ours(path, token) {
        return Ok(false);
    }
    match fs::remove_file(path) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(Error::output(path, e)),
    }
}
