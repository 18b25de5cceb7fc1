//! File plumbing shared by the readers and writers: atomic writes, opening with a message
//! naming the file, and extensions.

use crate::{Error, Result};
use std::io::Write;
use std::path::Path;

/// Writes a file atomically: `fill` writes into a temporary file in the target's directory,
/// which is renamed over `path` only if `fill` succeeds.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> Result<()>,
) -> Result<()> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(Error::file(path, "output directory does not exist"));
    }
    let mut builder = tempfile::Builder::new();
    builder.prefix(".drbokeh-").suffix(".part");
    #[cfg(unix)]
    {
        // Ordinary file permissions (rw-r--r--), not the private 0600 of temporary files.
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o644));
    }
    let tmp = builder
        .tempfile_in(dir)
        .map_err(|e| Error::file(path, format!("cannot create temporary file: {e}")))?;
    {
        let mut w = std::io::BufWriter::new(tmp.as_file());
        fill(&mut w)?;
        w.flush()
            .map_err(|e| Error::file(path, format!("write failed: {e}")))?;
    }
    tmp.persist(path)
        .map_err(|e| Error::file(path, format!("cannot rename into place: {}", e.error)))?;
    Ok(())
}

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
