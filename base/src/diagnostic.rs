//! Errors located in a text file (molecule definitions, scenes): file, line, column, what is
//! wrong and what to change, displayed the way rustc shows its errors.
//!
//! It lives in `rovib-base`, which both the generator and the runtime depend on, so definition
//! errors (from the build) and scene errors (from `rovib run`) are one type and look the same.

use core::fmt;
use core::ops::Range;

/// A problem in a file, with its place and a suggested fix.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileError {
    /// The file as the user named it (e.g. `molecules/h2o.toml`).
    pub path: String,
    /// 1-based line, or 0 if the problem concerns the whole file.
    pub line: usize,
    /// 1-based column (in characters), or 0.
    pub column: usize,
    /// What is wrong.
    pub message: String,
    /// What to change.
    pub help: String,
    /// The text of the offending line, for display.
    pub source_line: Option<String>,
}

impl fmt::Display for FileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "error: {}", self.message)?;
        if self.line == 0 {
            writeln!(f, "  --> {}", self.path)?;
        } else {
            writeln!(f, "  --> {}:{}:{}", self.path, self.line, self.column)?;
        }
        if let Some(src) = &self.source_line {
            let gutter = self.line.to_string();
            let pad = " ".repeat(gutter.len());
            writeln!(f, "{pad} |")?;
            writeln!(f, "{gutter} | {src}")?;
            let caret_pad: String =
                src.chars().take(self.column.saturating_sub(1)).map(|c| if c == '\t' { '\t' } else { ' ' }).collect();
            writeln!(f, "{pad} | {caret_pad}^")?;
        }
        write!(f, "  = help: {}", self.help)
    }
}

impl std::error::Error for FileError {}

impl FileError {
    /// The error on one line: `path:line:column: message (help: ...)`, for places where a
    /// multi-line display does not fit.
    pub fn one_line(&self) -> String {
        if self.line == 0 {
            format!("{}: {} (help: {})", self.path, self.message, self.help)
        } else {
            format!("{}:{}:{}: {} (help: {})", self.path, self.line, self.column, self.message, self.help)
        }
    }
}

/// The text of a file, for turning byte offsets into places.
#[derive(Copy, Clone, Debug)]
pub struct Source<'a> {
    /// The file as the user named it.
    pub path: &'a str,
    /// Its contents.
    pub text: &'a str,
}

impl Source<'_> {
    /// The 1-based line and column (in characters) of a byte offset.
    pub fn place(&self, offset: usize) -> (usize, usize) {
        let offset = offset.min(self.text.len());
        let before = &self.text[..offset];
        let line = before.matches('\n').count() + 1;
        let line_start = before.rfind('\n').map_or(0, |i| i + 1);
        let column = self.text[line_start..offset].chars().count() + 1;
        (line, column)
    }

    fn line_text(&self, line: usize) -> Option<String> {
        self.text.lines().nth(line.checked_sub(1)?).map(str::to_owned)
    }

    /// An error at a byte offset.
    pub fn error_at_offset(&self, offset: usize, message: impl Into<String>, help: impl Into<String>) -> FileError {
        let (line, column) = self.place(offset);
        FileError {
            path: self.path.to_owned(),
            line,
            column,
            message: message.into(),
            help: help.into(),
            source_line: self.line_text(line),
        }
    }

    /// An error at the start of a span.
    pub fn error(&self, span: Range<usize>, message: impl Into<String>, help: impl Into<String>) -> FileError {
        self.error_at_offset(span.start, message, help)
    }

    /// An error about the file as a whole.
    pub fn whole_file(&self, message: impl Into<String>, help: impl Into<String>) -> FileError {
        FileError {
            path: self.path.to_owned(),
            line: 0,
            column: 0,
            message: message.into(),
            help: help.into(),
            source_line: None,
        }
    }

    /// The byte offset in the file of a place inside the string value at `span` (TOML syntax,
    /// any of the four quote styles), given as a 1-based line and 0-based character column
    /// within the string's contents. Where the string has escapes, the offset is that of the
    /// string itself, since the contents and the source no longer line up.
    pub fn offset_in_string(&self, span: Range<usize>, value: &str, line: usize, column: usize) -> usize {
        let raw = &self.text[span.clone()];
        let delimiter = ["\"\"\"", "'''", "\"", "'"].into_iter().find(|d| raw.starts_with(d)).unwrap_or("");
        let mut content_start = span.start + delimiter.len();
        let mut content = &raw[delimiter.len()..raw.len().saturating_sub(delimiter.len())];
        if delimiter.len() == 3 {
            // TOML drops a newline right after the opening delimiter of a multi-line string.
            for nl in ["\r\n", "\n"] {
                if let Some(rest) = content.strip_prefix(nl) {
                    content = rest;
                    content_start += nl.len();
                    break;
                }
            }
        }
        if content != value {
            return span.start;
        }
        let line_start: usize = content.split_inclusive('\n').take(line.saturating_sub(1)).map(str::len).sum();
        let in_line: usize = content[line_start..].chars().take(column).map(char::len_utf8).sum();
        content_start + line_start + in_line
    }
}
