//! Library errors as Python exceptions, with the library's messages (the CLI prints the same
//! ones, spelling parameter names as flags): a file that cannot be read, decoded or written
//! is an `OSError`, every other input or parameter problem a `ValueError`.

use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::PyErr;

/// Converts a library error into the matching Python exception.
pub fn to_py(e: drbokeh::Error) -> PyErr {
    match e {
        drbokeh::Error::File { .. } | drbokeh::Error::Io { .. } => {
            PyOSError::new_err(e.to_string())
        }
        other => PyValueError::new_err(other.to_string()),
    }
}

/// `drbokeh::Result<T>` to `PyResult<T>`.
pub trait OrRaise<T> {
    /// Raises the library error as a Python exception.
    fn or_raise(self) -> pyo3::PyResult<T>;
}

impl<T> OrRaise<T> for drbokeh::Result<T> {
    fn or_raise(self) -> pyo3::PyResult<T> {
        self.map_err(to_py)
    }
}

/// A `ValueError` with this message.
pub fn value_error(message: impl Into<String>) -> PyErr {
    PyValueError::new_err(message.into())
}
