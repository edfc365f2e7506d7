//! Lifetimes of trajectories that stop early: how many trajectories were observed at each
//! output time, and how many stopped there, by stop condition and side.
//!
//! A trajectory observed at outputs `0..=k` that stopped at output `k` (a stop condition met
//! there) is counted as observed at `0..=k` and as stopped at `k`; a trajectory that ran to the
//! end is observed at every output. So the observed count falls from one output to the next by
//! exactly the trajectories stopped at the first: `observed(k + 1) = observed(k) − stopped(k)`.
//! All counts are integers: merging is exact and independent of the order.

use serde::{Deserialize, Serialize};

/// Counts per output time of the trajectories observed and of those stopped, by condition and
/// side. Empty (no shape) until the first trajectory is added or a shaped one merged in, so
/// that an empty outcome needs no plan to be made.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Lifetimes {
    /// Stop conditions.
    conditions: usize,
    /// Trajectories observed at each output time.
    observed: Vec<u64>,
    /// Trajectories stopped at each output time, `[time][condition][side]` flattened
    /// (`(k · conditions + c) · 2 + side`, side 0 below the interval, 1 above).
    stopped: Vec<u64>,
}

/// Why stop counts cannot be merged: they come from another run (read from a process or a
/// file) or are damaged.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LifetimesError {
    /// The counts do not fit their own shape.
    #[error("stop counts of an inconsistent shape ({times} output times, {conditions} conditions, {counts} counts)")]
    Inconsistent {
        /// Output times of the counts.
        times: usize,
        /// Stop conditions of the counts.
        conditions: usize,
        /// Stop counts held.
        counts: usize,
    },
    /// The counts have another number of output times or stop conditions.
    #[error(
        "stop counts of another layout: {times} output times and {conditions} stop conditions against {own_times} and {own_conditions}"
    )]
    Layout {
        /// Output times of the counts merged in.
        times: usize,
        /// Their stop conditions.
        conditions: usize,
        /// Output times of the counts merged into.
        own_times: usize,
        /// Their stop conditions.
        own_conditions: usize,
    },
}

/// Which side of its interval a stopped coordinate was on.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// Below the lower bound.
    Below,
    /// Above the upper bound.
    Above,
}

impl Side {
    /// `"below"` or `"above"`.
    pub fn name(self) -> &'static str {
        match self {
            Side::Below => "below",
            Side::Above => "above",
        }
    }

    fn index(self) -> usize {
        match self {
            Side::Below => 0,
            Side::Above => 1,
        }
    }
}

impl Lifetimes {
    /// No trajectory, `times` output times and `conditions` stop conditions.
    pub fn new(times: usize, conditions: usize) -> Self {
        Self { conditions, observed: vec![0; times], stopped: vec![0; times * conditions * 2] }
    }

    /// Whether nothing has been counted into a shape yet.
    pub fn is_empty(&self) -> bool {
        self.observed.is_empty()
    }

    /// Adds one trajectory of a run with `times` output times and `conditions` stop conditions,
    /// observed at outputs `0..observed`, stopped at output `observed − 1` by `stop` (condition
    /// index and side), or run to the end (`stop` none).
    ///
    /// # Panics
    ///
    /// If the shape differs from the counts already held, `observed` is 0 or beyond `times`,
    /// or the condition is beyond `conditions` (programming errors).
    pub fn add(&mut self, times: usize, conditions: usize, observed: usize, stop: Option<(usize, Side)>) {
        if self.is_empty() {
            *self = Self::new(times, conditions);
        }
        assert!(self.observed.len() == times && self.conditions == conditions, "one shape per run");
        assert!((1..=times).contains(&observed), "{observed} outputs observed of {times}");
        for o in &mut self.observed[..observed] {
            *o += 1;
        }
        if let Some((c, side)) = stop {
            assert!(c < conditions, "condition {c} of {conditions}");
            self.stopped[((observed - 1) * conditions + c) * 2 + side.index()] += 1;
        }
    }

    /// Adds the counts of `other` (of the same shape, or either empty); counts of another shape
    /// (another run's, read from a process or a file) are an error saying what differs.
    pub fn merge(&mut self, other: &Lifetimes) -> Result<(), LifetimesError> {
        if other.stopped.len() != other.observed.len() * other.conditions * 2 {
            return Err(LifetimesError::Inconsistent {
                times: other.observed.len(),
                conditions: other.conditions,
                counts: other.stopped.len(),
            });
        }
        if other.is_empty() {
            return Ok(());
        }
        if self.is_empty() {
            *self = other.clone();
            return Ok(());
        }
        if self.observed.len() != other.observed.len() || self.conditions != other.conditions {
            return Err(LifetimesError::Layout {
                times: other.observed.len(),
                conditions: other.conditions,
                own_times: self.observed.len(),
                own_conditions: self.conditions,
            });
        }
        for (a, b) in self.observed.iter_mut().zip(&other.observed) {
            *a += b;
        }
        for (a, b) in self.stopped.iter_mut().zip(&other.stopped) {
            *a += b;
        }
        Ok(())
    }

    /// Trajectories observed at output `k` (0 when empty).
    pub fn observed(&self, k: usize) -> u64 {
        self.observed.get(k).copied().unwrap_or(0)
    }

    /// Trajectories stopped at output `k` by condition `c` on `side` (0 when empty).
    pub fn stopped_by(&self, k: usize, c: usize, side: Side) -> u64 {
        self.stopped.get((k * self.conditions + c) * 2 + side.index()).copied().unwrap_or(0)
    }

    /// Trajectories stopped at output `k`, all conditions.
    pub fn stopped(&self, k: usize) -> u64 {
        let w = 2 * self.conditions;
        self.stopped.get(k * w..(k + 1) * w).map_or(0, |s| s.iter().sum())
    }

    /// Trajectories stopped by condition `c` on `side`, at any output.
    pub fn total_by(&self, c: usize, side: Side) -> u64 {
        (0..self.observed.len()).map(|k| self.stopped_by(k, c, side)).sum()
    }

    /// Trajectories stopped in all.
    pub fn total_stopped(&self) -> u64 {
        self.stopped.iter().sum()
    }

    /// The survival fraction after output `k`: the fraction of the trajectories (those observed
    /// at output 0) not stopped at outputs `0..=k`, and its binomial standard error
    /// `√(S (1 − S) / n)`. NaN for no trajectory.
    pub fn survival(&self, k: usize) -> (f64, f64) {
        let n = self.observed(0);
        if n == 0 {
            return (f64::NAN, f64::NAN);
        }
        let gone: u64 = (0..=k).map(|j| self.stopped(j)).sum();
        let s = (n - gone.min(n)) as f64 / n as f64;
        (s, (s * (1.0 - s) / n as f64).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn observed_counts_fall_by_the_stopped_ones_and_merging_is_exact() {
        let runs: [(usize, Option<(usize, Side)>); 6] = [
            (5, None),
            (1, Some((0, Side::Below))),
            (3, Some((1, Side::Above))),
            (3, Some((0, Side::Above))),
            (5, Some((1, Side::Below))),
            (5, None),
        ];
        let mut whole = Lifetimes::default();
        for &(o, s) in &runs {
            whole.add(5, 2, o, s);
        }
        assert_eq!((0..5).map(|k| whole.observed(k)).collect::<Vec<_>>(), [6, 5, 5, 3, 3]);
        for k in 0..4 {
            assert_eq!(whole.observed(k) - whole.observed(k + 1), whole.stopped(k));
        }
        assert_eq!(whole.stopped(4), 1);
        assert_eq!((whole.total_by(0, Side::Below), whole.total_by(0, Side::Above)), (1, 1));
        assert_eq!((whole.total_by(1, Side::Below), whole.total_by(1, Side::Above)), (1, 1));
        assert_eq!(whole.total_stopped(), 4);
        assert_eq!(whole.survival(0).0, 5.0 / 6.0);
        assert_eq!(whole.survival(2).0, 3.0 / 6.0);
        assert_eq!(whole.survival(4).0, 2.0 / 6.0);
        let mut merged = Lifetimes::default();
        for chunk in runs.chunks(4).rev() {
            let mut part = Lifetimes::default();
            chunk.iter().for_each(|&(o, s)| part.add(5, 2, o, s));
            merged.merge(&part).unwrap();
        }
        merged.merge(&Lifetimes::default()).unwrap();
        assert_eq!(merged, whole);
        // Counts of another run's shape are an error, not a panic, and leave the total unchanged.
        let mut other = Lifetimes::default();
        other.add(4, 2, 2, None);
        let err = merged.merge(&other).unwrap_err().to_string();
        assert!(err.contains("4 output times and 2 stop conditions against 5 and 2"), "{err}");
        assert_eq!(merged, whole);
        let text = serde_json::to_string(&whole).unwrap();
        assert_eq!(serde_json::from_str::<Lifetimes>(&text).unwrap(), whole);
        assert!(Lifetimes::default().survival(0).0.is_nan());
    }

    #[test]
    fn merge_errors_say_what_differs() {
        let inconsistent = LifetimesError::Inconsistent { times: 3, conditions: 1, counts: 5 };
        assert_eq!(
            inconsistent.to_string(),
            "stop counts of an inconsistent shape (3 output times, 1 conditions, 5 counts)"
        );
        let layout = LifetimesError::Layout { times: 4, conditions: 2, own_times: 5, own_conditions: 1 };
        assert_eq!(
            layout.to_string(),
            "stop counts of another layout: 4 output times and 2 stop conditions against 5 and 1"
        );
        let mut bad = Lifetimes::default();
        bad.add(2, 1, 1, None);
        bad.stopped.pop();
        assert_eq!(
            Lifetimes::default().merge(&bad),
            Err(LifetimesError::Inconsistent { times: 2, conditions: 1, counts: 3 })
        );
    }
}
