//! Reading input files (molecule definitions, scenes, states files) with a size limit, so that
//! a path such as `/dev/zero` or `/dev/urandom`, or a huge file given by mistake, is an error
//! with the numbers instead of memory that grows until the process is killed.

use std::fmt;
use std::io::Read;
use std::path::Path;

/// The largest definition or scene file read: 16 MiB, far above any real one (the largest
/// shipped definition is a few KiB; a 10⁴-term potential is about 0.5 MiB).
pub const MAX_INPUT_BYTES: u64 = 16 << 20;

/// Why an input could not be read. `name` is the file's path (or what the input is, e.g. "the
/// state from stdin"); the message is one line starting "cannot read NAME: ".
// Display is written by hand: this crate has no dependencies, on purpose.
#[derive(Debug)]
pub enum ReadError {
    /// The file cannot be opened, or reading it failed.
    Io {
        /// The input, as the message names it.
        name: String,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The input is larger than the limit.
    TooLarge {
        /// The input, as the message names it.
        name: String,
        /// The limit, bytes.
        limit: u64,
    },
    /// The input is not UTF-8 text.
    NotUtf8 {
        /// The input, as the message names it.
        name: String,
        /// The offset of the first invalid byte.
        offset: usize,
    },
}

impl fmt::Display for ReadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReadError::Io { name, source } => write!(f, "cannot read {name}: {source}"),
            ReadError::TooLarge { name, limit } => write!(
                f,
                "cannot read {name}: it is larger than {limit} bytes ({} MiB), the limit for this kind of input file; \
                 check that the path names the file you mean",
                limit >> 20
            ),
            ReadError::NotUtf8 { name, offset } => {
                write!(f, "cannot read {name}: not UTF-8 text (invalid byte at offset {offset})")
            }
        }
    }
}

impl std::error::Error for ReadError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ReadError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// Reads `path` as UTF-8 text of at most `limit` bytes. The error is one line naming the file
/// and, for a file that is too large, the limit and what to do.
pub fn read_text_capped(path: &Path, limit: u64) -> Result<String, ReadError> {
    let name = || path.display().to_string();
    let file = std::fs::File::open(path).map_err(|source| ReadError::Io { name: name(), source })?;
    read_capped(file, &name(), limit)
}

/// Reads UTF-8 text of at most `limit` bytes from `reader` (a file, stdin), named `name` in
/// errors.
pub fn read_capped(reader: impl Read, name: &str, limit: u64) -> Result<String, ReadError> {
    let mut bytes = Vec::new();
    // One byte more than the limit tells "exactly at the limit" from "larger".
    reader
        .take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(|source| ReadError::Io { name: name.to_owned(), source })?;
    if bytes.len() as u64 > limit {
        return Err(ReadError::TooLarge { name: name.to_owned(), limit });
    }
    String::from_utf8(bytes)
        .map_err(|e| ReadError::NotUtf8 { name: name.to_owned(), offset: e.utf8_error().valid_up_to() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_above_the_limit_is_refused_and_one_at_it_is_read() {
        let dir = std::env::temp_dir().join(format!("rovib-base-input-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f.toml");
        std::fs::write(&path, "x".repeat(100)).unwrap();
        assert_eq!(read_text_capped(&path, 100).unwrap().len(), 100);
        let e = read_text_capped(&path, 99).unwrap_err().to_string();
        assert!(e.contains("larger than 99 bytes") && e.contains("f.toml"), "{e}");
        std::fs::write(&path, [b'a', 0xff, b'b']).unwrap();
        assert!(
            read_text_capped(&path, 100).unwrap_err().to_string().contains("not UTF-8 text (invalid byte at offset 1)")
        );
        if Path::new("/dev/zero").exists() {
            let e = read_text_capped(Path::new("/dev/zero"), MAX_INPUT_BYTES).unwrap_err().to_string();
            assert!(e.contains("larger than 16777216 bytes (16 MiB)"), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn read_errors_name_the_input() {
        let io = ReadError::Io { name: "a.toml".into(), source: std::io::Error::other("gone") };
        assert_eq!(io.to_string(), "cannot read a.toml: gone");
        let large = ReadError::TooLarge { name: "a.toml".into(), limit: 32 << 20 };
        assert_eq!(
            large.to_string(),
            "cannot read a.toml: it is larger than 33554432 bytes (32 MiB), the limit for this kind of input file; \
             check that the path names the file you mean"
        );
        let text = ReadError::NotUtf8 { name: "the state from stdin".into(), offset: 7 };
        assert_eq!(text.to_string(), "cannot read the state from stdin: not UTF-8 text (invalid byte at offset 7)");
    }
}
