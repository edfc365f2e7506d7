//! One run per output directory: an exclusive `flock(2)` on the lock file `.rovib.lock`, which
//! holds the owner's process id and is removed when the run ends.
//!
//! A second run into the same directory (`rovib run` or `rovib ensemble`, a resume or not)
//! fails at once, naming the process that holds it. The kernel releases the lock when its
//! process ends, however it ends: a lock file left by a run that was killed (SIGKILL, out of
//! memory) holds no lock, and the next run takes it over, so `--resume` after a kill needs no
//! manual step. (On a network file system the lock is as good as its `flock` support; Linux
//! NFS emulates it with byte-range locks, which do work across clients.)

use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use nix::errno::Errno;

use crate::error::Error;
use nix::fcntl::{Flock, FlockArg};

/// The lock file's name inside an output directory.
pub const LOCK_FILE: &str = ".rovib.lock";

/// A held lock on an output directory; dropping it removes the lock file and releases the lock.
#[derive(Debug)]
pub struct DirLock {
    path: PathBuf,
    _file: Flock<File>,
}

impl DirLock {
    /// Locks `dir` (which must exist) for this process, or says who holds it.
    pub fn acquire(dir: &Path) -> Result<Self, Error> {
        let path = dir.join(LOCK_FILE);
        // A holder that ends removes the file while still holding its lock: a file opened just
        // before that is then locked but no longer the one at `path`; open again.
        for _ in 0..16 {
            let file = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .create(true)
                .truncate(false)
                .open(&path)
                .map_err(|e| Error::io("cannot create", &path, e))?;
            let mut file = match Flock::lock(file, FlockArg::LockExclusiveNonblock) {
                Ok(f) => f,
                Err((_, Errno::EWOULDBLOCK)) => return Err(held_by(dir, &path)),
                Err((_, e)) => return Err(Error::io("cannot lock", &path, e.into())),
            };
            if !same_file(&file, &path) {
                continue;
            }
            file.set_len(0)
                .and_then(|()| writeln!(*file, "{}", std::process::id()))
                .and_then(|()| file.sync_all())
                .map_err(|e| Error::io("cannot write", &path, e))?;
            return Ok(DirLock { path, _file: file });
        }
        Err(Error::unusable(path, ": other runs keep replacing this lock file; try again"))
    }
}

/// Whether `path` still names the open `file`.
fn same_file(file: &File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt as _;
    match (file.metadata(), std::fs::metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// The error for a directory that is locked, naming the holder if its lock file says.
fn held_by(dir: &Path, path: &Path) -> Error {
    let holder = std::fs::read_to_string(path).ok().and_then(|s| s.trim().parse::<u32>().ok());
    Error::Locked { dir: dir.to_owned(), lock: path.to_owned(), holder }
}

impl Drop for DirLock {
    fn drop(&mut self) {
        // Removed while still locked (the lock is released after this, when the file closes).
        // Nothing to do about a failure here: the file holds no lock once this process ends.
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
        let e = e.to_string();
        assert!(e.contains("in use by another run") && e.contains(&std::process::id().to_string()), "{e}");
        drop(first);
        assert!(!d.join(LOCK_FILE).exists());
        DirLock::acquire(&d).unwrap();
    }

    #[test]
    fn a_lock_file_left_by_a_killed_run_is_taken_over() {
        let d = dir("stale");
        // A killed run leaves its file but no lock (the kernel released it).
        std::fs::write(d.join(LOCK_FILE), "4294967295\n").unwrap();
        let lock = DirLock::acquire(&d).unwrap();
        let text = std::fs::read_to_string(d.join(LOCK_FILE)).unwrap();
        assert_eq!(text.trim(), std::process::id().to_string());
        drop(lock);
        assert!(!d.join(LOCK_FILE).exists());
    }
}
