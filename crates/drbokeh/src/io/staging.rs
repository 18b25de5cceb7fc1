//! Atomic multi-file output: a [`Staging`] writes every output of a command into
//! temporaries beside their targets ([`super::temps`]), and [`Staging::commit`] renames them
//! all into place only once every one of them is complete. Dropping a `Staging` without
//! committing (an error, a panic) removes its temporaries, so a failed command leaves
//! nothing behind and never a partial set of outputs.
//!
//! The renames are the only step that is not all-or-nothing: they run back to back after
//! all data is written, so only a rename failing mid-way (the directory vanished) can leave
//! the earlier outputs in place.

use super::temps::{self, Kind};
use crate::{Error, Result};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Outputs written but not yet visible.
#[derive(Debug, Default)]
pub struct Staging {
    /// (temporary, target, what the target is).
    staged: Vec<(PathBuf, PathBuf, Target)>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Target {
    /// A file, replaced if it exists.
    File,
    /// A directory that must not exist at commit time.
    NewDir,
    /// A directory replaced as a whole if it exists.
    ReplaceDir,
    /// A directory tree merged into an existing (or new) directory: each file replaces
    /// the one at the same relative path.
    Merge,
}

/// The directory a target lives in (`.` for a bare file name).
pub(crate) fn parent_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

impl Staging {
    /// An empty staging area.
    pub fn new() -> Self {
        Self::default()
    }

    /// Writes the content of file `path` into a temporary beside it; the file appears only
    /// at [`Staging::commit`]. A later call for the same path replaces the earlier content.
    pub fn file(
        &mut self,
        path: &Path,
        fill: impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> Result<()>,
    ) -> Result<()> {
        let dir = parent_dir(path);
        if !dir.is_dir() {
            return Err(Error::file(
                path,
                format!("output directory {} does not exist", dir.display()),
            ));
        }
        let (tmp, file) = temps::create(dir, Kind::File)
            .map_err(|e| Error::file(path, format!("cannot create a temporary file: {e}")))?;
        let file = file.expect("a file temporary comes with its file");
        let written = (|| {
            let mut w = std::io::BufWriter::new(&file);
            fill(&mut w)?;
            w.flush()
                .map_err(|e| Error::file(path, format!("write failed: {e}")))?;
            drop(w);
            file.sync_all()
                .map_err(|e| Error::file(path, format!("write failed: {e}")))
        })();
        if let Err(e) = written {
            temps::discard(&tmp);
            return Err(e);
        }
        self.push(tmp, path, Target::File);
        Ok(())
    }

    /// Writes `bytes` as file `path` (see [`Staging::file`]).
    pub fn bytes(&mut self, path: &Path, bytes: &[u8]) -> Result<()> {
        self.file(path, |w| {
            w.write_all(bytes)
                .map_err(|e| Error::file(path, format!("write failed: {e}")))
        })
    }

    /// A temporary directory beside `dir` to fill; at commit it becomes `dir`, which must
    /// not exist then (or, with `replace`, is replaced as a whole).
    pub fn dir(&mut self, dir: &Path, replace: bool) -> Result<PathBuf> {
        let target = if replace {
            Target::ReplaceDir
        } else {
            Target::NewDir
        };
        self.temp_dir(dir, parent_dir(dir), target)
    }

    /// A temporary directory whose tree is merged into `dir` at commit (created if
    /// missing; existing files at the same relative paths are replaced, others kept).
    pub fn tree(&mut self, dir: &Path) -> Result<PathBuf> {
        if dir.is_dir() {
            self.temp_dir(dir, dir, Target::Merge)
        } else {
            self.temp_dir(dir, parent_dir(dir), Target::NewDir)
        }
    }

    fn temp_dir(&mut self, dir: &Path, parent: &Path, target: Target) -> Result<PathBuf> {
        if !parent.is_dir() {
            return Err(Error::file(
                dir,
                format!("output directory {} does not exist", parent.display()),
            ));
        }
        let (tmp, _) = temps::create(parent, Kind::Dir)
            .map_err(|e| Error::file(dir, format!("cannot create a temporary directory: {e}")))?;
        self.push(tmp.clone(), dir, target);
        Ok(tmp)
    }

    fn push(&mut self, tmp: PathBuf, target: &Path, kind: Target) {
        if let Some(i) = self
            .staged
            .iter()
            .position(|(_, t, k)| t == target && *k == kind)
        {
            let (old, _, _) = self.staged.remove(i);
            temps::discard(&old);
        }
        self.staged.push((tmp, target.to_path_buf(), kind));
    }

    /// Makes every staged output visible, in the order staged.
    pub fn commit(mut self) -> Result<()> {
        let staged = std::mem::take(&mut self.staged);
        let moves: Vec<(PathBuf, PathBuf)> = staged
            .iter()
            .map(|(t, target, _)| (t.clone(), target.clone()))
            .collect();
        let kinds: Vec<Target> = staged.iter().map(|s| s.2).collect();
        let result = temps::commit(&moves, |tmp, target| {
            let i = moves.iter().position(|m| m.0 == tmp).unwrap_or(0);
            match kinds[i] {
                Target::File => std::fs::rename(tmp, target),
                Target::NewDir => {
                    if target.exists() {
                        return Err(std::io::Error::new(
                            std::io::ErrorKind::AlreadyExists,
                            "it appeared while the output was being made",
                        ));
                    }
                    std::fs::rename(tmp, target)
                }
                Target::ReplaceDir => replace_dir(tmp, target),
                Target::Merge => merge_tree(tmp, target),
            }
        });
        // Whatever was not moved (an error part-way) is removed.
        for (tmp, _, _) in &staged {
            if tmp.exists() {
                temps::discard(tmp);
            }
        }
        result
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        for (tmp, _, _) in self.staged.drain(..) {
            temps::discard(&tmp);
        }
    }
}

/// Replaces directory `target` (if it exists) by `tmp`: the old one is moved aside first,
/// so `target` is never missing its complete content for longer than two renames. Runs
/// under the temporaries' registry lock (no signal cleanup in between); a process killed
/// here leaves the aside copy under a temporary name that [`temps::sweep`] removes.
fn replace_dir(tmp: &Path, target: &Path) -> std::io::Result<()> {
    if !target.exists() {
        return std::fs::rename(tmp, target);
    }
    let aside = temps::fresh_name(parent_dir(target), Kind::Dir);
    std::fs::rename(target, &aside)?;
    if let Err(e) = std::fs::rename(tmp, target) {
        // Put the old one back.
        let _ = std::fs::rename(&aside, target);
        return Err(e);
    }
    let _ = std::fs::remove_dir_all(&aside);
    Ok(())
}

/// Moves every file of tree `tmp` to the same relative path under `target`, creating
/// directories as needed; then removes `tmp`.
fn merge_tree(tmp: &Path, target: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(target)?;
    for e in std::fs::read_dir(tmp)? {
        let e = e?;
        let to = target.join(e.file_name());
        if e.file_type()?.is_dir() {
            if to.is_dir() {
                merge_tree(&e.path(), &to)?;
            } else {
                if to.exists() {
                    std::fs::remove_file(&to)?;
                }
                std::fs::rename(e.path(), &to)?;
            }
        } else {
            if to.is_dir() {
                std::fs::remove_dir_all(&to)?;
            }
            std::fs::rename(e.path(), &to)?;
        }
    }
    std::fs::remove_dir_all(tmp)
}

/// Writes one file atomically (see [`Staging`]): the file appears only once complete.
pub fn write_atomic(
    path: &Path,
    fill: impl FnOnce(&mut std::io::BufWriter<&std::fs::File>) -> Result<()>,
) -> Result<()> {
    let mut s = Staging::new();
    s.file(path, fill)?;
    s.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn outputs_appear_together_or_not_at_all() {
        let d = tempfile::tempdir().unwrap();
        let (a, b) = (d.path().join("a.txt"), d.path().join("b.txt"));
        let mut s = Staging::new();
        s.bytes(&a, b"one").unwrap();
        s.bytes(&b, b"two").unwrap();
        assert_eq!(names(d.path()).len(), 2); // two temporaries, no outputs yet
        assert!(!a.exists() && !b.exists());
        s.commit().unwrap();
        assert_eq!(names(d.path()), ["a.txt", "b.txt"]);

        // A failure after the first output: nothing new, old content kept.
        let mut s = Staging::new();
        s.bytes(&a, b"new").unwrap();
        let err = s.file(&b, |_| Err(Error::file("b.txt", "boom")));
        assert!(err.is_err());
        drop(s);
        assert_eq!(names(d.path()), ["a.txt", "b.txt"]);
        assert_eq!(std::fs::read(&a).unwrap(), b"one");
    }

    #[test]
    fn trees_merge_and_directories_replace() {
        let d = tempfile::tempdir().unwrap();
        let out = d.path().join("report");
        std::fs::create_dir_all(out.join("scenes/s1")).unwrap();
        std::fs::write(out.join("keep.txt"), b"k").unwrap();
        std::fs::write(out.join("scenes/s1/a.png"), b"old").unwrap();
        let mut s = Staging::new();
        let root = s.tree(&out).unwrap();
        std::fs::create_dir_all(root.join("scenes/s1")).unwrap();
        std::fs::write(root.join("scenes/s1/a.png"), b"new").unwrap();
        std::fs::write(root.join("index.html"), b"i").unwrap();
        s.commit().unwrap();
        assert_eq!(names(&out), ["index.html", "keep.txt", "scenes"]);
        assert_eq!(std::fs::read(out.join("scenes/s1/a.png")).unwrap(), b"new");

        let mut s = Staging::new();
        let t = s.dir(&out, true).unwrap();
        std::fs::write(t.join("only.txt"), b"o").unwrap();
        s.commit().unwrap();
        assert_eq!(names(&out), ["only.txt"]);
        assert_eq!(names(d.path()), ["report"]);
    }
}
