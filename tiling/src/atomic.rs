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

/// Replace `path` with `bytes` atomically (tmp + fsync + rename + fsync directory).
pub fn atomic_write(path: &Path, bytes: &[u8]) -> Result<()> {
    atomic_write_with(path, |f| f.write_all(bytes))
}

/// Like [`atomic_write`], with the content produced by `fill` writing into the temporary file.
pub fn atomic_write_with(
    path: &Path,
    fill: impl FnOnce(&mut File) -> std::io::Result<()>,
) -> Result<()> {
    let tmp = tmp_path(path);
    let written = (|| {
        let mut f = File::create(&tmp)?;
        fill(&mut f)?;
        f.sync_all()
    })();
    if let Err(e) = written {
        let _ = fs::remove_file(&tmp);
        return Err(Error::io(&tmp, e));
    }
    publish(&tmp, path)
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
