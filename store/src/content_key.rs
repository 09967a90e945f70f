//! Content keys of input files: what a unit built from an input is named after, so a changed
//! input means new units and an unchanged one (wherever it lives, however often it is opened)
//! means the same units.
//!
//! The key is FNV-1a-64 over the file size and the CRC-32 of each 1 MiB block (CRC-32 runs at
//! memory speed; the FNV pass is over 4 bytes per MiB). Reading a 100 GB survey on every command
//! would cost minutes, so keys are cached in `cache/inputs.json` by the file's identity:
//! canonical path, device, inode, size, and mtime and ctime in nanoseconds. A user can set mtime
//! back (`touch -d`) but not ctime, which the kernel sets on every change, so "same size, same
//! mtime, other content" still changes the identity.
//!
//! One hole is left by the file system's clock granularity (a few ms on ext4, up to 1 s
//! elsewhere): a change within the same tick as the one before it, just after we hashed, keeps
//! the ctime. As git does with its index ("racy git"), a key is not cached while the file changed
//! less than [`RACY`] ago; the next call hashes it again.
//!
//! Several processes may update the cache at once: each rewrites it whole under a unique
//! temporary name (last writer wins), and every entry is independently correct, so a lost entry
//! only costs one more hash.

use std::collections::BTreeMap;
use std::fs::{self, File, Metadata};
use std::io::{self, Read};
use std::os::unix::fs::MetadataExt;
use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use talus_tiling::Fnv64;

use talus_base::{Error, Result};

use super::fsops::replace_file;
use super::Store;

/// Block size of the per-block CRCs (part of the key's definition: changing it changes every key).
const BLOCK: usize = 1 << 20;

/// How recently changed a file may be and still have its key cached (see the module doc).
pub(crate) const RACY: Duration = Duration::from_secs(2);

const CACHE_VERSION: u32 = 1;

/// A file's identity: equal identities mean equal content (see the module doc).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
struct Identity {
    dev: u64,
    ino: u64,
    size: u64,
    mtime_s: i64,
    mtime_ns: i64,
    ctime_s: i64,
    ctime_ns: i64,
}

impl Identity {
    fn of(m: &Metadata) -> Identity {
        Identity {
            dev: m.dev(),
            ino: m.ino(),
            size: m.size(),
            mtime_s: m.mtime(),
            mtime_ns: m.mtime_nsec(),
            ctime_s: m.ctime(),
            ctime_ns: m.ctime_nsec(),
        }
    }

    /// Whether the file changed less than `window` ago by this host's clock (or in its future).
    fn racy(&self, window: Duration) -> bool {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos() as i128)
            .unwrap_or(0);
        let changed = |s: i64, ns: i64| i128::from(s) * 1_000_000_000 + i128::from(ns);
        let latest = changed(self.mtime_s, self.mtime_ns).max(changed(self.ctime_s, self.ctime_ns));
        now - latest < window.as_nanos() as i128
    }
}

#[derive(Debug, Serialize, Deserialize)]
struct Entry {
    #[serde(flatten)]
    identity: Identity,
    key: String,
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct Cache {
    version: u32,
    /// By canonical path; sorted, so the file is deterministic.
    files: BTreeMap<String, Entry>,
}

impl Store {
    fn cache_path(&self) -> std::path::PathBuf {
        self.work.join("cache").join("inputs.json")
    }

    /// An unreadable or foreign cache is an empty one: it only ever saves work.
    fn load_cache(&self) -> Cache {
        super::fsops::read_store_file(&self.cache_path())
            .ok()
            .and_then(|b| serde_json::from_slice::<Cache>(&b).ok())
            .filter(|c| c.version == CACHE_VERSION)
            .unwrap_or_default()
    }

    /// The content key of `input` (16 hex digits; see the module doc). Errors reading the input
    /// are `Error::Input` naming it.
    pub fn content_key(&self, input: &Path) -> Result<String> {
        let cannot = |e: io::Error| Error::input(input, format!("cannot read: {e}"));
        let canon = fs::canonicalize(input).map_err(cannot)?;
        let meta = fs::metadata(&canon).map_err(cannot)?;
        if !meta.is_file() {
            return Err(Error::input(input, "not a regular file"));
        }
        // A path that is not UTF-8 cannot be a JSON key; such a file is simply hashed each time.
        let cache_key = canon.to_str().map(str::to_string);
        let identity = Identity::of(&meta);
        if let Some(entry) = cache_key
            .as_ref()
            .and_then(|k| self.load_cache().files.remove(k))
        {
            if entry.identity == identity {
                return Ok(entry.key);
            }
        }
        // A file being written while we read it would give a key of no content in particular:
        // hash until the identity holds still across the read.
        for _ in 0..3 {
            let mut f = File::open(&canon).map_err(cannot)?;
            let before = Identity::of(&f.metadata().map_err(cannot)?);
            let key = hash_content(&mut f).map_err(cannot)?;
            let after = Identity::of(&fs::metadata(&canon).map_err(cannot)?);
            if before != after || key.1 != before.size {
                continue;
            }
            if let Some(k) = cache_key.filter(|_| !before.racy(self.racy)) {
                let mut cache = self.load_cache();
                cache.version = CACHE_VERSION;
                cache.files.insert(
                    k,
                    Entry {
                        identity: before,
                        key: key.0.clone(),
                    },
                );
                let bytes = serde_json::to_vec_pretty(&cache)
                    .map_err(|e| Error::Internal(format!("input cache: {e}")))?;
                replace_file(&self.tmp(), &self.cache_path(), &bytes)?;
            }
            return Ok(key.0);
        }
        Err(Error::input(
            input,
            "kept changing while being read (3 attempts); is it still being written?",
        ))
    }
}

/// The key of the content read from `f`, and how many bytes that was.
fn hash_content(f: &mut File) -> io::Result<(String, u64)> {
    let mut buf = vec![0u8; BLOCK];
    let mut crcs = Vec::new();
    let mut size = 0u64;
    loop {
        // Fill the whole block (read may return less), so blocks always start at k MiB.
        let mut n = 0;
        while n < BLOCK {
            match f.read(&mut buf[n..]) {
                Ok(0) => break,
                Ok(m) => n += m,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        if n == 0 {
            break;
        }
        crcs.push(crc32fast::hash(&buf[..n]));
        size += n as u64;
        if n < BLOCK {
            break;
        }
    }
    let mut h = Fnv64::new();
    h.write_u64(size);
    for crc in crcs {
        h.write(&crc.to_le_bytes());
    }
    Ok((h.hex(), size))
}
