//! Errors located in a text file: `rovib_base::diagnostic`, re-exported so that
//! `rovib_runtime::diagnostic::{FileError, Source}` names the same types the generator uses.

pub use rovib_base::diagnostic::*;

/// Input files read with a size limit, and numbers written compactly in messages (also from
/// `rovib-base`).
pub use rovib_base::input::{MAX_INPUT_BYTES, ReadError, read_capped, read_text_capped};
pub use rovib_base::number::Compact;
