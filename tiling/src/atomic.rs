//! Crash-safe replacement of a file: write a temporary sibling, fsync it, rename it over the final
//! name, fsync the directory. POSIX rename within one directory is atomic, so after a SIGKILL or
//! power loss a reader sees either the complete old file or the complete new one, never a mix
//! (SPEC.md §2: nothing half-written under a final name). The directory fsync makes the rename
//! itself durable.

use crate::error::{Error, Result};
use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The temporary name used for `path`: `<file name>.tmp` in the same directory. It is fixed (not
/// random) so a temporary left by a crash is simply overwritten by the next attempt.
pub fn tmp_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(".tmp");
    path.with_file_name(name)
}

/// A file written under a temporary name and given its final name by [`AtomicFile::commit`]
/// (fsync, rename, fsync of the directory); dropped before that, the temporary is removed. The
/// one write-then-rename of talus: whole files ([`atomic_write`]), streamed ones (a LAS writer
/// writing to [`AtomicFile::tmp`]), and the store's, whose temporaries have unique names in its
/// own folder so that two processes replacing one file leave one whole version.
#[derive(Debug)]
pub struct AtomicFile {
    tmp: PathBuf,
    path: PathBuf,
    committed: bool,
}

impl AtomicFile {
    /// `path`, written as its sibling `<file name>.tmp` ([`tmp_path`]).
    pub fn new(path: &Path) -> AtomicFile {
        AtomicFile::at(tmp_path(path), path)
    }

    /// `path`, written as `tmp` (on the same file system).
    pub fn at(tmp: PathBuf, path: &Path) -> AtomicFile {
        AtomicFile {
            tmp,
            path: path.to_path_buf(),
            committed: false,
        }
    }

    /// Where to write the content.
    pub fn tmp(&self) -> &Path {
        &self.tmp
    }

    /// The final name.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Write the temporary with `fill` (created anew; fsynced) and commit it.
    pub fn write_with(self, fill: impl FnOnce(&mut File) -> std::io::Result<()>) -> Result<()> {
        let written = (|| {
            let mut f = File::create(&self.tmp)?;
            fill(&mut f)?;
            f.sync_all()
        })();
        written.map_err(|e| Error::io(&self.tmp, e))?;
        self.commit()
    }

    /// The temporary (written) made durable and given its final name, durably.
    pub fn commit(mut self) -> Result<()> {
        File::open(&self.tmp)
            .and_then(|f| f.sync_all())
            .map_err(|e| Error::io(&self.tmp, e))?;
        publish(&self.tmp, &self.path)?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for AtomicFile {
    /// Not committed: the temporary goes.
    fn drop(&mut self) {
        if !self.committed {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

/// Replace `path` with `bytes` atomically (tmp + fsync + rename + fsync directory).
pub fn atomic_write(path: &Path, bytes: &[u8]) -> Result<()> {
    atomic_write_with(path, |f| f.write_all(bytes))
}

/// Like [`atomic_write`], with the content produced by `fill` writing into the temporary file.
pub fn atomic_write_with(
    path: &Path,
    fill: impl FnOnce(&mut File) -> std::io::Result<()>,
) -> Result<()> {
    AtomicFile::new(path).write_with(fill)
}

/// Give the durable temporary file `tmp` its name `path`, durably.
pub fn publish(tmp: &Path, path: &Path) -> Result<()> {
    fs::rename(tmp, path).map_err(|e| Error::io(path, e))?;
    sync_dir(path)
}

/// fsync the directory holding `path`, so a rename or creation in it survives a power loss.
pub fn sync_dir(path: &Path) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    // Opening a directory read-only and calling fsync is the POSIX way; on platforms where a
    // directory cannot be opened as a file there is nothing more we can do, so skip.
    #[cfg(unix)]
    {
        let d = File::open(dir).map_err(|e| Error::io(dir, e))?;
        d.sync_all().map_err(|e| Error::io(dir, e))?;
    }
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}
