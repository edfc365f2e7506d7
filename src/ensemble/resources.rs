//! What an ensemble will hold in memory and write to disk, estimated from the scene before the
//! first trajectory, and the caps it must stay below (`ensemble.max_memory_gb`,
//! `ensemble.max_disk_gb`).
//!
//! Memory: every block in flight (one per thread, plus the running total and a few waiting to
//! be merged) holds a full set of accumulators: 24 bytes per mean and correlation value and
//! 8 bytes per histogram bin, per output time; each thread also buffers its trajectory's
//! observations. Disk: the checkpoint holds up to [`CHECKPOINT_LINES`] block lines of the
//! accumulators as JSON (about 3 bytes per histogram bin, 60 per mean), histograms.csv about
//! 40 bytes per bin and time, ensemble.csv and correlations.csv 50 bytes per value, and every
//! kept trajectory about 25 bytes per number of its rows.

use super::schedule::COMPACT_EVERY;

/// The default cap on the estimated memory, GB (10⁹ bytes).
pub const DEFAULT_MAX_MEMORY_GB: f64 = 4.0;

/// The default cap on the estimated disk use, GB.
pub const DEFAULT_MAX_DISK_GB: f64 = 20.0;

/// Block lines the checkpoint holds at most between two compactions (and the merged line).
pub const CHECKPOINT_LINES: u64 = COMPACT_EVERY as u64 + 2;

/// The shape of an ensemble's work and statistics.
#[derive(Clone, Debug)]
pub struct Shape {
    /// Trajectories.
    pub trajectories: u64,
    /// Blocks.
    pub blocks: u64,
    /// Worker threads.
    pub threads: usize,
    /// Output times.
    pub times: usize,
    /// Quantities observed (means, histogrammed, correlated).
    pub quantities: usize,
    /// Quantities with means.
    pub means: usize,
    /// Correlated quantities.
    pub correlations: usize,
    /// Histogram bins summed over histograms and their times.
    pub histogram_bins: u64,
    /// Numbers per row of a kept trajectory file.
    pub row_numbers: usize,
    /// Every k-th trajectory kept.
    pub keep: Option<u64>,
}

/// Bytes of memory and of disk, estimated.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Estimate {
    /// Memory, bytes.
    pub memory: f64,
    /// Disk, bytes.
    pub disk: f64,
    /// Of which the kept trajectories, bytes.
    pub kept: f64,
}

impl Shape {
    /// The estimate (floating point: the figures can exceed u64).
    pub fn estimate(&self) -> Estimate {
        let times = self.times as f64;
        let values = times * (self.means + self.correlations) as f64;
        let bins = self.histogram_bins as f64;
        let accumulators = 24.0 * values + 8.0 * bins;
        let in_flight = (self.threads as f64 + 4.0).min(self.blocks as f64 + 1.0);
        let buffers = self.threads as f64 * times * (self.quantities as f64 + 4.0) * 8.0;
        let memory = accumulators * in_flight + buffers;
        let line = 3.0 * bins + 60.0 * values;
        let checkpoint = line * (self.blocks.min(CHECKPOINT_LINES) as f64);
        let tables = 40.0 * bins + 50.0 * values;
        let kept = match self.keep {
            Some(k) => self.trajectories.div_ceil(k) as f64 * times * self.row_numbers as f64 * 25.0,
            None => 0.0,
        };
        Estimate { memory, disk: checkpoint + tables + kept, kept }
    }
}

/// `bytes` as GB with three significant digits.
pub fn gb(bytes: f64) -> String {
    format!("{:.3} GB", bytes / 1e9)
}
