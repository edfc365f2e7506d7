//! Running mean and variance (Welford) with the pairwise merge of Chan, Golub and LeVeque.

use serde::{Deserialize, Serialize};

/// Count, mean and sum of squared deviations of a stream of numbers.
///
/// [`Moments::add`] is Welford's update, stable for long streams; [`Moments::merge`] is Chan's
/// parallel formula. Both are deterministic: the same values added and merged in the same order
/// give the same bits, which is what makes an ensemble independent of the thread count when
/// blocks are merged in a fixed order.
#[derive(Copy, Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Moments {
    count: u64,
    mean: f64,
    /// Σ (x − mean)².
    m2: f64,
}

impl Moments {
    /// No values yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one value.
    #[inline]
    pub fn add(&mut self, x: f64) {
        self.count += 1;
        let delta = x - self.mean;
        self.mean += delta / self.count as f64;
        self.m2 += delta * (x - self.mean);
    }

    /// Merges the values of `other` in, as if they had been added after this one's.
    pub fn merge(&mut self, other: &Moments) {
        if other.count == 0 {
            return;
        }
        if self.count == 0 {
            *self = *other;
            return;
        }
        let (na, nb) = (self.count as f64, other.count as f64);
        let n = na + nb;
        let delta = other.mean - self.mean;
        self.mean += delta * (nb / n);
        self.m2 += other.m2 + delta * delta * (na * nb / n);
        self.count += other.count;
    }

    /// How many values were added.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Their mean (NaN for none).
    pub fn mean(&self) -> f64 {
        if self.count == 0 { f64::NAN } else { self.mean }
    }

    /// The unbiased sample variance Σ(x − x̄)²/(n − 1) (NaN for fewer than two values).
    pub fn variance(&self) -> f64 {
        if self.count < 2 { f64::NAN } else { self.m2 / (self.count - 1) as f64 }
    }

    /// The standard error of the mean, √(variance / n) (NaN for fewer than two values).
    pub fn standard_error(&self) -> f64 {
        (self.variance() / self.count as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values of very different size about a large offset: a naive Σx² − n x̄² loses them.
    fn values(n: usize) -> Vec<f64> {
        (0..n).map(|i| 1e6 + ((i * 7919) % 101) as f64 * 0.37 - (i % 3) as f64 * 1e-3).collect()
    }

    fn two_pass(x: &[f64]) -> (f64, f64) {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (x.len() - 1) as f64;
        (mean, var)
    }

    #[test]
    fn welford_matches_the_two_pass_formulas() {
        let x = values(1000);
        let mut m = Moments::new();
        x.iter().for_each(|&v| m.add(v));
        let (mean, var) = two_pass(&x);
        assert_eq!(m.count(), 1000);
        assert!((m.mean() - mean).abs() <= 1e-15 * mean, "{} vs {mean}", m.mean());
        assert!((m.variance() - var).abs() <= 1e-10 * var, "{} vs {var}", m.variance());
        assert!((m.standard_error() - (var / 1000.0).sqrt()).abs() <= 1e-10 * (var / 1000.0).sqrt());
    }

    #[test]
    fn exact_small_cases() {
        let mut m = Moments::new();
        assert!(m.mean().is_nan() && m.variance().is_nan());
        for v in [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0] {
            m.add(v);
        }
        // Mean 5, Σ(x − 5)² = 32, sample variance 32/7.
        assert_eq!(m.mean(), 5.0);
        assert!((m.variance() - 32.0 / 7.0).abs() < 1e-15);
    }

    #[test]
    fn merged_blocks_agree_with_one_stream_and_with_each_other() {
        let x = values(1000);
        let mut whole = Moments::new();
        x.iter().for_each(|&v| whole.add(v));
        let blocks: Vec<Moments> = x
            .chunks(64)
            .map(|c| {
                let mut m = Moments::new();
                c.iter().for_each(|&v| m.add(v));
                m
            })
            .collect();
        let mut forward = Moments::new();
        blocks.iter().for_each(|b| forward.merge(b));
        let mut backward = Moments::new();
        blocks.iter().rev().for_each(|b| backward.merge(b));
        assert_eq!(forward.count(), 1000);
        for m in [forward, backward] {
            assert!((m.mean() - whole.mean()).abs() <= 1e-15 * whole.mean());
            assert!((m.variance() - whole.variance()).abs() <= 1e-10 * whole.variance());
        }
        // The same merge order gives the same bits.
        let mut again = Moments::new();
        blocks.iter().for_each(|b| again.merge(b));
        assert_eq!(again, forward);
        // Empty blocks change nothing.
        let mut with_empty = forward;
        with_empty.merge(&Moments::new());
        assert_eq!(with_empty, forward);
    }

    #[test]
    fn serde_round_trip_is_exact() {
        let mut m = Moments::new();
        values(10).iter().for_each(|&v| m.add(v));
        let text = serde_json::to_string(&m).unwrap();
        assert_eq!(serde_json::from_str::<Moments>(&text).unwrap(), m);
    }
}
