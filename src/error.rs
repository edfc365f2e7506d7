//! The library's error: what went wrong in loading a scene, running a simulation or an
//! ensemble, or writing their outputs, with the place (a scene line, a file path) and a fix.

use std::fmt;
use std::path::PathBuf;

use thiserror::Error as ThisError;

use crate::runtime::diagnostic::{FileError, ReadError};

/// A failure of a library call.
#[derive(Debug, ThisError)]
pub enum Error {
    /// A problem located in a file (a scene, a molecule definition), shown with its place and a fix.
    #[error("{0}")]
    File(FileError),
    /// An input/output failure on a named path.
    #[error("{context} {}: {source}", path.display())]
    Io {
        /// What was being done, e.g. "cannot create".
        context: String,
        /// The file or folder.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A file that exists but cannot be used as asked: an output that cannot be continued (cut,
    /// changed, another run's), a restart file that is not one. `why` follows the path.
    #[error("{}{why}", path.display())]
    Unusable {
        /// The file.
        path: PathBuf,
        /// What is wrong with it and what to do, starting with the separator (": …", " has …").
        why: String,
    },
    /// Another run holds the lock of the output folder (`dir_lock`).
    #[error(
        "{} is in use by another run{}, which holds the lock {}; wait for it to end or choose another output directory",
        dir.display(),
        holder.map_or(String::new(), |pid| format!(" (process {pid})")),
        lock.display()
    )]
    Locked {
        /// The output folder.
        dir: PathBuf,
        /// Its lock file.
        lock: PathBuf,
        /// The process id written in the lock file, if it could be read.
        holder: Option<u32>,
    },
    /// The stop flag ended the run; the outputs up to the last whole record are in `out_dir`.
    #[error("{message}")]
    Interrupted {
        /// What was done and how to continue, one line.
        message: String,
        /// The output folder.
        out_dir: PathBuf,
    },
    /// Anything else, one line with its context.
    #[error("{}", .0.replace('\n', " "))]
    Message(String),
}

impl From<FileError> for Error {
    fn from(e: FileError) -> Self {
        Error::File(e)
    }
}

/// An input that cannot be read is one line naming it (a [`Error::Message`]).
impl From<ReadError> for Error {
    fn from(e: ReadError) -> Self {
        Error::Message(e.to_string())
    }
}

impl From<String> for Error {
    fn from(m: String) -> Self {
        Error::Message(m)
    }
}

impl From<&str> for Error {
    fn from(m: &str) -> Self {
        Error::Message(m.to_owned())
    }
}

impl Error {
    /// A file that cannot be used as asked; `why` follows its path (": …", " has …").
    pub fn unusable(path: impl Into<PathBuf>, why: impl Into<String>) -> Self {
        Error::Unusable { path: path.into(), why: why.into() }
    }

    /// An error from anything displayable, prefixed with context.
    pub fn context(context: impl fmt::Display, e: impl fmt::Display) -> Self {
        Error::Message(format!("{context}: {e}"))
    }

    /// An input/output error on `path`.
    pub fn io(context: impl Into<String>, path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { context: context.into(), path: path.into(), source }
    }

    /// Whether the stop flag ended the run.
    pub fn is_interrupted(&self) -> bool {
        matches!(self, Error::Interrupted { .. })
    }

    /// The error for a molecule name that is not compiled in.
    pub fn unknown_molecule(name: &str) -> Self {
        // Only a name a definition could have (a lowercase identifier) gets "add
        // molecules/NAME.toml": an empty name would say "molecules/.toml".
        let definable = name.chars().next().is_some_and(|c| c.is_ascii_lowercase())
            && name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
        let add = if definable {
            format!("add molecules/{name}.toml and rebuild to add it")
        } else {
            "a new molecule needs a name of lowercase letters, digits and `_`, starting with a letter, and its \
             molecules/NAME.toml"
                .to_owned()
        };
        Error::Message(format!(
            "unknown molecule `{}`; the compiled-in molecules are {} ({add})",
            name.escape_debug(),
            crate::molecules::NAMES.join(", ")
        ))
    }
}

/// A library result.
pub type Result<T, E = Error> = std::result::Result<T, E>;
