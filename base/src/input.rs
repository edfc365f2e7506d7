//! Reading input files (molecule definitions, scenes, states files) with a size limit, so that
//! a path such as `/dev/zero` or `/dev/urandom`, or a huge file given by mistake, is an error
//! with the numbers instead of memory that grows until the process is killed.

use std::io::Read;
use std::path::Path;

/// The largest definition or scene file read: 16 MiB, far above any real one (the largest
/// shipped definition is a few KiB; a 10⁴-term potential is about 0.5 MiB).
pub const MAX_INPUT_BYTES: u64 = 16 << 20;

/// Reads `path` as UTF-8 text of at most `limit` bytes. The error is one line naming the file
/// and, for a file that is too large, the limit and what to do.
pub fn read_text_capped(path: &Path, limit: u64) -> Result<String, String> {
    let file = std::fs::File::open(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    read_capped(file, &path.display().to_string(), limit)
}

/// Reads UTF-8 text of at most `limit` bytes from `reader` (a file, stdin), named `name` in
/// errors.
pub fn read_capped(reader: impl Read, name: &str, limit: u64) -> Result<String, String> {
    let mut bytes = Vec::new();
    // One byte more than the limit tells "exactly at the limit" from "larger".
    reader.take(limit.saturating_add(1)).read_to_end(&mut bytes).map_err(|e| format!("cannot read {name}: {e}"))?;
    if bytes.len() as u64 > limit {
        return Err(format!(
            "cannot read {name}: it is larger than {limit} bytes ({} MiB), the limit for this kind of input file; \
             check that the path names the file you mean",
            limit >> 20
        ));
    }
    String::from_utf8(bytes).map_err(|e| {
        format!("cannot read {name}: not UTF-8 text (invalid byte at offset {})", e.utf8_error().valid_up_to())
    })
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
        let e = read_text_capped(&path, 99).unwrap_err();
        assert!(e.contains("larger than 99 bytes") && e.contains("f.toml"), "{e}");
        std::fs::write(&path, [b'a', 0xff, b'b']).unwrap();
        assert!(read_text_capped(&path, 100).unwrap_err().contains("not UTF-8 text (invalid byte at offset 1)"));
        if Path::new("/dev/zero").exists() {
            let e = read_text_capped(Path::new("/dev/zero"), MAX_INPUT_BYTES).unwrap_err();
            assert!(e.contains("larger than 16777216 bytes (16 MiB)"), "{e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
