//! Typed errors of the talus library.
//!
//! Every variant that comes from user input names the file (or flag) and the problem, so the
//! binary can print one line and exit with code 2 (see [`Error::exit_code`]).

use std::path::PathBuf;

/// Result alias used across the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What went wrong. `Input`/`Usage` variants are the user's to fix (exit code 2);
/// `Io` on an output path and `Internal` are ours or the machine's (exit code 1).
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A point cloud (or other input file) that cannot be used, with the reason.
    #[error("{}: {problem}", path.display())]
    Input { path: PathBuf, problem: String },

    /// A nonsense parameter or flag combination.
    #[error("{0}")]
    Usage(String),

    /// The two epochs cannot be compared (no overlap, ...).
    #[error("{0}")]
    Epochs(String),

    /// An output path that cannot be written (unwritable, disk full, ...).
    #[error("{}: cannot write: {source}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// DIR's lock is held by another live run (see `store::Store::lock`).
    #[error("{}: in use by another talus run ({holder}); wait for it to finish, or remove {}/.talus/lock if you are sure it is gone", dir.display(), dir.display())]
    Busy { dir: PathBuf, holder: String },

    /// A file of a finished unit is damaged (checksum, truncation): the unit is thrown away and
    /// redone by the executor; this reaches the user only if the redo is damaged too.
    #[error("{}: damaged work file: {problem}", path.display())]
    Damaged { path: PathBuf, problem: String },

    /// The run was interrupted (SIGINT); finished units are kept for `--resume`.
    #[error("interrupted")]
    Interrupted,

    /// Jobs of a cluster run failed, were cancelled or hit their limits (the message names them;
    /// the finished units are kept for `--resume`).
    #[error("{0}")]
    Jobs(String),

    /// A bug or an unexpected condition that the user could not have caused.
    #[error("internal error: {0}")]
    Internal(String),
}

impl Error {
    /// Shorthand for [`Error::Input`].
    pub fn input(path: impl Into<PathBuf>, problem: impl Into<String>) -> Self {
        Error::Input {
            path: path.into(),
            problem: problem.into(),
        }
    }

    /// Shorthand for [`Error::Output`].
    pub fn output(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Output {
            path: path.into(),
            source,
        }
    }

    /// The process exit code of SPEC.md §2: 2 for bad usage, config or input; 130 when
    /// interrupted; 1 otherwise.
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Input { .. } | Error::Usage(_) | Error::Epochs(_) => 2,
            // An unwritable output directory is the user's to fix as well.
            Error::Output { .. } => 2,
            // Another run holds DIR: the user waits or clears a lock they know is stale.
            Error::Busy { .. } => 2,
            Error::Interrupted => 130,
            Error::Internal(_) | Error::Damaged { .. } | Error::Jobs(_) => 1,
        }
    }
}
