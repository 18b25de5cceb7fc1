//! File plumbing shared by the readers and writers: opening with a message naming the
//! file, and extensions. (Atomic writes are `staging.rs`, beside the temp registry.)

use crate::{Error, Result};
use std::path::Path;

/// Opens a file for reading with a message naming it on failure.
pub(crate) fn open(path: &Path) -> Result<std::fs::File> {
    std::fs::File::open(path).map_err(|e| Error::file(path, format!("cannot open: {e}")))
}

/// The lower-cased extension of a path ("" if none).
pub(crate) fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}
