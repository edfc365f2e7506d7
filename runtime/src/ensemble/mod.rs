//! Mergeable accumulators for ensemble statistics: means and variances, histograms,
//! time-correlation functions and lifetimes, folded one trajectory at a time and merged block by block.
//!
//! An ensemble of millions of trajectories keeps no histories: each finished trajectory is
//! folded into accumulators of fixed size, and the accumulators of blocks of trajectories are
//! merged. Every accumulator is plain data (serde), so blocks computed on other threads,
//! processes or machines can be shipped and merged. Merging in a fixed order (block index
//! order) makes the result bit-identical whatever ran where and when.

mod correlation;
mod histogram;
mod lifetimes;
mod moments;

pub use correlation::{CorrelationWorkspace, autocorrelation_direct};
pub use histogram::{Histogram, HistogramError};
pub use lifetimes::{Lifetimes, LifetimesError, Side};
pub use moments::Moments;
