//! The definition's `[arrays]` table: coefficient arrays for `c[k]` in expressions, given inline
//! or read from a CSV file beside the definition.
//!
//! ```toml
//! [arrays]
//! c = [1.0, -0.25, 0.03]                  # inline
//! d = { file = "fit.csv", column = 2 }    # column 2 (1-based) of fit.csv, next to this file
//! ```
//!
//! A CSV file has one value per line in the named column (columns separated by commas; default
//! column 1); blank lines and lines starting with `#` are skipped. Every problem names the file
//! and line.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use crate::definition_error::DefinitionError;
use crate::diagnostic::Source;

/// One entry of `[arrays]` as read.
#[derive(Deserialize, Clone)]
#[serde(untagged)]
pub(crate) enum RawArray {
    /// Inline values.
    Values(Vec<f64>),
    /// A CSV file beside the definition.
    File {
        /// Path relative to the definition's directory.
        file: String,
        /// 1-based column, default 1.
        #[serde(default)]
        column: Option<usize>,
    },
}

/// The largest CSV file read for an array.
const MAX_CSV_BYTES: u64 = 64 << 20;

/// The arrays read (name, values), the data files read, and the problems found.
pub(crate) type Arrays = (Vec<(Spanned<String>, Vec<f64>)>, Vec<PathBuf>, Vec<DefinitionError>);

/// Reads every array: name → values, plus the data files read (for rebuilds when they change).
/// `base` is the directory of the definition file, or `None` when the definition did not come
/// from a file (then a `file` entry is an error).
pub(crate) fn read(
    src: &Source<'_>,
    table: &BTreeMap<Spanned<String>, Spanned<RawArray>>,
    base: Option<&Path>,
) -> Arrays {
    let (mut arrays, mut files, mut errors) = (Vec::new(), Vec::new(), Vec::new());
    for (name, raw) in table {
        let values = match raw.get_ref() {
            RawArray::Values(v) if v.is_empty() => {
                Err(src.error(raw.span(), format!("array `{}` is empty", name.get_ref()), "give at least one value"))
            }
            RawArray::Values(v) => match v.iter().position(|x| !x.is_finite()) {
                Some(i) => Err(src.error(
                    raw.span(),
                    format!("value {i} of array `{}` is not finite", name.get_ref()),
                    "write finite numbers",
                )),
                None => Ok(v.clone()),
            },
            RawArray::File { file, column } => {
                let column = match column.unwrap_or(1) {
                    0 => Err(src.error(raw.span(), "column 0 does not exist", "columns are counted from 1")),
                    c => Ok(c),
                };
                column.and_then(|column| {
                    let Some(base) = base else {
                        return Err(src.error(
                            raw.span(),
                            "an array from a file needs the definition's directory",
                            "generate the definition from its file (the path is relative to it)",
                        ));
                    };
                    let path = base.join(file);
                    files.push(path.clone());
                    read_csv(src, raw.span(), &path, column)
                })
            }
        };
        match values {
            Ok(v) => arrays.push((name.clone(), v)),
            Err(e) => {
                errors.push(e);
                // A stand-in, so that uses of the array are not reported as well.
                arrays.push((name.clone(), vec![1.0; crate::parse::MAX_SUM_TERMS]));
            }
        }
    }
    (arrays, files, errors)
}

/// Column `column` (1-based) of the CSV file at `path`, named by the entry at `entry`.
fn read_csv(src: &Source<'_>, entry: Range<usize>, path: &Path, column: usize) -> Result<Vec<f64>, DefinitionError> {
    let text = rovib_base::input::read_text_capped(path, MAX_CSV_BYTES).map_err(|message| {
        src.error(
            entry.clone(),
            format!("cannot read `{}`: {message}", path.display()),
            "the path is relative to the definition file's directory",
        )
    })?;
    let display = path.display().to_string();
    let csv = Source { path: &display, text: &text };
    let mut values = Vec::new();
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let start = offset;
        offset += line.len();
        let content = line.trim();
        if content.is_empty() || content.starts_with('#') {
            continue;
        }
        let Some(field) = content.split(',').nth(column - 1) else {
            return Err(csv.error_at_offset(
                start,
                format!("this line has {} column(s), not column {column}", content.split(',').count()),
                "give every line the column the definition reads, or change `column`",
            ));
        };
        let field_offset = start + line.find(field.trim()).unwrap_or(0);
        match field.trim().parse::<f64>() {
            Ok(v) if v.is_finite() => values.push(v),
            _ => {
                return Err(csv.error_at_offset(
                    field_offset,
                    format!("`{}` is not a finite number", field.trim()),
                    "write one number per line in this column; start comment lines with #",
                ));
            }
        }
    }
    if values.is_empty() {
        return Err(src.error(entry, format!("`{display}` has no values"), "give at least one value"));
    }
    Ok(values)
}
