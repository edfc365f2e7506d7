//! Errors located in a text file: `rovib_base::diagnostic`, re-exported so that
//! `rovib_runtime::diagnostic::{FileError, Source}` names the same types the generator uses.

pub use rovib_base::diagnostic::*;
