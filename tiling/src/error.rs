//! Typed errors of the tiling crate: every variant names the file (or parameter) and the problem,
//! so the caller can report it and decide (a `Corrupt` tile is rebuilt, not fatal).

use std::path::PathBuf;

/// Result with the tiling [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Errors of the tiling crate.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The operating system refused a read, write, rename or sync.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A tile file is damaged (bad magic, unknown version, checksum mismatch,
    /// truncation, undecodable JSON). The caller should delete it and rebuild the unit.
    #[error("{}: corrupt: {reason}", path.display())]
    Corrupt { path: PathBuf, reason: String },
    /// The data handed to a writer is inconsistent (e.g. columns of different lengths).
    #[error("{}: {problem}", path.display())]
    Invalid { path: PathBuf, problem: String },
    /// A planning parameter is unusable (non-finite bounds, zero budget, negative halo).
    #[error("{what}: {problem}")]
    Parameter { what: &'static str, problem: String },
}

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn corrupt(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::Corrupt {
            path: path.into(),
            reason: reason.into(),
        }
    }

    pub(crate) fn invalid(path: impl Into<PathBuf>, problem: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.into(),
            problem: problem.into(),
        }
    }
}

/// A tiling error as talus's: a file it could not write is an output error naming the file; the
/// rest are ours. (A damaged tile file read back is `Error::Damaged`: see `talus::units::damaged`.)
impl From<Error> for talus_base::Error {
    fn from(e: Error) -> talus_base::Error {
        match e {
            Error::Io { path, source } => talus_base::Error::output(path, source),
            other => talus_base::Error::Internal(other.to_string()),
        }
    }
}
