//! Helpers of the tests that drive the `rovib` binary: a fresh temporary directory for each
//! test and one run of the binary.

use std::path::PathBuf;
use std::process::{Command, Output};

/// A fresh, empty temporary directory for test `name` of the test file `file` (removed first
/// if an earlier run left it).
pub fn temp_dir(file: &str, name: &str) -> PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-{file}-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Runs the `rovib` binary of this build with `args` and waits for it.
pub fn rovib(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rovib")).args(args).output().unwrap()
}
