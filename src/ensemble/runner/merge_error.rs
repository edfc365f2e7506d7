//! Why two outcomes cannot be merged: they are of different runs (another scene's statistics
//! layout, another run's stop counts), read from a process or a checkpoint.

use crate::runtime::ensemble::{HistogramError, LifetimesError};

/// The shape of a run's statistics: (output times, means per time, means, lags of each
/// correlation).
pub type StatisticsShape = (usize, usize, usize, Vec<usize>);

/// The (bins, low, high) of a histogram.
pub type HistogramShape = (usize, f64, f64);

/// Why outcomes or accumulators cannot be merged; nothing was merged.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MergeError {
    /// Another number of output times, means or correlation lags.
    #[error(
        "statistics of another layout: (output times, means per time, means, correlation lags) {theirs:?} against {mine:?}"
    )]
    Shape {
        /// The shape of the statistics merged in.
        theirs: StatisticsShape,
        /// The shape of those merged into.
        mine: StatisticsShape,
    },
    /// Another number of histograms.
    #[error("statistics of another layout: {theirs} histograms against {mine}")]
    HistogramCount {
        /// Histograms of the statistics merged in.
        theirs: usize,
        /// Histograms of those merged into.
        mine: usize,
    },
    /// A histogram of other bins or range.
    #[error("statistics of another layout: histogram {index} has (bins, low, high) {theirs:?} against {mine:?}")]
    Histogram {
        /// Which histogram.
        index: usize,
        /// Its shape in the statistics merged in.
        theirs: HistogramShape,
        /// Its shape in those merged into.
        mine: HistogramShape,
    },
    /// Histograms that do not merge.
    #[error(transparent)]
    HistogramMerge(#[from] HistogramError),
    /// Stop counts of another shape.
    #[error(transparent)]
    Lifetimes(#[from] LifetimesError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_both_layouts() {
        let shape = MergeError::Shape { theirs: (3, 2, 6, vec![4]), mine: (5, 2, 10, vec![]) };
        assert_eq!(
            shape.to_string(),
            "statistics of another layout: (output times, means per time, means, correlation lags) (3, 2, 6, [4]) \
             against (5, 2, 10, [])"
        );
        let count = MergeError::HistogramCount { theirs: 1, mine: 2 };
        assert_eq!(count.to_string(), "statistics of another layout: 1 histograms against 2");
        let histogram = MergeError::Histogram { index: 0, theirs: (10, 0.0, 1.0), mine: (20, 0.0, 1.5) };
        assert_eq!(
            histogram.to_string(),
            "statistics of another layout: histogram 0 has (bins, low, high) (10, 0.0, 1.0) against (20, 0.0, 1.5)"
        );
        assert_eq!(
            MergeError::from(HistogramError::Mismatch).to_string(),
            "cannot merge histograms of different bins or ranges"
        );
        let lifetimes = LifetimesError::Layout { times: 4, conditions: 2, own_times: 5, own_conditions: 2 };
        assert_eq!(MergeError::from(lifetimes.clone()).to_string(), lifetimes.to_string());
    }
}
