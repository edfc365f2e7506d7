//! Checkpoint file of an ensemble: one JSON line per finished block, so a killed run resumes.
//!
//! The first line is a [`Header`] (format, scene hash, seed, trajectory count, block size, lane
//! setting). Then optionally one `merged` line, the outcome of blocks `0..merged` already merged
//! in block order (what an uninterrupted run holds at that point), then one line per further
//! finished block (index and [`Outcome`]), in the order they finished. Each of these lines is
//! `{"sum":"<16 hex digits>","record":<the record>}`, the sum being [`scene_hash`] (FNV-1a) of
//! the header line, a newline and the record's exact bytes: a line changed by hand (a mean, a
//! count, a block index) or copied from another run's checkpoint is refused with its file and
//! line instead of resumed into different outputs. (The sum detects edits and mix-ups, not a
//! forger who recomputes it: it has no secret.) Every batch of lines is written whole,
//! flushed and `fsync`ed before the next is recorded, so a run killed at any moment leaves at most
//! one torn last line, which [`Checkpoint::resume`] drops (and truncates away). Floats go through
//! serde_json with `float_roundtrip`, so a resumed run merges exactly the numbers the killed run
//! computed and its outputs are byte-identical to an uninterrupted run's.
//!
//! [`Checkpoint::compact`] rewrites the file (a temporary file, synced, then renamed over the old
//! one, so either the old or the new file is there after a crash) as the header, the merged
//! prefix and the blocks still out of order: the file stays a few blocks long however many
//! trajectories the ensemble has.

use std::collections::BTreeMap;
use std::fmt;
use std::fs::{File, OpenOptions};
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::runner::Outcome;

/// Version of the checkpoint layout; a file of another version is refused, not misread.
pub const FORMAT: u32 = 2;

/// What a checkpoint belongs to; a resume with any field different is refused.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    /// [`FORMAT`].
    pub format: u32,
    /// [`scene_hash`] of the scene file's bytes, as 16 hexadecimal digits.
    pub scene_hash: String,
    /// The ensemble's seed.
    pub seed: u64,
    /// Trajectories in the ensemble.
    pub trajectories: u64,
    /// Trajectories per block.
    pub block: u64,
    /// Whether trajectories ran on SIMD lanes (`--no-lanes`: false). Lanes and one trajectory
    /// at a time agree to round-off only, so a resume must use the setting of the run it
    /// continues for its outputs to be those of an uninterrupted run.
    pub lanes: bool,
    /// The chart the trajectories are integrated in (`run.chart`: "internal" or "cartesian";
    /// "internal" for checkpoints written before the key existed). The charts agree within the
    /// tolerances only, so a resume must use the chart of the run it continues.
    #[serde(default = "internal_chart")]
    pub chart: String,
}

fn internal_chart() -> String {
    "internal".into()
}

impl Header {
    /// The header of an ensemble of `trajectories` from the scene file's `scene` bytes.
    /// Lanes on (the default; see [`Header::with_lanes`]).
    pub fn new(scene: &[u8], seed: u64, trajectories: u64, block: u64) -> Self {
        Self {
            format: FORMAT,
            scene_hash: format!("{:016x}", scene_hash(scene)),
            seed,
            trajectories,
            block,
            lanes: true,
            chart: internal_chart(),
        }
    }

    /// The same header with the chart `chart` (`run.chart`).
    pub fn with_chart(self, chart: &str) -> Self {
        Self { chart: chart.into(), ..self }
    }

    /// The same header with the lane setting `lanes`.
    pub fn with_lanes(self, lanes: bool) -> Self {
        Self { lanes, ..self }
    }

    /// The header as written on the checkpoint's first line (and covered by every line's sum).
    fn text(&self) -> String {
        serde_json::to_string(self).expect("a header serialises")
    }

    fn blocks(&self) -> u64 {
        self.trajectories.div_ceil(self.block.max(1))
    }
}

/// What makes blocks of two processes (MPI ranks) mergeable: the run's [`Header`] (hash of the
/// scene and states file, seed, N, block size, lane setting) and the layout of its statistics.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Identity {
    /// The run, as its checkpoint records it.
    pub header: Header,
    /// The statistics' layout.
    pub layout: Layout,
}

/// The shape of a run's accumulators.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layout {
    /// Output times.
    pub n_times: usize,
    /// Quantities with means.
    pub n_means: usize,
    /// Each histogram's bins, low and high edge.
    pub histograms: Vec<(usize, f64, f64)>,
    /// Each correlation function's lags.
    pub correlations: Vec<usize>,
}

impl Layout {
    /// The layout of `a`.
    pub fn of(a: &super::runner::Accumulators) -> Self {
        Self {
            n_times: a.n_times,
            n_means: a.n_means,
            histograms: a.histograms.iter().map(|h| (h.counts().len(), h.low(), h.high())).collect(),
            correlations: a.correlations.iter().map(Vec::len).collect(),
        }
    }
}

impl Identity {
    /// What differs in `other` from this identity, one phrase each (`other`'s value, then
    /// this one's); empty when the two runs are the same.
    pub fn differences(&self, other: &Identity, this: &str) -> Vec<String> {
        let (a, b) = (&self.header, &other.header);
        let mut d = Vec::new();
        if a.format != b.format {
            d.push(format!("message format {} ({this}: {}): another rovib version", b.format, a.format));
        }
        if a.scene_hash != b.scene_hash {
            d.push(format!(
                "scene hash {} ({this}: {}): another scene file or states file",
                b.scene_hash, a.scene_hash
            ));
        }
        if a.seed != b.seed {
            d.push(format!("seed {} ({this}: {})", b.seed, a.seed));
        }
        if a.trajectories != b.trajectories {
            d.push(format!("{} trajectories ({this}: {})", b.trajectories, a.trajectories));
        }
        if a.block != b.block {
            d.push(format!("blocks of {} ({this}: {})", b.block, a.block));
        }
        if a.lanes != b.lanes {
            let s = |l: bool| if l { "lanes" } else { "--no-lanes" };
            d.push(format!("{} ({this}: {})", s(b.lanes), s(a.lanes)));
        }
        if a.chart != b.chart {
            d.push(format!("run.chart = \"{}\" ({this}: \"{}\")", b.chart, a.chart));
        }
        if self.layout != other.layout {
            d.push(format!("statistics layout {:?} ({this}: {:?})", other.layout, self.layout));
        }
        d
    }
}

/// How many times longer a line may be than the same line of an empty outcome: every number
/// of an empty outcome is written as `0` or `0.0`, and the longest an integer (20 digits) or
/// float (24 characters) can be is under 16 times that, separators included.
const NUMBER_GROWTH: u64 = 16;

/// Room per line for the text of the listed failures (at most `LISTED_FAILURES` messages).
const FAILURE_TEXT_BYTES: u64 = 64 << 10;

/// The largest checkpoint of this run [`Checkpoint::resume`] reads, in bytes: the header, the
/// merged line and one line per block, each at most `NUMBER_GROWTH` (16) times the line of `empty`
/// (an outcome of this run's shape with nothing in it) plus `FAILURE_TEXT_BYTES` (64 KiB). A
/// checkpoint larger than that is not one this run wrote (a wrong file, `/dev/zero`): it is
/// refused with the figures instead of read into memory without bound.
pub fn size_limit(header: &Header, empty: &Outcome) -> u64 {
    let mut bytes = Vec::new();
    line(&mut bytes, &header.text(), &Line::Merged { merged: header.blocks(), outcome: empty.clone() });
    let per_line = (bytes.len() as u64).saturating_mul(NUMBER_GROWTH).saturating_add(FAILURE_TEXT_BYTES);
    header.blocks().saturating_add(2).saturating_mul(per_line)
}

/// One recorded block, or the merged outcome of the first blocks.
#[derive(Serialize, Deserialize)]
#[serde(untagged, deny_unknown_fields)]
enum Line {
    Block { block: u64, outcome: Outcome },
    Merged { merged: u64, outcome: Outcome },
}

/// What a checkpoint holds: the merged outcome of blocks `0..merged.0` (if any were merged) and
/// the outcomes of further finished blocks by index.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Resumed {
    /// Blocks `0..n` merged in block order, and their outcome.
    pub merged: Option<(u64, Outcome)>,
    /// Other finished blocks (all at or past the merged ones).
    pub blocks: BTreeMap<u64, Outcome>,
}

/// Appends `line` to `bytes` as `{"sum":"…","record":…}` and a newline; `header` is the text of
/// the checkpoint's first line.
fn line(bytes: &mut Vec<u8>, header: &str, line: &Line) {
    let record = serde_json::to_vec(line).expect("an outcome serialises");
    bytes.extend_from_slice(format!("{SUM_PREFIX}{:016x}{RECORD_PREFIX}", line_sum(header, &record)).as_bytes());
    bytes.extend_from_slice(&record);
    bytes.extend_from_slice(b"}\n");
}

const SUM_PREFIX: &str = "{\"sum\":\"";
const RECORD_PREFIX: &str = "\",\"record\":";

/// The sum of a record line: FNV-1a of the header line, a newline and the record's bytes.
fn line_sum(header: &str, record: &[u8]) -> u64 {
    let h = header.bytes().chain(std::iter::once(b'\n')).chain(record.iter().copied());
    h.fold(0xcbf2_9ce4_8422_2325_u64, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3))
}

/// What to do when a checkpoint cannot be resumed, for the command's and the library's users.
const AFRESH: &str = "start afresh (without `--resume`, `EnsembleOptions::resume`)";
/// Trajectories run without lanes, as both users ask for it.
const ONE_AT_A_TIME: &str = "one at a time (`--no-lanes`, `EnsembleOptions::lanes = false`)";

/// The record of a line written by [`line`], after checking its sum against `header` (the
/// checkpoint's first line); the error says what is wrong.
fn checked_record<'a>(header: &str, text: &'a str) -> Result<&'a str, String> {
    let malformed = || "not a checkpoint record line (`{\"sum\":…,\"record\":…}`); delete this line".to_owned();
    let rest = text.strip_prefix(SUM_PREFIX).ok_or_else(malformed)?;
    let (sum, rest) = rest.split_at_checked(16).ok_or_else(malformed)?;
    let record = rest.strip_prefix(RECORD_PREFIX).and_then(|r| r.strip_suffix('}')).ok_or_else(malformed)?;
    let sum = u64::from_str_radix(sum, 16).map_err(|_| malformed())?;
    let expected = line_sum(header, record.as_bytes());
    if sum != expected {
        return Err(format!(
            "the line's sum {sum:016x} does not match its content and the header ({expected:016x}): the line was \
             changed, or copied from another checkpoint; delete this line and every line after it (their blocks \
             run again), or {AFRESH} after deleting the file"
        ));
    }
    Ok(record)
}

/// FNV-1a (64 bit) of `bytes`: stable across platforms and Rust versions, unlike `DefaultHasher`.
pub fn scene_hash(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325_u64, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3))
}

/// A checkpoint that cannot be written or does not fit this run: the file, the line (if any)
/// and what to change.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CheckpointError {
    /// The checkpoint file.
    pub path: PathBuf,
    /// 1-based line, when the problem is in one.
    pub line: Option<usize>,
    /// What is wrong and what to do.
    pub message: String,
}

impl fmt::Display for CheckpointError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}:{}: {}", self.path.display(), l, self.message),
            None => write!(f, "{}: {}", self.path.display(), self.message),
        }
    }
}

impl std::error::Error for CheckpointError {}

/// An open checkpoint, appended to as blocks finish.
pub struct Checkpoint {
    file: File,
    path: PathBuf,
    /// The header line's text, covered by every record line's sum.
    header: String,
}

impl Checkpoint {
    /// Starts a new checkpoint at `path` (replacing any old one) with `header`.
    pub fn create(path: &Path, header: &Header) -> Result<Self, CheckpointError> {
        let err = |e: std::io::Error| CheckpointError {
            path: path.to_owned(),
            line: None,
            message: format!("cannot write the checkpoint: {e}"),
        };
        let file = File::create(path).map_err(err)?;
        let mut c = Self { file, path: path.to_owned(), header: header.text() };
        let text = c.header.clone();
        c.write_line(&text)?;
        Ok(c)
    }

    /// Opens the checkpoint at `path` to continue it: checks its header against `header` and
    /// returns what it holds. A torn last line (a run killed mid-write) is dropped. A file of
    /// more than `limit` bytes ([`size_limit`]) is refused unread.
    pub fn resume(path: &Path, header: &Header, limit: u64) -> Result<(Self, Resumed), CheckpointError> {
        let fail = |line: Option<usize>, message: String| CheckpointError { path: path.to_owned(), line, message };
        let text = crate::runtime::diagnostic::read_text_capped(path, limit).map_err(|e| {
            fail(
                None,
                format!("{e} (the checkpoint of this run is at most {limit} bytes); {AFRESH} after deleting the file"),
            )
        })?;
        // Only lines ending in '\n' were completely written.
        let complete = text.rfind('\n').map_or(0, |i| i + 1);
        let mut lines = text[..complete].lines();
        let first = lines.next().ok_or_else(|| fail(Some(1), format!("no header; {AFRESH}")))?;
        let found: Header = serde_json::from_str(first)
            .map_err(|e| fail(Some(1), format!("not a checkpoint header ({e}); {AFRESH}")))?;
        if found.format != header.format {
            return Err(fail(
                Some(1),
                format!(
                    "the checkpoint has format {}, this rovib writes format {}; {AFRESH} after deleting the file",
                    found.format, header.format
                ),
            ));
        }
        if found == header.clone().with_lanes(found.lanes) && found.lanes != header.lanes {
            let setting = |lanes: bool| if lanes { "on SIMD lanes (the default)" } else { ONE_AT_A_TIME };
            return Err(fail(
                Some(1),
                format!(
                    "the checkpoint was written with trajectories run {}, this resume runs them {}: the two agree \
                     to round-off only, so the outputs would not be those of an uninterrupted run; resume {}",
                    setting(found.lanes),
                    setting(header.lanes),
                    if found.lanes { "on lanes (without `--no-lanes`)" } else { ONE_AT_A_TIME }
                ),
            ));
        }
        if found != *header {
            return Err(fail(
                Some(1),
                format!(
                    "the checkpoint is of another run (found {found:?}, expected {header:?}); {AFRESH} \
                     or restore the scene and seed it was made with"
                ),
            ));
        }
        let mut resumed = Resumed::default();
        for (i, l) in lines.enumerate() {
            let n = i + 2;
            let record = checked_record(first, l).map_err(|m| fail(Some(n), m))?;
            let line: Line = serde_json::from_str(record)
                .map_err(|e| fail(Some(n), format!("not a block record ({e}); delete this line")))?;
            match line {
                Line::Merged { merged, outcome } if n == 2 && merged <= header.blocks() => {
                    resumed.merged = Some((merged, outcome));
                }
                Line::Merged { .. } => {
                    return Err(fail(
                        Some(n),
                        "a merged record must be the second line and within the ensemble".into(),
                    ));
                }
                Line::Block { block, outcome } => {
                    if block >= header.blocks() {
                        return Err(fail(
                            Some(n),
                            format!("block {block} is past the last block {}", header.blocks() - 1),
                        ));
                    }
                    if resumed.merged.as_ref().is_some_and(|(m, _)| block < *m)
                        || resumed.blocks.insert(block, outcome).is_some()
                    {
                        return Err(fail(Some(n), format!("block {block} recorded twice; delete this line")));
                    }
                }
            }
        }
        let mut file = OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| fail(None, format!("cannot reopen the checkpoint for writing: {e}")))?;
        let end = complete as u64;
        file.set_len(end)
            .and_then(|()| file.seek(SeekFrom::Start(end)).map(drop))
            .map_err(|e| fail(None, format!("cannot drop the torn last line: {e}")))?;
        Ok((Self { file, path: path.to_owned(), header: first.to_owned() }, resumed))
    }

    /// Records `block`'s outcome, durably (written, flushed and synced) before returning.
    pub fn append(&mut self, block: u64, outcome: &Outcome) -> Result<(), CheckpointError> {
        self.append_all(&[(block, outcome)])
    }

    /// Records several blocks with one write and one sync.
    pub fn append_all(&mut self, blocks: &[(u64, &Outcome)]) -> Result<(), CheckpointError> {
        let mut bytes = Vec::new();
        for &(block, outcome) in blocks {
            line(&mut bytes, &self.header, &Line::Block { block, outcome: outcome.clone() });
        }
        self.write_bytes(&bytes)
    }

    /// Rewrites the checkpoint as `header`, the outcome `merged` of blocks `0..next` and the
    /// further finished blocks `pending`, atomically (temporary file, sync, rename, sync of the
    /// folder), and goes on appending to the new file.
    pub fn compact(
        &mut self,
        header: &Header,
        next: u64,
        merged: &Outcome,
        pending: &BTreeMap<u64, Outcome>,
    ) -> Result<(), CheckpointError> {
        let err = |e: std::io::Error| CheckpointError {
            path: self.path.clone(),
            line: None,
            message: format!("cannot rewrite the checkpoint: {e}"),
        };
        let text = header.text();
        let mut bytes = text.clone().into_bytes();
        bytes.push(b'\n');
        if next > 0 {
            line(&mut bytes, &text, &Line::Merged { merged: next, outcome: merged.clone() });
        }
        for (&block, outcome) in pending {
            line(&mut bytes, &text, &Line::Block { block, outcome: outcome.clone() });
        }
        let mut name = self.path.file_name().unwrap_or_default().to_owned();
        name.push(".tmp");
        let tmp = self.path.with_file_name(name);
        let mut file = File::create(&tmp).map_err(err)?;
        file.write_all(&bytes).and_then(|()| file.sync_all()).map_err(err)?;
        std::fs::rename(&tmp, &self.path).map_err(err)?;
        // The rename is durable once the folder is synced (where folders can be opened).
        if let Some(dir) =
            self.path.parent().and_then(|d| File::open(if d.as_os_str().is_empty() { Path::new(".") } else { d }).ok())
        {
            let _ = dir.sync_all();
        }
        self.file = OpenOptions::new().append(true).open(&self.path).map_err(err)?;
        self.header = text;
        Ok(())
    }

    /// The checkpoint file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn write_line(&mut self, text: &str) -> Result<(), CheckpointError> {
        let mut bytes = Vec::with_capacity(text.len() + 1);
        bytes.extend_from_slice(text.as_bytes());
        bytes.push(b'\n');
        self.write_bytes(&bytes)
    }

    fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), CheckpointError> {
        self.file.write_all(bytes).and_then(|()| self.file.flush()).and_then(|()| self.file.sync_data()).map_err(|e| {
            CheckpointError {
                path: self.path.clone(),
                line: None,
                message: format!("cannot write the checkpoint: {e}"),
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ensemble::runner::{Accumulators, Failure};
    use crate::runtime::ensemble::Moments;

    /// An outcome whose sums are awkward floats (not exactly representable in few digits).
    fn outcome(seed: u64) -> Outcome {
        let mut m = Moments::new();
        for k in 0..5 {
            m.add(((seed * 7 + k) as f64).sqrt() / 3.0 + 1e-17 * k as f64);
        }
        let statistics =
            Accumulators { n_times: 1, n_means: 1, means: vec![m], histograms: Vec::new(), correlations: Vec::new() };
        let mut o = Outcome::new(statistics);
        o.completed = 5;
        o.steps = 100 + seed;
        o
    }

    /// Means in [`widest`]: enough that the numbers, not the failure text, fill a line.
    const WIDE: usize = 4000;

    /// The size limit of a checkpoint of [`widest`]'s shape.
    fn limit(header: &Header) -> u64 {
        let empty = Accumulators {
            n_times: WIDE,
            n_means: 1,
            means: vec![Moments::new(); WIDE],
            histograms: Vec::new(),
            correlations: Vec::new(),
        };
        size_limit(header, &Outcome::new(empty))
    }

    /// The longest block a run of this shape can write: the widest numbers and the
    /// listed failures with long messages.
    fn widest(seed: u64) -> Outcome {
        let mut o = outcome(seed);
        let mut m = Moments::new();
        for x in [-1.2345678901234567e-300, 1.2345678901234567e100, -9.876543210987654e-105] {
            m.add(x);
        }
        o.statistics.means = vec![m; WIDE];
        o.statistics.n_times = WIDE;
        (o.completed, o.steps, o.rhs_evaluations, o.interrupted) = (u64::MAX, u64::MAX, u64::MAX, u64::MAX);
        for reason in ["energy guard", "too many steps", "step size too small", "non-finite", "not converged"] {
            o.failed.insert(reason.to_owned(), u64::MAX);
        }
        o.first_failures = (0..crate::ensemble::runner::LISTED_FAILURES as u64)
            .map(|i| Failure {
                index: u64::MAX - i,
                reason: "energy guard".into(),
                time: Some(-1.2345678901234567e-300),
                detail: "x".repeat(2000),
            })
            .collect();
        o
    }

    fn dir(name: &str) -> PathBuf {
        // The same directory on every run (removed first), so that runs do not pile up in /tmp.
        let d = std::env::temp_dir().join(format!("rovib-checkpoint-{name}"));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d.join("checkpoint.jsonl")
    }

    #[test]
    fn blocks_round_trip_exactly_and_a_torn_line_is_dropped() {
        let path = dir("roundtrip");
        let header = Header::new(b"scene", 7, 200, 64);
        let mut c = Checkpoint::create(&path, &header).unwrap();
        c.append(2, &outcome(2)).unwrap();
        c.append(0, &outcome(0)).unwrap();
        drop(c);
        // A run killed mid-write: half a line with no newline.
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        f.write_all(b"{\"block\":1,\"outco").unwrap();
        drop(f);
        let (mut c, resumed) = Checkpoint::resume(&path, &header, limit(&header)).unwrap();
        let done = resumed.blocks;
        assert_eq!(resumed.merged, None);
        assert_eq!(done.keys().copied().collect::<Vec<_>>(), vec![0, 2]);
        // Bit-exact floats, not merely close ones.
        assert_eq!(done[&0], outcome(0));
        assert_eq!(done[&2], outcome(2));
        c.append(1, &outcome(1)).unwrap();
        drop(c);
        let (_, resumed) = Checkpoint::resume(&path, &header, limit(&header)).unwrap();
        assert_eq!(resumed.blocks.len(), 3);
        assert_eq!(resumed.blocks[&1], outcome(1));
    }

    #[test]
    fn compaction_keeps_the_merged_prefix_and_the_blocks_out_of_order_exactly() {
        let path = dir("compact");
        let header = Header::new(b"scene", 7, 640, 64);
        let mut c = Checkpoint::create(&path, &header).unwrap();
        c.append_all(&[(0, &outcome(0)), (1, &outcome(1)), (4, &outcome(4))]).unwrap();
        let mut merged = outcome(0);
        merged.merge(&outcome(1)).unwrap();
        let pending = BTreeMap::from([(4, outcome(4))]);
        c.compact(&header, 2, &merged, &pending).unwrap();
        c.append(3, &outcome(3)).unwrap();
        drop(c);
        assert_eq!(std::fs::read_to_string(&path).unwrap().lines().count(), 4);
        assert!(!path.with_file_name("checkpoint.jsonl.tmp").exists());
        let (_, resumed) = Checkpoint::resume(&path, &header, limit(&header)).unwrap();
        assert_eq!(resumed.merged, Some((2, merged)));
        assert_eq!(resumed.blocks.keys().copied().collect::<Vec<_>>(), vec![3, 4]);
        assert_eq!(resumed.blocks[&3], outcome(3));
        // A block below the merged prefix is a duplicate.
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        let mut bytes = Vec::new();
        line(&mut bytes, &header.text(), &Line::Block { block: 1, outcome: outcome(1) });
        f.write_all(&bytes).unwrap();
        drop(f);
        let e = Checkpoint::resume(&path, &header, limit(&header)).err().unwrap();
        assert_eq!(e.line, Some(5));
        assert!(e.to_string().contains("recorded twice"), "{e}");
    }

    #[test]
    fn another_run_or_a_bad_line_is_refused_with_file_and_line() {
        let path = dir("refuse");
        let header = Header::new(b"scene", 7, 200, 64);
        let mut c = Checkpoint::create(&path, &header).unwrap();
        c.append(0, &outcome(0)).unwrap();
        drop(c);
        for other in [Header::new(b"scene!", 7, 200, 64), Header::new(b"scene", 8, 200, 64)] {
            let e = Checkpoint::resume(&path, &other, limit(&other)).err().unwrap();
            assert_eq!(e.line, Some(1));
            assert!(e.to_string().contains("another run"), "{e}");
        }
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        f.write_all(b"{\"block\":9}\n").unwrap();
        drop(f);
        let e = Checkpoint::resume(&path, &header, limit(&header)).err().unwrap();
        assert_eq!(e.line, Some(3));
        let missing = dir("missing").with_file_name("none.jsonl");
        assert!(Checkpoint::resume(&missing, &header, limit(&header)).is_err());
    }

    /// The size limit holds every checkpoint the run can write, and a larger file is refused
    /// unread with the figures and what to do.
    #[test]
    fn a_checkpoint_above_the_runs_size_limit_is_refused_unread() {
        let path = dir("limit");
        let header = Header::new(b"scene", 7, 200, 64);
        let mut c = Checkpoint::create(&path, &header).unwrap();
        c.compact(&header, 1, &widest(0), &BTreeMap::new()).unwrap();
        for b in 1..header.blocks() {
            c.append(b, &widest(b)).unwrap();
        }
        drop(c);
        let size = std::fs::metadata(&path).unwrap().len();
        let (_, resumed) = Checkpoint::resume(&path, &header, limit(&header)).unwrap();
        assert_eq!(resumed.blocks.len() as u64, header.blocks() - 1);
        assert!(size <= limit(&header), "a full checkpoint of {size} bytes is above the limit {}", limit(&header));
        // Proportional to the run: 32 blocks + 2 lines against 4 + 2.
        let ten = Header::new(b"scene", 7, 2000, 64);
        let ratio = limit(&ten) as f64 / limit(&header) as f64;
        assert!((ratio - 34.0 / 6.0).abs() < 1e-2, "{ratio}");

        std::fs::write(&path, "x".repeat(limit(&header) as usize + 1)).unwrap();
        let e = Checkpoint::resume(&path, &header, limit(&header)).err().unwrap();
        assert_eq!(e.path, path);
        let shown = e.to_string();
        assert!(shown.contains(&format!("larger than {} bytes", limit(&header))), "{shown}");
        assert!(shown.contains("start afresh (without `--resume`"), "{shown}");
    }

    /// A checkpoint of blocks 0 and 1 whose text is then edited by `edit`; the resume's error.
    fn edited(name: &str, edit: impl Fn(&str) -> String) -> CheckpointError {
        let path = dir(name);
        let header = Header::new(b"scene", 7, 200, 64);
        let mut c = Checkpoint::create(&path, &header).unwrap();
        c.append_all(&[(0, &outcome(0)), (1, &outcome(1))]).unwrap();
        drop(c);
        let text = std::fs::read_to_string(&path).unwrap();
        let changed = edit(&text);
        assert_ne!(changed, text, "the edit must change the file");
        std::fs::write(&path, changed).unwrap();
        Checkpoint::resume(&path, &header, limit(&header)).err().expect("an edited checkpoint must be refused")
    }

    #[test]
    fn an_edited_or_moved_line_is_refused_with_file_and_line() {
        // A changed count.
        let e = edited("count", |t| t.replacen("\"completed\":5", "\"completed\":6", 1));
        assert_eq!(e.line, Some(2));
        assert!(e.to_string().contains("does not match its content"), "{e}");
        // A changed mean: one digit of the first sum.
        let e = edited("mean", |t| {
            let at = t.find("\"sum\":").unwrap() + 200;
            let lines: Vec<&str> = t.lines().collect();
            let mut second = lines[1].to_owned();
            let digit = second[..].char_indices().skip(at.min(second.len() - 2)).find(|(_, c)| c.is_ascii_digit());
            let (i, c) = digit.unwrap();
            second.replace_range(i..i + 1, if c == '9' { "8" } else { "9" });
            format!("{}\n{second}\n{}\n", lines[0], lines[2])
        });
        assert_eq!(e.line, Some(2));
        // Block 1's record under index 2 (a block copied under another index).
        let e = edited("moved", |t| {
            let last = t.lines().nth(2).unwrap();
            format!("{t}{}\n", last.replace("{\"block\":1,", "{\"block\":2,"))
        });
        assert_eq!(e.line, Some(4));
        assert!(e.to_string().contains("does not match"), "{e}");
        // A line of another run's checkpoint (another seed) pasted in: its sum covers its header.
        let e = edited("pasted", |t| {
            let other = Header::new(b"scene", 8, 200, 64);
            let mut bytes = t.as_bytes().to_vec();
            line(&mut bytes, &other.text(), &Line::Block { block: 3, outcome: outcome(3) });
            String::from_utf8(bytes).unwrap()
        });
        assert_eq!(e.line, Some(4));
    }

    #[test]
    fn a_resume_with_the_other_lane_setting_is_refused_naming_both() {
        let path = dir("lanes");
        let header = Header::new(b"scene", 7, 200, 64);
        Checkpoint::create(&path, &header).unwrap();
        let other = header.clone().with_lanes(false);
        let e = Checkpoint::resume(&path, &other, limit(&other)).err().unwrap();
        assert_eq!(e.line, Some(1));
        let shown = e.to_string();
        assert!(
            shown.contains("SIMD lanes (the default)")
                && shown.contains("one at a time (`--no-lanes`, `EnsembleOptions::lanes = false`)"),
            "{shown}"
        );
        assert!(shown.contains("resume on lanes (without `--no-lanes`)"), "{shown}");
        let path = dir("no-lanes");
        Checkpoint::create(&path, &other).unwrap();
        let e = Checkpoint::resume(&path, &header, limit(&header)).err().unwrap();
        assert!(e.to_string().contains("resume one at a time (`--no-lanes`"), "{e}");
        assert!(Checkpoint::resume(&path, &other, limit(&other)).is_ok());
    }

    #[test]
    fn scene_hash_is_fnv1a() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(scene_hash(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(scene_hash(b"a"), 0xaf63_dc4c_8601_ec8c);
    }
}
