//! Fixed-range histograms with counts of the values below, above and not a number.

use serde::{Deserialize, Serialize};

/// Counts of values in `bins` equal bins over `[low, high]`; values outside are counted apart.
///
/// Bin `i` is `[low + i·w, low + (i+1)·w)` with `w = (high − low)/bins`; `high` itself falls in
/// the last bin. Merging adds counts, which is exact and independent of the order.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Histogram {
    low: u64,
    high: u64,
    counts: Vec<u64>,
    below: u64,
    above: u64,
    not_a_number: u64,
}

/// Why a histogram cannot be made or merged.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HistogramError {
    /// No bins, or a range that is empty or not finite.
    #[error(
        "a histogram needs at least one bin and a finite range with low < high (got {bins} bins over [{low}, {high}])"
    )]
    Shape {
        /// Bins asked for.
        bins: usize,
        /// Lower end.
        low: f64,
        /// Upper end.
        high: f64,
    },
    /// Histograms of different shapes cannot be merged.
    #[error("cannot merge histograms of different bins or ranges")]
    Mismatch,
}

impl Histogram {
    /// `bins` empty bins over `[low, high]`.
    pub fn new(bins: usize, low: f64, high: f64) -> Result<Self, HistogramError> {
        if bins == 0 || !(low.is_finite() && high.is_finite() && low < high) {
            return Err(HistogramError::Shape { bins, low, high });
        }
        // The ends are stored as bits so that the type can be `Eq` (shapes compare exactly).
        Ok(Self {
            low: low.to_bits(),
            high: high.to_bits(),
            counts: vec![0; bins],
            below: 0,
            above: 0,
            not_a_number: 0,
        })
    }

    /// The lower end of the range.
    pub fn low(&self) -> f64 {
        f64::from_bits(self.low)
    }

    /// The upper end of the range.
    pub fn high(&self) -> f64 {
        f64::from_bits(self.high)
    }

    /// The width of a bin.
    pub fn width(&self) -> f64 {
        (self.high() - self.low()) / self.counts.len() as f64
    }

    /// Counts one value.
    #[inline]
    pub fn add(&mut self, x: f64) {
        let (low, high) = (self.low(), self.high());
        if x.is_nan() {
            self.not_a_number += 1;
        } else if x < low {
            self.below += 1;
        } else if x > high {
            self.above += 1;
        } else {
            let bins = self.counts.len();
            let i = (((x - low) / (high - low)) * bins as f64) as usize;
            self.counts[i.min(bins - 1)] += 1;
        }
    }

    /// Adds the counts of `other`, which must have the same bins.
    pub fn merge(&mut self, other: &Histogram) -> Result<(), HistogramError> {
        if self.low != other.low || self.high != other.high || self.counts.len() != other.counts.len() {
            return Err(HistogramError::Mismatch);
        }
        for (a, b) in self.counts.iter_mut().zip(&other.counts) {
            *a += b;
        }
        self.below += other.below;
        self.above += other.above;
        self.not_a_number += other.not_a_number;
        Ok(())
    }

    /// Counts per bin.
    pub fn counts(&self) -> &[u64] {
        &self.counts
    }

    /// Values below the range.
    pub fn below(&self) -> u64 {
        self.below
    }

    /// Values above the range.
    pub fn above(&self) -> u64 {
        self.above
    }

    /// Values that were NaN.
    pub fn not_a_number(&self) -> u64 {
        self.not_a_number
    }

    /// Every value counted, in range or not.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum::<u64>() + self.below + self.above + self.not_a_number
    }

    /// Probability density of bin `i`: its count over (all values counted × bin width), so the
    /// densities integrate to the fraction of values inside the range.
    pub fn density(&self, i: usize) -> f64 {
        self.counts[i] as f64 / (self.total() as f64 * self.width())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bins_edges_and_outside_values() {
        let mut h = Histogram::new(4, 0.0, 2.0).unwrap();
        for x in [0.0, 0.49, 0.5, 1.2, 1.99, 2.0, -0.1, 2.1, f64::NAN] {
            h.add(x);
        }
        assert_eq!(h.counts(), &[2, 1, 1, 2]);
        assert_eq!((h.below(), h.above(), h.not_a_number(), h.total()), (1, 1, 1, 9));
        assert_eq!(h.width(), 0.5);
        let integral: f64 = (0..4).map(|i| h.density(i) * h.width()).sum();
        assert!((integral - 6.0 / 9.0).abs() < 1e-15);
    }

    #[test]
    fn merging_adds_counts_and_refuses_other_shapes() {
        let xs: Vec<f64> = (0..500).map(|i| ((i * 37) % 113) as f64 / 50.0 - 0.1).collect();
        let mut whole = Histogram::new(7, 0.0, 2.0).unwrap();
        xs.iter().for_each(|&x| whole.add(x));
        let mut merged = Histogram::new(7, 0.0, 2.0).unwrap();
        for chunk in xs.chunks(64).rev() {
            let mut h = Histogram::new(7, 0.0, 2.0).unwrap();
            chunk.iter().for_each(|&x| h.add(x));
            merged.merge(&h).unwrap();
        }
        assert_eq!(merged, whole);
        assert_eq!(merged.merge(&Histogram::new(6, 0.0, 2.0).unwrap()), Err(HistogramError::Mismatch));
        assert!(matches!(Histogram::new(0, 0.0, 1.0), Err(HistogramError::Shape { .. })));
        assert!(matches!(Histogram::new(3, 1.0, 1.0), Err(HistogramError::Shape { .. })));
        assert!(matches!(Histogram::new(3, 0.0, f64::INFINITY), Err(HistogramError::Shape { .. })));
    }
}
