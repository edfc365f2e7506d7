//! One run per output directory: a lock file `.rovib.lock`, created with `create_new` (atomic on
//! every local file system) and holding the owner's process id, removed when the run ends.
//!
//! A second run into the same directory fails at once. A lock left by a process that no longer
//! exists (killed with SIGKILL, a power cut) is not taken over silently: the error says that its
//! process is gone and how to remove it.

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// The lock file's name inside an output directory.
pub const LOCK_FILE: &str = ".rovib.lock";

/// A held lock on an output directory; dropping it removes the lock file.
#[derive(Debug)]
pub struct DirLock {
    path: PathBuf,
}

impl DirLock {
    /// Locks `dir` (which must exist) for this process, or says who holds it.
    pub fn acquire(dir: &Path) -> Result<Self, String> {
        let path = dir.join(LOCK_FILE);
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(mut file) => {
                let lock = DirLock { path };
                writeln!(file, "{}", std::process::id())
                    .and_then(|()| file.sync_all())
                    .map_err(|e| format!("cannot write {}: {e}", lock.path.display()))?;
                Ok(lock)
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Err(held_by(dir, &path)),
            Err(e) => Err(format!("cannot create {}: {e}", path.display())),
        }
    }
}

/// The message for a directory that is already locked.
fn held_by(dir: &Path, path: &Path) -> String {
    let pid = std::fs::read_to_string(path).ok().and_then(|s| s.trim().parse::<u32>().ok());
    match pid {
        // /proc/PID exists while the process does (Linux); elsewhere assume it is running.
        Some(pid) if Path::new("/proc/self").exists() && !Path::new(&format!("/proc/{pid}")).exists() => format!(
            "{} is locked by process {pid}, which is no longer running (a run that was killed); \
             if no other run uses this directory, remove {} and try again",
            dir.display(),
            path.display()
        ),
        Some(pid) => format!(
            "{} is in use by another run (process {pid}); wait for it to end or choose another --out directory",
            dir.display()
        ),
        None => format!(
            "{} is locked by another run ({} exists); if no other run uses this directory, remove it and try again",
            dir.display(),
            path.display()
        ),
    }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        // Nothing to do about a failure here: the next run reports the stale lock.
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        // The same directory on every run (removed first), so that runs do not pile up in /tmp.
        let d = std::env::temp_dir().join(format!("rovib-dir-lock-{name}"));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_second_lock_fails_until_the_first_is_dropped() {
        let d = dir("twice");
        let first = DirLock::acquire(&d).unwrap();
        let e = DirLock::acquire(&d).unwrap_err();
        assert!(e.contains("in use by another run") && e.contains(&std::process::id().to_string()), "{e}");
        drop(first);
        assert!(!d.join(LOCK_FILE).exists());
        DirLock::acquire(&d).unwrap();
    }

    #[test]
    fn a_stale_lock_names_its_dead_process_and_the_file_to_remove() {
        let d = dir("stale");
        // Process ids on Linux stay below 2^22; this one cannot exist.
        std::fs::write(d.join(LOCK_FILE), "4294967295\n").unwrap();
        let e = DirLock::acquire(&d).unwrap_err();
        assert!(e.contains("no longer running") && e.contains("remove"), "{e}");
        assert!(e.contains(&d.join(LOCK_FILE).display().to_string()), "{e}");
    }
}
