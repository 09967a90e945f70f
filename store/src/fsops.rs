//! File-system steps the store is built from, each durable and each naming its path on error.
//!
//! The store's promises (a unit is complete exactly when its directory exists under `units/`; a
//! replaced file is either the old or the new one) rest on two POSIX facts: `rename` within one
//! file system is atomic, and a rename or creation survives a power loss only once its directory
//! is fsynced. Temporary files always get a [`unique`](super::process::unique) name in the
//! store's `tmp/`, never a fixed one: several processes on several hosts write the same targets.

use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::SystemTime;

use talus_base::{Error, Result};

use super::process::unique;

/// An I/O failure on `path` in the store or the output directory.
pub(crate) fn out_err(path: &Path) -> impl FnOnce(io::Error) -> Error + '_ {
    move |e| Error::output(path, e)
}

/// fsync the directory `dir`, making the creations, renames and removals in it durable.
pub(crate) fn sync_dir(dir: &Path) -> Result<()> {
    File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(out_err(dir))
}

/// fsync the file `path` (opened read-only: fsync flushes the file, whoever wrote it).
pub(crate) fn sync_file(path: &Path) -> Result<()> {
    File::open(path)
        .and_then(|f| f.sync_all())
        .map_err(out_err(path))
}

/// [`sync_file`] of every path, a few at once: each fsync waits for the disk, and the file
/// system commits concurrent ones together (13 result chunks of a unit took 13 ms one after the
/// other).
pub(crate) fn sync_files(paths: &[PathBuf]) -> Result<()> {
    const AT_ONCE: usize = 8;
    if paths.len() < 2 {
        return paths.iter().try_for_each(|p| sync_file(p));
    }
    let threads = paths.len().min(AT_ONCE);
    std::thread::scope(|s| {
        let each: Vec<_> = (0..threads)
            .map(|t| {
                s.spawn(move || {
                    paths
                        .iter()
                        .skip(t)
                        .step_by(threads)
                        .try_for_each(|p| sync_file(p))
                })
            })
            .collect();
        // Every thread joined, then the first error in thread order.
        let joined: Vec<Result<()>> = each
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(Error::Internal("a file sync panicked".into())))
            })
            .collect();
        joined.into_iter().collect()
    })
}

/// A fresh temporary path in `tmp` whose name starts with `what` (for a reader of the directory)
/// and ends with a unique owner suffix (for [`gc`](super::Store::gc)).
pub(crate) fn tmp_name(tmp: &Path, what: &str) -> PathBuf {
    // Keep the whole name well inside NAME_MAX (255) whatever the caller's unit name.
    let what: String = what.chars().take(96).collect();
    tmp.join(format!("{what}~{}", unique()))
}

/// Write `bytes` to a unique temporary file in `tmp`, fsynced, and return its path.
pub(crate) fn write_tmp(tmp: &Path, what: &str, bytes: &[u8]) -> Result<PathBuf> {
    let path = tmp_name(tmp, what);
    let written = (|| {
        let mut f = File::create_new(&path)?;
        f.write_all(bytes)?;
        f.sync_all()
    })();
    if let Err(e) = written {
        let _ = fs::remove_file(&path);
        return Err(Error::output(&path, e));
    }
    Ok(path)
}

/// Replace `path` with `bytes` atomically: a unique temporary in `tmp` (same file system),
/// renamed over `path`, the directory fsynced. Two processes doing this at once leave one
/// complete version (the last rename), never a mix.
pub(crate) fn replace_file(tmp: &Path, path: &Path, bytes: &[u8]) -> Result<()> {
    let what = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    talus_tiling::AtomicFile::at(tmp_name(tmp, &what), path)
        .write_with(|f| f.write_all(bytes))
        .map_err(|e| match e {
            talus_tiling::Error::Io { source, .. } => Error::output(path, source),
            other => Error::from(other),
        })
}

/// The directory holding `path`.
pub(crate) fn parent(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// Remove a file or a whole directory tree; a path that is already gone is fine (another process
/// or an earlier attempt removed it).
pub(crate) fn remove_any(path: &Path) -> Result<()> {
    let meta = match fs::symlink_metadata(path) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(Error::output(path, e)),
    };
    let r = if meta.is_dir() {
        fs::remove_dir_all(path)
    } else {
        fs::remove_file(path)
    };
    match r {
        Err(e) if e.kind() != io::ErrorKind::NotFound => Err(Error::output(path, e)),
        _ => Ok(()),
    }
}

/// Remove a directory tree by first renaming it into `tmp` (atomic: readers see the whole tree
/// or nothing), then deleting it there. If the deletion is cut short, what is left is a trash
/// directory in `tmp` that gc clears. Returns false when `path` did not exist.
pub(crate) fn trash(tmp: &Path, path: &Path) -> Result<bool> {
    match move_to_trash(tmp, path)? {
        Some(dest) => remove_any(&dest).map(|()| true),
        None => Ok(false),
    }
}

/// The first half of [`trash`]: `path` renamed into `tmp` (durably), where it is left for the
/// caller to delete (or gc to clear). The trash directory's path, None when `path` did not exist.
pub(crate) fn move_to_trash(tmp: &Path, path: &Path) -> Result<Option<PathBuf>> {
    let dest = tmp_name(tmp, "trash");
    match fs::rename(path, &dest) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::output(path, e)),
    }
    sync_dir(parent(path))?;
    Ok(Some(dest))
}

/// Trash directories (`move_to_trash`) deleted on a thread of their own while the caller goes
/// on; dropping it waits for the deletion. What a failed or interrupted deletion leaves is a trash
/// directory in `tmp/`, which gc clears.
pub struct Sweep(Option<std::thread::JoinHandle<()>>);

impl Sweep {
    pub fn start(trash: Vec<PathBuf>) -> Self {
        if trash.is_empty() {
            return Sweep(None);
        }
        Sweep(Some(std::thread::spawn(move || {
            for t in trash {
                let _ = remove_any(&t);
            }
        })))
    }
}

impl Drop for Sweep {
    fn drop(&mut self) {
        if let Some(t) = self.0.take() {
            let _ = t.join();
        }
    }
}

/// The latest modification time of `path` or anything below it (a sign of life of a writer).
pub(crate) fn newest_mtime(path: &Path) -> Option<SystemTime> {
    let meta = fs::symlink_metadata(path).ok()?;
    let mut newest = meta.modified().ok()?;
    if meta.is_dir() {
        for entry in fs::read_dir(path).ok()?.flatten() {
            if let Some(t) = newest_mtime(&entry.path()) {
                newest = newest.max(t);
            }
        }
    }
    Some(newest)
}

/// The names in directory `dir`, sorted (so every walk of the store is deterministic); an absent
/// directory has none.
pub(crate) fn sorted_names(dir: &Path) -> Result<Vec<String>> {
    let entries = match fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(Error::output(dir, e)),
    };
    let mut names = Vec::new();
    for entry in entries {
        let entry = entry.map_err(out_err(dir))?;
        names.push(entry.file_name().to_string_lossy().into_owned());
    }
    names.sort();
    Ok(names)
}

/// Open a file of the store, or one talus published into DIR, for reading: never through a
/// symbolic link, and only a regular file (else `InvalidData`). A result folder may come from anyone (shared on a
/// cluster, sent as an archive): a link planted in it must not make talus read elsewhere, and a
/// FIFO must not block a reader forever (it is opened without blocking, then refused).
pub fn open_store_file(path: &Path) -> io::Result<File> {
    use std::os::unix::fs::OpenOptionsExt;
    let f = fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| {
            if e.raw_os_error() == Some(libc::ELOOP) {
                io::Error::new(
                    io::ErrorKind::InvalidData,
                    "is a symbolic link (talus follows no link in its work area)",
                )
            } else {
                e
            }
        })?;
    if !f.metadata()?.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            "not a regular file",
        ));
    }
    Ok(f)
}

/// The whole content of a file of the store ([`open_store_file`]).
pub fn read_store_file(path: &Path) -> io::Result<Vec<u8>> {
    use std::io::Read;
    let mut bytes = Vec::new();
    open_store_file(path)?.read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// Refuse a symbolic link at any existing component of `root/rel` below `root` (`rel` relative,
/// checked by the caller): the store's directories and DIR's output folders are walked without
/// following links, so that nothing talus reads, writes or removes there lies outside DIR. A
/// component that does not exist ends the walk (nothing below it exists either).
pub fn no_links(root: &Path, rel: &Path) -> Result<()> {
    let mut path = root.to_path_buf();
    for c in rel.components() {
        path.push(c);
        match fs::symlink_metadata(&path) {
            Ok(m) if m.file_type().is_symlink() => return Err(link_error(&path)),
            Ok(_) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(Error::input(&path, format!("cannot read: {e}"))),
        }
    }
    Ok(())
}

/// The error for a symbolic link found where talus keeps or publishes its files.
pub fn link_error(path: &Path) -> Error {
    Error::input(
        path,
        "is a symbolic link inside a talus result folder: talus follows no link there (the folder \
         may come from anyone, and a link could make it read, write or remove files elsewhere); \
         remove the link",
    )
}

/// The CRC-32 and size of a regular file of the store or DIR (never through a link:
/// [`open_store_file`]), read once in 1 MiB blocks.
pub fn crc_and_size(path: &Path) -> io::Result<(u32, u64)> {
    use std::io::Read;
    let mut f = open_store_file(path)?;
    let mut h = crc32fast::Hasher::new();
    let mut buf = vec![0u8; 1 << 20];
    let mut size = 0u64;
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
        size += n as u64;
    }
    Ok((h.finalize(), size))
}
