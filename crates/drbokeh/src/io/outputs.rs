//! Output paths checked before any work ([`OutputPlan`]): every output's directory exists
//! and is writable, its extension is supported, it is not a directory (or, for directory
//! outputs, not a file), it is not the same file as any input (through symlinks, hard
//! links, `./` and `..` spellings) nor as another output. Checking also sweeps stale
//! temporaries of killed runs from the directories written to ([`super::temps::sweep`]).

use super::staging::parent_dir;
use super::temps::{self, Kind};
use crate::{Error, Result};
use std::path::{Path, PathBuf};

/// How a directory output is written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirMode {
    /// Created; must not exist yet.
    New,
    /// Created, or replaced as a whole if it exists (`--force`); may not hold an input.
    Replace,
    /// Created if missing (with its parents), files inside replaced one by one.
    Merge,
}

/// The inputs and outputs of a command, checked together before the work starts.
#[derive(Clone, Debug, Default)]
pub struct OutputPlan {
    inputs: Vec<(PathBuf, String)>,
    files: Vec<(PathBuf, String, Vec<String>)>,
    dirs: Vec<(PathBuf, String, DirMode)>,
}

/// A path's identity: device and inode when it exists, and its canonical spelling (the
/// canonical parent joined with the name when it does not exist yet).
#[derive(Clone, Debug, PartialEq, Eq)]
struct Identity {
    inode: Option<(u64, u64)>,
    canonical: Option<PathBuf>,
}

fn identity(p: &Path) -> Identity {
    #[cfg(unix)]
    let inode = {
        use std::os::unix::fs::MetadataExt;
        std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()))
    };
    #[cfg(not(unix))]
    let inode = None;
    let canonical = std::fs::canonicalize(p).ok().or_else(|| {
        let name = p.file_name()?;
        std::fs::canonicalize(parent_dir(p))
            .ok()
            .map(|d| d.join(name))
    });
    Identity { inode, canonical }
}

impl Identity {
    fn same(&self, other: &Identity) -> bool {
        (self.inode.is_some() && self.inode == other.inode)
            || (self.canonical.is_some() && self.canonical == other.canonical)
    }
}

/// The lower-cased extension of a path.
fn ext(p: &Path) -> String {
    p.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// Fails unless a temporary file can be created in `dir` (the real test of writability,
/// whatever the permission bits say).
fn check_writable(dir: &Path, what: &Path) -> Result<()> {
    match temps::create(dir, Kind::File) {
        Ok((probe, _)) => {
            temps::discard(&probe);
            Ok(())
        }
        Err(e) => Err(Error::file(
            what,
            format!("cannot write into {}: {e}", dir.display()),
        )),
    }
}

impl OutputPlan {
    /// An empty plan.
    pub fn new() -> Self {
        Self::default()
    }

    /// An input file or directory (`option` names it in messages, e.g. `--image`).
    /// Inputs that do not exist are ignored here (their reader reports them).
    pub fn input(&mut self, path: impl AsRef<Path>, option: &str) -> &mut Self {
        self.inputs
            .push((path.as_ref().to_path_buf(), option.to_string()));
        self
    }

    /// An output file with its accepted extensions (lower case, without dot; none: any).
    pub fn file(&mut self, path: impl AsRef<Path>, option: &str, extensions: &[&str]) -> &mut Self {
        self.files.push((
            path.as_ref().to_path_buf(),
            option.to_string(),
            extensions.iter().map(|e| e.to_string()).collect(),
        ));
        self
    }

    /// An output directory.
    pub fn dir(&mut self, path: impl AsRef<Path>, option: &str, mode: DirMode) -> &mut Self {
        self.dirs
            .push((path.as_ref().to_path_buf(), option.to_string(), mode));
        self
    }

    /// Checks every output (see the module documentation) and sweeps stale temporaries
    /// from the directories that will be written. Does not create anything.
    pub fn check(&self) -> Result<()> {
        let inputs: Vec<(Identity, &PathBuf, &String)> = self
            .inputs
            .iter()
            .filter(|(p, _)| p.exists())
            .map(|(p, o)| (identity(p), p, o))
            .collect();
        let mut outputs: Vec<(Identity, &PathBuf, &String)> = Vec::new();
        for (path, option, exts) in &self.files {
            if path.is_dir() {
                return Err(Error::file(
                    path,
                    format!("{option} names a directory; give a file name"),
                ));
            }
            let e = ext(path);
            if !exts.is_empty() && !exts.contains(&e) {
                return Err(Error::file(
                    path,
                    format!(
                        "unsupported output extension '.{e}' for {option} (use {})",
                        exts.iter()
                            .map(|x| format!(".{x}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            }
            let dir = parent_dir(path);
            if !dir.is_dir() {
                return Err(Error::file(
                    path,
                    format!("output directory {} does not exist", dir.display()),
                ));
            }
            temps::sweep(dir);
            check_writable(dir, path)?;
            outputs.push((identity(path), path, option));
        }
        for (path, option, mode) in &self.dirs {
            if path.exists() && !path.is_dir() {
                return Err(Error::file(
                    path,
                    format!("{option} exists and is not a directory"),
                ));
            }
            if *mode == DirMode::New && path.exists() {
                return Err(Error::file(
                    path,
                    format!("{option}: output directory already exists"),
                ));
            }
            // The directory that will receive the new entry: the parent, or for a merge
            // the nearest existing ancestor (created directories go below it).
            let mut base = if *mode == DirMode::Merge && path.is_dir() {
                path.clone()
            } else {
                parent_dir(path).to_path_buf()
            };
            if *mode == DirMode::Merge {
                while !base.exists() {
                    match base.parent() {
                        Some(p) if !p.as_os_str().is_empty() => base = p.to_path_buf(),
                        _ => {
                            base = PathBuf::from(".");
                            break;
                        }
                    }
                }
            }
            if !base.is_dir() {
                return Err(Error::file(
                    path,
                    format!("{option}: directory {} does not exist", base.display()),
                ));
            }
            temps::sweep(&base);
            if path.is_dir() {
                temps::sweep(path);
            }
            check_writable(&base, path)?;
            let id = identity(path);
            for (iid, ipath, iopt) in &inputs {
                let inside = match (&id.canonical, &iid.canonical) {
                    (Some(d), Some(i)) => i.starts_with(d),
                    _ => false,
                };
                if id.same(iid) || (*mode == DirMode::Replace && inside) {
                    return Err(Error::file(
                        path,
                        format!(
                            "{option} would replace the input {} ({iopt}); choose another output directory",
                            ipath.display()
                        ),
                    ));
                }
            }
        }
        for (i, (id, path, option)) in outputs.iter().enumerate() {
            for (iid, ipath, iopt) in &inputs {
                if id.same(iid) {
                    return Err(Error::file(
                        path,
                        format!(
                            "{option} is the same file as the input {} ({iopt}); it would be overwritten",
                            ipath.display()
                        ),
                    ));
                }
            }
            for (oid, _, oopt) in &outputs[..i] {
                if id.same(oid) {
                    return Err(Error::file(
                        path,
                        format!("{option} and {oopt} name the same file"),
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_file_through_spellings_and_symlinks() {
        let d = tempfile::tempdir().unwrap();
        let input = d.path().join("in.png");
        std::fs::write(&input, b"x").unwrap();
        let dotted = d.path().join(".").join("sub").join("..").join("in.png");
        std::fs::create_dir(d.path().join("sub")).unwrap();
        let e = OutputPlan::new()
            .input(&input, "--image")
            .file(&dotted, "--output", &["png"])
            .check()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("same file as the input") && e.contains("--image"),
            "{e}"
        );
        #[cfg(unix)]
        {
            let link = d.path().join("link.png");
            std::os::unix::fs::symlink(&input, &link).unwrap();
            assert!(OutputPlan::new()
                .input(&link, "--image")
                .file(&input, "--output", &["png"])
                .check()
                .is_err());
        }
        let ok = d.path().join("out.png");
        OutputPlan::new()
            .input(&input, "--image")
            .file(&ok, "--output", &["png"])
            .check()
            .unwrap();
        assert!(!ok.exists());
        let e = OutputPlan::new()
            .file(&ok, "--output", &["png"])
            .file(d.path().join("sub/../out.png"), "--log", &["png"])
            .check()
            .unwrap_err()
            .to_string();
        assert!(e.contains("--log and --output name the same file"), "{e}");
        let e = OutputPlan::new()
            .file(d.path().join("nodir/out.png"), "--output", &["png"])
            .check()
            .unwrap_err()
            .to_string();
        assert!(e.contains("does not exist"), "{e}");
        let e = OutputPlan::new()
            .file(d.path().join("out.gif"), "--output", &["png", "npy"])
            .check()
            .unwrap_err()
            .to_string();
        assert!(e.contains("'.gif'") && e.contains(".png, .npy"), "{e}");
    }
}
