//! What a problem in a definition file is ([`DefinitionError`]: a located file error) and how
//! an error inside an expression string gets its place in the file (`ExpressionPlace`): what
//! the readers of a definition's parts share.

use std::ops::Range;

use crate::diagnostic::{FileError, Source};
use crate::parse::ExprError;

/// A problem in a definition file, with its place and a suggested fix (file, line, column,
/// message, help), displayed like a rustc error.
pub type DefinitionError = FileError;

/// Places inside expression strings.
pub(crate) trait ExpressionPlace {
    /// Turns an error inside the string value at `span` into an error at its place in the file.
    fn expression_error(&self, span: Range<usize>, value: &str, e: ExprError) -> DefinitionError;
}

impl ExpressionPlace for Source<'_> {
    fn expression_error(&self, span: Range<usize>, value: &str, e: ExprError) -> DefinitionError {
        let offset = self.offset_in_string(span, value, e.line, e.column);
        self.error_at_offset(offset, e.message, e.help)
    }
}
