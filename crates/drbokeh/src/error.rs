//! The library's error type. Every failure caused by user input is an [`Error`], never a panic.

use std::path::PathBuf;

/// Errors returned by the drbokeh library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An input is malformed: wrong shape, wrong channel count, non-finite value, bad range.
    #[error("{what}: {problem}")]
    InvalidInput {
        /// What was being validated (a file name, a parameter name, a layer).
        what: String,
        /// What is wrong with it.
        problem: String,
    },
    /// A parameter (camera, aperture, window) is out of its valid range.
    #[error("invalid parameter {name}: {problem}")]
    InvalidParameter {
        /// The parameter's name as the library spells it (e.g. `focus`, `max_layers`);
        /// front ends map it to their own spelling (the CLI to `--focus`).
        name: String,
        /// What is wrong with it.
        problem: String,
    },
    /// A file could not be read, decoded or written.
    #[error("{}: {problem}", path.display())]
    File {
        /// The file concerned.
        path: PathBuf,
        /// What went wrong.
        problem: String,
    },
    /// An operating-system I/O error on a file, kept as the error's `source`. The message
    /// includes the source's text, so printing this error alone says everything.
    #[error("{}: {action}: {source}", path.display())]
    Io {
        /// The file or directory concerned.
        path: PathBuf,
        /// What was being done (`cannot read`, `cannot list`, ...).
        action: String,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

/// Result alias used throughout the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An [`Error::InvalidInput`] about `what`.
    pub fn input(what: impl Into<String>, problem: impl Into<String>) -> Self {
        Error::InvalidInput {
            what: what.into(),
            problem: problem.into(),
        }
    }

    /// An [`Error::InvalidParameter`] about parameter `name`.
    pub fn param(name: impl Into<String>, problem: impl Into<String>) -> Self {
        Error::InvalidParameter {
            name: name.into(),
            problem: problem.into(),
        }
    }

    /// An [`Error::File`] about `path`.
    pub fn file(path: impl Into<PathBuf>, problem: impl Into<String>) -> Self {
        Error::File {
            path: path.into(),
            problem: problem.into(),
        }
    }

    /// An [`Error::Io`]: `action` on `path` failed with `source`.
    pub fn io(path: impl Into<PathBuf>, action: impl Into<String>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            action: action.into(),
            source,
        }
    }

    /// Re-labels an input error with the file it came from, so messages name the file.
    pub fn in_file(self, path: &std::path::Path) -> Self {
        match self {
            Error::InvalidInput { what, problem } => {
                Error::file(path, format!("{what}: {problem}"))
            }
            Error::InvalidParameter { name, problem } => {
                Error::file(path, format!("{name}: {problem}"))
            }
            other => other,
        }
    }
}
