//! Temporary files and directories: every output is first written to a temporary beside
//! its target, named `.drbokeh-<host>-<pid>-<n>.part` (files) or `.drbokeh-<host>-<pid>-<n>.dir`
//! (directories). While it exists, each temporary is listed in a process-wide registry, so
//!
//! - [`remove_all`] (called by the CLI's SIGINT/SIGTERM handler) deletes every temporary of
//!   the process and blocks any new one from being created or renamed into place;
//! - [`sweep`] deletes the temporaries that killed runs (SIGKILL, power loss) left in a
//!   directory: those whose process, on this host, no longer exists, and (from versions
//!   before this naming) `.drbokeh-*` entries older than an hour.

use crate::{Error, Result};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::Duration;

/// The prefix of every temporary name.
pub const PREFIX: &str = ".drbokeh-";

/// Age after which a legacy temporary (no process id in its name) is considered stale.
const LEGACY_STALE_AFTER: Duration = Duration::from_secs(3600);

struct Registry {
    /// Temporaries of this process that exist now.
    paths: Vec<PathBuf>,
    /// Set once cleanup has started: nothing new may be created or committed.
    closed: bool,
}

static REGISTRY: Mutex<Registry> = Mutex::new(Registry {
    paths: Vec::new(),
    closed: false,
});
static COUNTER: AtomicU64 = AtomicU64::new(0);

fn lock() -> MutexGuard<'static, Registry> {
    REGISTRY.lock().unwrap_or_else(|e| e.into_inner())
}

/// This host's name, reduced to `[A-Za-z0-9_]` (at most 32 characters).
fn host() -> String {
    static HOST: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HOST.get_or_init(|| {
        let raw = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .ok()
            .or_else(|| std::env::var("HOSTNAME").ok())
            .unwrap_or_default();
        let clean: String = raw
            .trim()
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .take(32)
            .collect();
        if clean.is_empty() {
            "host".into()
        } else {
            clean
        }
    })
    .clone()
}

/// Whether process `pid` exists on this host.
fn alive(pid: u32) -> bool {
    #[cfg(unix)]
    {
        // kill(pid, 0) probes without signalling; EPERM means it exists (another user's).
        let r = unsafe { libc::kill(pid as libc::pid_t, 0) };
        r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
    }
    #[cfg(not(unix))]
    {
        let _ = pid;
        true
    }
}

/// What kind of temporary to create.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    File,
    Dir,
}

/// The name process `pid` on this host gives its temporary number `n` (a directory with
/// `dir`): what [`sweep`] recognises. Public for tests that plant stale temporaries.
pub fn name_for(pid: u32, n: u64, dir: bool) -> String {
    format!(
        "{PREFIX}{}-{pid}-{n}.{}",
        host(),
        if dir { "dir" } else { "part" }
    )
}

/// A temporary name in `dir` that is not registered (for a move under the registry lock).
pub(crate) fn fresh_name(dir: &Path, kind: Kind) -> PathBuf {
    let ext = match kind {
        Kind::File => "part",
        Kind::Dir => "dir",
    };
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!(
            "{PREFIX}{}-{}-{n}.{ext}",
            host(),
            std::process::id()
        ));
        if std::fs::symlink_metadata(&path).is_err() {
            return path;
        }
    }
}

/// Creates and registers a new temporary in `dir`. Fails if cleanup has started. For a
/// file, returns it opened for writing (permissions rw-r--r--, as for any output).
pub(crate) fn create(dir: &Path, kind: Kind) -> std::io::Result<(PathBuf, Option<std::fs::File>)> {
    let mut reg = lock();
    if reg.closed {
        return Err(std::io::Error::new(
            std::io::ErrorKind::Interrupted,
            "interrupted: cleaning up",
        ));
    }
    let ext = match kind {
        Kind::File => "part",
        Kind::Dir => "dir",
    };
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!(
            "{PREFIX}{}-{}-{n}.{ext}",
            host(),
            std::process::id()
        ));
        let made = match kind {
            Kind::File => {
                let mut o = std::fs::OpenOptions::new();
                o.write(true).create_new(true);
                #[cfg(unix)]
                {
                    use std::os::unix::fs::OpenOptionsExt;
                    o.mode(0o644);
                }
                o.open(&path).map(Some)
            }
            Kind::Dir => std::fs::create_dir(&path).map(|_| None),
        };
        match made {
            Ok(file) => {
                reg.paths.push(path.clone());
                return Ok((path, file));
            }
            // A stale temporary of an earlier process with our pid: take the next number.
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

/// Forgets a temporary (it was renamed into place or removed).
fn forget(reg: &mut Registry, path: &Path) {
    if let Some(i) = reg.paths.iter().position(|p| p == path) {
        reg.paths.swap_remove(i);
    }
}

/// Removes a temporary (file or directory tree) and forgets it.
pub(crate) fn discard(path: &Path) {
    let mut reg = lock();
    remove_path(path);
    forget(&mut reg, path);
}

/// Renames temporaries into place, in order, under the registry lock (so a signal's cleanup
/// cannot run half-way through). Fails without renaming anything if cleanup has started.
/// `rename(temp, target)` does the move (plain rename, or a directory replacement).
pub(crate) fn commit(
    moves: &[(PathBuf, PathBuf)],
    rename: impl Fn(&Path, &Path) -> std::io::Result<()>,
) -> Result<()> {
    let mut reg = lock();
    if reg.closed {
        return Err(Error::file(
            moves.first().map(|m| m.1.clone()).unwrap_or_default(),
            "interrupted before the output was complete",
        ));
    }
    for (tmp, target) in moves {
        rename(tmp, target).map_err(|e| {
            Error::file(
                target,
                format!("cannot move the finished output into place: {e}"),
            )
        })?;
        forget(&mut reg, tmp);
    }
    Ok(())
}

fn remove_path(path: &Path) {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => {
            let _ = std::fs::remove_dir_all(path);
        }
        Ok(_) => {
            let _ = std::fs::remove_file(path);
        }
        Err(_) => {}
    }
}

/// Deletes every temporary of this process and refuses new ones from now on. Returns how
/// many were removed. Safe to call from a signal-handling thread.
pub fn remove_all() -> usize {
    let mut reg = lock();
    reg.closed = true;
    let n = reg.paths.len();
    for p in reg.paths.drain(..) {
        remove_path(&p);
    }
    n
}

/// The temporaries of this process that exist now (for tests and diagnostics).
pub fn registered() -> Vec<PathBuf> {
    lock().paths.clone()
}

/// Whether a directory entry named `name` is a stale temporary (its process is gone).
fn is_stale(name: &str, entry: &Path) -> bool {
    let Some(rest) = name.strip_prefix(PREFIX) else {
        return false;
    };
    let base = rest
        .strip_suffix(".part")
        .or_else(|| rest.strip_suffix(".dir"));
    if let Some(base) = base {
        let parts: Vec<&str> = base.rsplitn(3, '-').collect();
        if let [n, pid, host_name] = parts.as_slice() {
            if n.parse::<u64>().is_ok() {
                if let Ok(pid) = pid.parse::<u32>() {
                    return *host_name == host() && pid != std::process::id() && !alive(pid);
                }
            }
        }
    }
    // An older version's name (`.drbokeh-XXXXXX.part`, `.drbokeh-scene-XXXXXX`): stale
    // once it has not been touched for an hour.
    std::fs::symlink_metadata(entry)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.elapsed().ok())
        .is_some_and(|age| age > LEGACY_STALE_AFTER)
}

/// Removes the stale temporaries in `dir` (see the module documentation); returns how
/// many. Errors (unreadable directory, races with other processes) are ignored: sweeping
/// is best effort.
pub fn sweep(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut n = 0;
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(name) = name.to_str() else { continue };
        let path = e.path();
        if is_stale(name, &path) {
            remove_path(&path);
            n += 1;
        }
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stale_names_are_those_of_dead_processes_on_this_host() {
        let dir = tempfile::tempdir().unwrap();
        let me = std::process::id();
        let dead = format!("{PREFIX}{}-{}-3.part", host(), u32::MAX - 7);
        let mine = format!("{PREFIX}{}-{me}-4.part", host());
        let other_host = format!("{PREFIX}elsewhere-{}-5.dir", u32::MAX - 7);
        let fresh_legacy = format!("{PREFIX}abc123.part");
        let user_file = "notes.txt".to_string();
        for n in [&dead, &mine, &other_host, &fresh_legacy, &user_file] {
            std::fs::write(dir.path().join(n), b"x").unwrap();
        }
        assert_eq!(sweep(dir.path()), 1);
        assert!(!dir.path().join(&dead).exists());
        for n in [&mine, &other_host, &fresh_legacy, &user_file] {
            assert!(dir.path().join(n).exists(), "{n}");
        }
    }
}
