//! A buffered output file that remembers its path for error messages ([`OutputFile`]), and
//! the atomic write of a JSON file ([`write_atomically`]): what the run's writers share.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::error::Error;

/// The longest line [`OutputFile::append`] reads from a file it continues: 1 MiB, far above a
/// trajectory.csv row (tens of columns of at most 25 characters) or a lab.xyz line.
pub const MAX_LINE_BYTES: u64 = 1 << 20;

/// A writer that remembers its path for error messages.
pub struct OutputFile {
    path: PathBuf,
    out: BufWriter<File>,
}

impl OutputFile {
    /// Creates (truncates) `dir/name`.
    pub fn create(dir: &Path, name: &str) -> Result<Self, Error> {
        let path = dir.join(name);
        let file = File::create(&path).map_err(|e| Error::io("cannot create", &path, e))?;
        Ok(OutputFile { path, out: BufWriter::new(file) })
    }

    /// Opens `dir/name` to append to it (a resumed run), after checking that its first line is
    /// `first_line` (the header this run would write), that it ends with a whole line and that
    /// it has `lines` lines (what the run being continued wrote, no more and no less).
    pub fn append(dir: &Path, name: &str, first_line: &str, lines: usize) -> Result<Self, Error> {
        use std::io::{BufRead as _, Read as _};
        let path = dir.join(name);
        // Read a line at a time, each of at most MAX_LINE_BYTES, and stop past `lines`: memory
        // stays bounded whatever the file is (a link to /dev/zero, a huge file).
        let file = File::open(&path).map_err(|e| Error::io("cannot read (to continue it)", &path, e))?;
        let mut reader = std::io::BufReader::new(file);
        let mut line = Vec::new();
        let mut found_lines = 0;
        loop {
            line.clear();
            let read = (&mut reader)
                .take(MAX_LINE_BYTES + 1)
                .read_until(b'\n', &mut line)
                .map_err(|e| Error::io("cannot read (to continue it)", &path, e))?;
            if read == 0 {
                break;
            }
            if !line.ends_with(b"\n") {
                if line.len() as u64 > MAX_LINE_BYTES {
                    return Err(Error::unusable(
                        path,
                        format!(
                            ": line {} is longer than {MAX_LINE_BYTES} bytes, the most a line of this output can be: \
                             it is not this run's file (resume into the directory of the run that wrote the restart \
                             file)",
                            found_lines + 1
                        ),
                    ));
                }
                return Err(Error::unusable(path, " ends inside a line; it was cut and cannot be continued"));
            }
            if found_lines == 0 {
                let found = String::from_utf8_lossy(&line);
                let found = found.trim_end_matches('\n').trim_end_matches('\r');
                if found != first_line {
                    return Err(Error::unusable(
                        &path,
                        format!(
                            " starts with `{found}`, not `{first_line}` as this run writes it: it is not this run's \
                             (resume into the directory of the run that wrote the restart file)"
                        ),
                    ));
                }
            }
            found_lines += 1;
            if found_lines > lines {
                return Err(Error::unusable(
                    path,
                    format!(
                        " has more than the {lines} lines the run that wrote the restart file left: it was changed \
                         or already continued"
                    ),
                ));
            }
        }
        if found_lines != lines {
            return Err(Error::unusable(
                path,
                format!(
                    " has {found_lines} lines, but the run that wrote the restart file left {lines}: it was changed \
                     or already continued"
                ),
            ));
        }
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .map_err(|e| Error::io("cannot open (to continue it)", &path, e))?;
        Ok(OutputFile { path, out: BufWriter::new(file) })
    }

    /// Writes one line (a newline is added).
    pub fn line(&mut self, text: &str) -> Result<(), Error> {
        writeln!(self.out, "{text}").map_err(|e| Error::io("cannot write", &self.path, e))
    }

    /// Flushes the buffer to disk.
    pub fn flush(&mut self) -> Result<(), Error> {
        self.out.flush().map_err(|e| Error::io("cannot write", &self.path, e))
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Writes `value` (pretty-printed JSON) to `dir/name` atomically: to `name.tmp`, flushed and
/// synced, then renamed over `name`.
pub fn write_atomically(dir: &Path, name: &str, value: &Value) -> Result<PathBuf, Error> {
    let tmp = dir.join(format!("{name}.tmp"));
    let path = dir.join(name);
    let write = || -> std::io::Result<()> {
        let mut file = File::create(&tmp)?;
        writeln!(file, "{}", serde_json::to_string_pretty(value).expect("a JSON value serialises"))?;
        file.sync_all()
    };
    write().map_err(|e| Error::io("cannot write", &tmp, e))?;
    std::fs::rename(&tmp, &path).map_err(|e| Error::io(format!("cannot rename {} to", tmp.display()), &path, e))?;
    Ok(path)
}
