//! Who runs which block, and how finished blocks become the ensemble's outcome.
//!
//! The blocks still to run are handed out in index order by one [`Dispatcher`], on demand: to
//! this process's worker threads one block at a time, and to other processes (MPI ranks, through
//! a [`Remote`]) a few at a time as they ask. Blocks finish in any order; the [`Collector`]
//! records each in the checkpoint, keeps it until every block before it has arrived, and merges
//! the outcomes strictly in block order (0, 1, 2, …) into one running total. The merge order, and
//! so every bit of the statistics, is therefore independent of the number of threads and
//! processes and of which of them ran which block.

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::checkpoint::{Checkpoint, CheckpointError, Header, Identity, Resumed};
use super::runner::{BLOCK, MergeError, Outcome, Tally};

/// A block's outcome, or the panic that ended it.
pub type BlockResult = Result<Outcome, BlockPanic>;

/// A block that has no outcome: one of its trajectories panicked.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
#[error("a trajectory of block {block} (trajectories {}..{}) panicked: {message}", trajectories.start, trajectories.end)]
pub struct BlockPanic {
    /// The block.
    pub block: u64,
    /// Its trajectory indices.
    pub trajectories: Range<u64>,
    /// The panic's message.
    pub message: String,
}

/// Why an ensemble's run of blocks failed (the first failure is reported).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RunError {
    /// A trajectory panicked.
    #[error(transparent)]
    Panicked(#[from] BlockPanic),
    /// A block's outcome does not merge into the total (another run's layout).
    #[error("block {block} cannot be merged: {source}")]
    Merge {
        /// The block.
        block: u64,
        /// What differs.
        source: MergeError,
    },
    /// The checkpoint cannot be written.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// Another process (an MPI rank) failed, or its messages could not be read.
    #[error("{0}")]
    Remote(String),
}

/// Blocks recorded in the checkpoint between two compactions of it.
pub const COMPACT_EVERY: usize = 256;

/// The trajectory indices of block `b` of an ensemble of `n` trajectories.
pub fn block_range(b: u64, n: u64) -> Range<u64> {
    b * BLOCK..((b + 1) * BLOCK).min(n)
}

/// Runs block `block` with `run`, turning a panic into an error naming the block.
pub fn caught(block: u64, n: u64, run: impl FnOnce() -> Outcome) -> BlockResult {
    catch_unwind(AssertUnwindSafe(run)).map_err(|payload| {
        let message = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic without a message".to_owned());
        BlockPanic { block, trajectories: block_range(block, n), message }
    })
}

/// The blocks still to run, handed out in index order. They are produced as handed out, never
/// listed up front: an ensemble of 10¹² trajectories has 1.6·10¹⁰ blocks.
pub struct Dispatcher {
    todo: Box<dyn Iterator<Item = u64> + Send>,
    closed: bool,
}

impl Dispatcher {
    /// Hands out `todo` in the order given.
    pub fn new(todo: impl IntoIterator<Item = u64, IntoIter: Send + 'static>) -> Self {
        Self { todo: Box::new(todo.into_iter()), closed: false }
    }

    /// Up to `n` blocks; none once closed, once `stop` is set, or when all were handed out.
    pub fn take(&mut self, n: usize, stop: &AtomicBool) -> Vec<u64> {
        if self.closed || stop.load(Ordering::Relaxed) {
            return Vec::new();
        }
        self.todo.by_ref().take(n).collect()
    }

    /// No more blocks are handed out (an error: the blocks running finish and are recorded).
    pub fn close(&mut self) {
        self.closed = true;
    }
}

/// Other processes that run blocks (MPI ranks 1 … K−1); the coordinator polls them.
pub trait Remote {
    /// Handles what the other processes sent, without waiting: every finished block goes to
    /// `sink(rank, block, result)`, every request for work is answered from `dispatcher` (an
    /// empty answer, as once `stop` is set, tells that process to end). Returns whether anything arrived; an error is a
    /// failure of the run (the link stays usable so the other processes can be released).
    fn poll(
        &mut self,
        dispatcher: &Mutex<Dispatcher>,
        stop: &AtomicBool,
        sink: &mut dyn FnMut(usize, u64, BlockResult),
    ) -> Result<bool, String>;

    /// Whether every other process has been told to end.
    fn finished(&self) -> bool;

    /// The run this process coordinates: the blocks of a process whose run differs (another
    /// scene, seed, N, lane setting or statistics layout) are refused, never merged.
    fn expect(&mut self, identity: Identity);

    /// Processes in all, this one included.
    fn ranks(&self) -> usize;
}

/// The receiving end of the blocks: checkpoint, reorder buffer and the running total.
pub struct Collector {
    n: u64,
    n_blocks: u64,
    next: u64,
    total: Outcome,
    pending: BTreeMap<u64, Outcome>,
    batch: Vec<(u64, Outcome)>,
    checkpoint: Option<(Checkpoint, Header)>,
    since_compaction: usize,
    tainted: bool,
    error: Option<RunError>,
    by_rank: Vec<u64>,
    resumed: u64,
}

impl Collector {
    /// Collects the `n` trajectories' blocks into `empty` (the statistics of no trajectory),
    /// starting from what a checkpoint held, recording new blocks in `checkpoint`; `ranks`
    /// processes report blocks.
    pub fn new(
        n: u64,
        empty: Outcome,
        resumed: Resumed,
        checkpoint: Option<(Checkpoint, Header)>,
        ranks: usize,
    ) -> Self {
        let (next, total) = resumed.merged.unwrap_or((0, empty));
        let finished = |o: &Outcome| o.completed + o.failed_count();
        let done = finished(&total) + resumed.blocks.values().map(finished).sum::<u64>();
        let mut c = Self {
            n,
            n_blocks: n.div_ceil(BLOCK),
            next,
            total,
            pending: resumed.blocks,
            batch: Vec::new(),
            checkpoint,
            since_compaction: 0,
            tainted: false,
            error: None,
            by_rank: vec![0; ranks.max(1)],
            resumed: done,
        };
        c.advance();
        c
    }

    /// The blocks that still have to run, in index order (produced lazily).
    pub fn todo(&self) -> impl Iterator<Item = u64> + Send + 'static {
        let done: BTreeSet<u64> = self.pending.keys().copied().collect();
        (self.next..self.n_blocks).filter(move |b| !done.contains(b))
    }

    /// Trajectories (completed or failed) taken from the checkpoint.
    pub fn resumed(&self) -> u64 {
        self.resumed
    }

    /// Block `block` arrived from process `rank`.
    pub fn add(&mut self, rank: usize, block: u64, result: BlockResult) {
        match result {
            Ok(o) => {
                if let Some(c) = self.by_rank.get_mut(rank) {
                    *c += 1;
                }
                self.batch.push((block, o));
            }
            Err(panic) => self.fail(panic),
        }
    }

    /// Records a failure of the run (the first one is reported).
    pub fn fail(&mut self, error: impl Into<RunError>) {
        self.error.get_or_insert(error.into());
    }

    /// The failure of the run, if any.
    pub fn error(&self) -> Option<&RunError> {
        self.error.as_ref()
    }

    /// Whether a block cut short by an interrupt arrived.
    pub fn interrupted(&self) -> bool {
        self.tainted
    }

    /// Records the blocks that arrived since the last call in the checkpoint (one write, one
    /// sync; blocks cut short by an interrupt are not recorded, they run again on resume), then
    /// merges every block whose predecessors are all in, and compacts the checkpoint every
    /// [`COMPACT_EVERY`] blocks.
    pub fn flush(&mut self) -> Result<(), CheckpointError> {
        if self.batch.is_empty() {
            return Ok(());
        }
        if let Some((c, _)) = &mut self.checkpoint {
            let records: Vec<(u64, &Outcome)> =
                self.batch.iter().filter(|(_, o)| o.interrupted == 0).map(|(b, o)| (*b, o)).collect();
            if !records.is_empty() {
                c.append_all(&records)?;
                self.since_compaction += records.len();
            }
        }
        for (b, o) in self.batch.drain(..) {
            self.tainted |= o.interrupted > 0;
            self.pending.insert(b, o);
        }
        self.advance();
        if let Some((c, header)) = &mut self.checkpoint
            && self.since_compaction >= COMPACT_EVERY
            && !self.tainted
        {
            c.compact(header, self.next, &self.total, &self.pending)?;
            self.since_compaction = 0;
        }
        Ok(())
    }

    fn advance(&mut self) {
        if self.error.is_some() {
            return;
        }
        while let Some(o) = self.pending.remove(&self.next) {
            if let Err(source) = self.total.merge(&o) {
                self.fail(RunError::Merge { block: self.next, source });
                return;
            }
            self.next += 1;
        }
    }

    /// The ensemble's outcome: every block in block order; blocks that never ran (an
    /// interrupt) count as interrupted. Also the blocks each process ran, and the checkpoint.
    pub fn finish(mut self) -> Result<(Outcome, Vec<u64>, Option<Checkpoint>), RunError> {
        for b in self.next..self.n_blocks {
            match self.pending.remove(&b) {
                Some(o) => self.total.merge(&o).map_err(|source| RunError::Merge { block: b, source })?,
                None => {
                    let r = block_range(b, self.n);
                    self.total.interrupted += r.end - r.start;
                }
            }
        }
        Ok((self.total, self.by_rank, self.checkpoint.map(|(c, _)| c)))
    }
}

/// What this process's worker threads run.
pub struct Work<'a> {
    /// Worker threads.
    pub threads: usize,
    /// Their pool.
    pub pool: &'a rayon::ThreadPool,
    /// Runs one block (never panics: a panic becomes an error).
    pub run: &'a (dyn Fn(u64) -> BlockResult + Sync),
    /// Set by Ctrl-C or SIGTERM (or by a block that came back interrupted): no block starts.
    pub stop: &'a AtomicBool,
    /// The live counts, advanced for blocks other processes ran.
    pub progress: &'a Tally,
}

/// The longest wait between two calls of `coordinate`'s `report`.
pub const REPORT_EVERY: Duration = Duration::from_millis(100);

/// Runs the collector's remaining blocks on this process's threads and on `remote`'s processes
/// until all are in (or the stop flag or an error ends the run), flushing the collector as
/// blocks arrive. On an error (a panicking trajectory, a checkpoint that cannot be written, a
/// process that could not start) no new block starts, the running ones finish and are recorded,
/// and the first error is returned. `report` runs on this thread after each round of arrivals
/// and at least every [`REPORT_EVERY`] (for a progress callback, which may set the stop flag).
pub fn coordinate(
    work: &Work<'_>,
    collector: &mut Collector,
    mut remote: Option<&mut dyn Remote>,
    report: &mut dyn FnMut(),
) -> Result<(), RunError> {
    let dispatcher = Mutex::new(Dispatcher::new(collector.todo()));
    let lock = || dispatcher.lock().unwrap_or_else(PoisonError::into_inner);
    let (tx, rx) = mpsc::channel::<(u64, BlockResult)>();
    std::thread::scope(|scope| {
        let d = &dispatcher;
        scope.spawn(move || {
            work.pool.scope(|s| {
                for _ in 0..work.threads {
                    let tx = tx.clone();
                    s.spawn(move |_| {
                        loop {
                            let next = d.lock().unwrap_or_else(PoisonError::into_inner).take(1, work.stop).pop();
                            let Some(b) = next else { break };
                            if tx.send((b, (work.run)(b))).is_err() {
                                break;
                            }
                        }
                    });
                }
            });
            drop(tx);
        });
        let mut local_done = false;
        loop {
            let mut busy = false;
            if let Some(r) = remote.as_deref_mut() {
                let mut sink = |rank: usize, b: u64, result: BlockResult| {
                    if let Ok(o) = &result {
                        work.progress.remote_block(o);
                    }
                    collector.add(rank, b, result);
                };
                match r.poll(d, work.stop, &mut sink) {
                    Ok(any) => busy |= any,
                    Err(e) => collector.fail(RunError::Remote(e)),
                }
            }
            if !local_done {
                let wait = if remote.is_some() { Duration::from_millis(1) } else { REPORT_EVERY };
                let first = rx.recv_timeout(wait);
                match first {
                    Ok((b, result)) => {
                        collector.add(0, b, result);
                        while let Ok((b, result)) = rx.try_recv() {
                            collector.add(0, b, result);
                        }
                    }
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => local_done = true,
                }
            } else if !busy {
                std::thread::sleep(Duration::from_millis(1));
            }
            if let Err(e) = collector.flush() {
                collector.fail(e);
            }
            report();
            if collector.interrupted() {
                // A process was stopped (SIGTERM on its node): the whole run stops.
                work.stop.store(true, Ordering::Relaxed);
            }
            if collector.error().is_some() {
                lock().close();
            }
            if local_done && remote.as_deref().is_none_or(|r| r.finished()) {
                break;
            }
        }
    });
    match collector.error() {
        Some(e) => Err(e.clone()),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ensemble::runner::Accumulators;
    use crate::runtime::ensemble::Moments;

    fn outcome(b: u64) -> Outcome {
        let mut m = Moments::new();
        for k in 0..3 {
            m.add(((b * 13 + k) as f64).sqrt() * 0.1);
        }
        let statistics =
            Accumulators { n_times: 1, n_means: 1, means: vec![m], histograms: Vec::new(), correlations: Vec::new() };
        let mut o = Outcome::new(statistics);
        o.completed = 3;
        o
    }

    fn empty() -> Outcome {
        let statistics = Accumulators {
            n_times: 1,
            n_means: 1,
            means: vec![Moments::new()],
            histograms: Vec::new(),
            correlations: Vec::new(),
        };
        Outcome::new(statistics)
    }

    /// A block of another layout (another scene's histogram shape) fails the run with what
    /// differs; it neither panics nor is merged.
    #[test]
    fn a_block_of_another_layout_is_an_error_not_a_panic() {
        use crate::runtime::ensemble::Histogram;
        let with = |bins: usize| {
            let mut o = empty();
            o.statistics.histograms = vec![Histogram::new(bins, 0.0, 1.0).unwrap()];
            o
        };
        let mut c = Collector::new(2 * BLOCK, with(20), Resumed::default(), None, 1);
        c.add(0, 0, Ok(with(30)));
        c.flush().unwrap();
        let e = c.error().expect("a block of another layout must fail the run").to_string();
        assert!(e.contains("block 0 cannot be merged") && e.contains("histogram 0"), "{e}");
        let mut a = with(20);
        assert!(a.merge(&outcome(0)).is_err());
        assert_eq!(a, with(20), "nothing is merged from accumulators of another layout");
    }

    #[test]
    fn blocks_arriving_in_any_order_merge_in_block_order() {
        let n = 10 * BLOCK;
        let mut in_order = empty();
        for b in 0..10 {
            in_order.merge(&outcome(b)).unwrap();
        }
        let mut c = Collector::new(n, empty(), Resumed::default(), None, 3);
        for (i, b) in [3, 1, 0, 9, 2, 4, 8, 5, 7, 6].into_iter().enumerate() {
            c.add(i % 3, b, Ok(outcome(b)));
            c.flush().unwrap();
        }
        let (total, by_rank, _) = c.finish().unwrap();
        assert_eq!(by_rank, vec![4, 3, 3]);
        // Bit for bit: the merge order is the block order, not the arrival order.
        assert_eq!(total, in_order);
        // A different order of merging does change the last bits (so the check above can fail).
        let mut reversed = empty();
        for b in (0..10).rev() {
            reversed.merge(&outcome(b)).unwrap();
        }
        assert_ne!(reversed.statistics, in_order.statistics);
    }

    #[test]
    fn a_missing_block_counts_as_interrupted_and_a_panic_is_named() {
        let n = 3 * BLOCK - 5;
        let mut c = Collector::new(n, empty(), Resumed::default(), None, 1);
        c.add(0, 0, Ok(outcome(0)));
        let e = caught(1, n, || panic!("boom"));
        c.add(0, 1, e);
        c.flush().unwrap();
        assert_eq!(
            c.error().map(ToString::to_string).as_deref(),
            Some("a trajectory of block 1 (trajectories 64..128) panicked: boom")
        );
        let (total, _, _) = c.finish().unwrap();
        assert_eq!(total.completed, 3);
        assert_eq!(total.interrupted, n - 64);
    }

    /// The path the integration tests do not reach (they stop before [`COMPACT_EVERY`] blocks):
    /// blocks arriving out of order through a compaction of the checkpoint, the run killed (the
    /// collector dropped with a block still out of order), resumed from the compacted file, and
    /// the rest arriving in reverse order. The resumed collector must run exactly the blocks
    /// never recorded and end with the bits of the in-order merge. (Shown able to fail: with the
    /// compaction recording one block fewer as merged than it merged, which a resume would run
    /// and count again, this test fails at the compacted file's `merged` count; with a resume
    /// that skips a block, at `todo`; docs/src/history/benchmarks.md, "Ensembles over MPI".)
    #[test]
    fn a_run_killed_after_a_compaction_resumes_to_the_bits_of_the_in_order_merge() {
        use super::super::checkpoint::{Checkpoint, Header};
        let n_blocks = COMPACT_EVERY as u64 + 60;
        let n = n_blocks * BLOCK - 7;
        let mut in_order = empty();
        for b in 0..n_blocks {
            in_order.merge(&outcome(b)).unwrap();
        }
        // The same directory on every run (removed first), so that runs do not pile up in /tmp.
        let dir = std::env::temp_dir().join("rovib-schedule-compaction");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("checkpoint.jsonl");
        let header = Header::new(b"scene", 1, n, BLOCK);
        let checkpoint = Checkpoint::create(&path, &header).unwrap();
        let mut c = Collector::new(n, empty(), Resumed::default(), Some((checkpoint, header.clone())), 2);
        // Neighbours swapped (1, 0, 3, 2, …), seven per flush: the compaction (after the flush
        // that passes COMPACT_EVERY records, 259) leaves block 259 out of order, and so does
        // the kill after 287 arrivals (block 287 in, 286 not).
        let order: Vec<u64> = (0..n_blocks).map(|i| i ^ 1).collect();
        let cut = COMPACT_EVERY + 31;
        for chunk in order[..cut].chunks(7) {
            for &b in chunk {
                c.add((b % 2) as usize, b, Ok(outcome(b)));
            }
            c.flush().unwrap();
        }
        drop(c);
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.lines().count() < 40, "the checkpoint was not compacted: {} lines", text.lines().count());
        assert!(text.lines().nth(1).unwrap().contains(",\"record\":{\"merged\":258,"), "{}", &text[..200]);

        let (checkpoint, resumed) =
            Checkpoint::resume(&path, &header, crate::ensemble::checkpoint::size_limit(&header, &empty())).unwrap();
        let mut c = Collector::new(n, empty(), resumed, Some((checkpoint, header)), 1);
        assert_eq!(c.resumed(), 3 * cut as u64);
        let mut never_recorded = order[cut..].to_vec();
        never_recorded.sort_unstable();
        assert_eq!(c.todo().collect::<Vec<_>>(), never_recorded);
        for &b in never_recorded.iter().rev() {
            c.add(0, b, Ok(outcome(b)));
            c.flush().unwrap();
        }
        let (total, _, _) = c.finish().unwrap();
        assert_eq!(total, in_order);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// 10¹² trajectories are 1.6·10¹⁰ blocks: the collector and the dispatcher produce them as
    /// handed out (listing them up front, as once, needs 125 GB and the process is killed).
    #[test]
    fn a_huge_ensemble_hands_out_its_blocks_without_listing_them() {
        let n = 1_000_000_000_000;
        let c = Collector::new(n, empty(), Resumed::default(), None, 1);
        let stop = AtomicBool::new(false);
        let mut d = Dispatcher::new(c.todo());
        assert_eq!(d.take(3, &stop), vec![0, 1, 2]);
        assert_eq!(d.take(1, &stop), vec![3]);
    }

    #[test]
    fn the_dispatcher_hands_out_in_order_until_closed_or_stopped() {
        let stop = AtomicBool::new(false);
        let mut d = Dispatcher::new([1, 2, 5, 6]);
        assert_eq!(d.take(3, &stop), vec![1, 2, 5]);
        stop.store(true, Ordering::Relaxed);
        assert!(d.take(1, &stop).is_empty());
        stop.store(false, Ordering::Relaxed);
        d.close();
        assert!(d.take(1, &stop).is_empty());
    }

    #[test]
    fn run_errors_say_what_failed() {
        let panic = BlockPanic { block: 2, trajectories: 128..150, message: "boom".into() };
        assert_eq!(panic.to_string(), "a trajectory of block 2 (trajectories 128..150) panicked: boom");
        assert_eq!(RunError::from(panic.clone()).to_string(), panic.to_string());
        let merge = RunError::Merge { block: 3, source: MergeError::HistogramCount { theirs: 1, mine: 2 } };
        assert_eq!(merge.to_string(), "block 3 cannot be merged: statistics of another layout: 1 histograms against 2");
        let remote = RunError::Remote("rank 1 could not start: no scene".into());
        assert_eq!(remote.to_string(), "rank 1 could not start: no scene");
        let checkpoint = CheckpointError { path: "c.jsonl".into(), line: Some(2), message: "cut".into() };
        assert_eq!(RunError::from(checkpoint).to_string(), "c.jsonl:2: cut");
    }
}
