//! Time-correlation functions of a sampled series by FFT, with the unbiased normalisation (or,
//! for spectra, of the Hann-tapered series: [`CorrelationWorkspace::tapered_autocorrelation`]).
//!
//! For a series `x(0), …, x(n−1)` at equal times, the autocorrelation at lag `τ` is
//!
//! ```text
//! C(τ) = Σ_{t=0}^{n−1−τ} x(t) x(t+τ) / (n − τ),   τ = 0, …, n−1
//! ```
//!
//! (each lag divided by the number of pairs it has: the standard unbiased estimate). The sum
//! is a linear, not circular, correlation: the series is padded with zeros to a length of at
//! least `2n − 1` before the transform, so no lag wraps around onto another. Cost `O(n log n)`
//! against `O(n²)` for the direct sum ([`autocorrelation_direct`], kept as the reference).

use std::sync::Arc;

use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};

/// Plans and buffers for series of one length; create once per thread and reuse: a call
/// allocates nothing.
pub struct CorrelationWorkspace {
    n: usize,
    forward: Arc<dyn Fft<f64>>,
    inverse: Arc<dyn Fft<f64>>,
    buffer: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl CorrelationWorkspace {
    /// A workspace for series of length `n` (`n ≥ 1`; 0 is treated as 1).
    pub fn new(n: usize) -> Self {
        let n = n.max(1);
        // A power of two ≥ 2n − 1: the zero padding that makes the correlation linear.
        let padded = (2 * n - 1).next_power_of_two();
        let mut planner = FftPlanner::new();
        let forward = planner.plan_fft_forward(padded);
        let inverse = planner.plan_fft_inverse(padded);
        let scratch_len = forward.get_inplace_scratch_len().max(inverse.get_inplace_scratch_len());
        Self {
            n,
            forward,
            inverse,
            buffer: vec![Complex::default(); padded],
            scratch: vec![Complex::default(); scratch_len],
        }
    }

    /// The series length this workspace is for.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Always false: a workspace is for series of at least one value.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Writes `C(τ)` of `x` for `τ = 0..n` into `out`. Both have the same length `n`, at least 1
    /// and at most [`Self::len`]; every method of the workspace takes a series that long, and
    /// treats it as a whole series of `n` values (normalisation, time mean and taper over `n`).
    ///
    /// # Panics
    ///
    /// If `x` and `out` differ in length, are empty or longer than the workspace's length (a
    /// programming error).
    pub fn autocorrelation(&mut self, x: &[f64], out: &mut [f64]) {
        self.correlate(x, 0.0, out);
    }

    /// The autocorrelation of the fluctuation `x(t) − x̄` about the series' own time mean.
    pub fn fluctuation_autocorrelation(&mut self, x: &[f64], out: &mut [f64]) {
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        self.correlate(x, mean, out);
    }

    /// The autocorrelation of the fluctuation about the time mean after a Hann taper
    /// `h_t = sin²(π (t + ½) / n)`: with `y(t) = h_t (x(t) − x̄)`,
    ///
    /// ```text
    /// C_h(τ) = Σ_{t=0}^{n−1−τ} y(t) y(t+τ) / Σ_t h_t²
    /// ```
    ///
    /// Its cosine transform is the tapered periodogram `|Σ_t y(t) e^{−iωt}|² / Σ_t h_t²`, never
    /// negative, and it keeps `C_h(0)` the (taper-weighted) variance. The expected value is the
    /// true `C(τ)` times the taper's own normalised autocorrelation, which falls smoothly to
    /// zero at `τ = n`: a spectrum from it needs no further window, and a slow drift or a
    /// large low-frequency part (a molecule's rotation) does not leak into high frequencies as
    /// it does through the kink at τ = 0 that the unbiased estimate of a drifting series has
    /// (docs/src/reference/equations.md, section 11).
    pub fn tapered_autocorrelation(&mut self, x: &[f64], out: &mut [f64]) {
        let mean = x.iter().sum::<f64>() / x.len().max(1) as f64;
        self.correlate_with(x, mean, true, out);
    }

    fn correlate(&mut self, x: &[f64], shift: f64, out: &mut [f64]) {
        self.correlate_with(x, shift, false, out);
    }

    fn correlate_with(&mut self, x: &[f64], shift: f64, taper: bool, out: &mut [f64]) {
        // A series shorter than the workspace's (a trajectory that stopped early) is its own
        // series: its own length in the normalisation and the taper; the padding stays ≥ 2n − 1.
        let n = x.len();
        assert!(
            n >= 1 && n <= self.n && out.len() == n,
            "series of length {} and {} for a workspace of {}",
            x.len(),
            out.len(),
            self.n
        );
        let mut taper_power = 0.0;
        for (t, (b, &v)) in self.buffer.iter_mut().zip(x).enumerate() {
            let h = if taper { hann(t, n) } else { 1.0 };
            taper_power += h * h;
            *b = Complex::new(h * (v - shift), 0.0);
        }
        self.buffer[n..].fill(Complex::default());
        self.forward.process_with_scratch(&mut self.buffer, &mut self.scratch);
        // |X(k)|² is the transform of the (linear, thanks to the padding) autocorrelation sum.
        for b in &mut self.buffer {
            *b = Complex::new(b.norm_sqr(), 0.0);
        }
        self.inverse.process_with_scratch(&mut self.buffer, &mut self.scratch);
        // rustfft does not normalise: the inverse carries a factor of the padded length.
        let scale = 1.0 / self.buffer.len() as f64;
        for (tau, o) in out.iter_mut().enumerate() {
            let pairs = if taper { taper_power } else { (n - tau) as f64 };
            *o = self.buffer[tau].re * scale / pairs;
        }
    }
}

/// The Hann taper `sin²(π (t + ½) / n)` at sample `t` of `n` (symmetric, never zero).
pub fn hann(t: usize, n: usize) -> f64 {
    (std::f64::consts::PI * (t as f64 + 0.5) / n as f64).sin().powi(2)
}

/// `C(τ) = Σ_t x(t) x(t+τ) / (n − τ)` by the direct `O(n²)` sum: the reference for the FFT.
pub fn autocorrelation_direct(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    (0..n).map(|tau| (0..n - tau).map(|t| x[t] * x[t + tau]).sum::<f64>() / (n - tau) as f64).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(n: usize) -> Vec<f64> {
        (0..n).map(|i| (0.3 * i as f64).sin() + 0.5 * (1.7 * i as f64).cos() + 0.1 * ((i * 31) % 7) as f64).collect()
    }

    #[test]
    fn fft_matches_the_direct_sum_for_many_lengths() {
        for n in [1, 2, 3, 5, 16, 17, 100, 101, 257] {
            let x = series(n);
            let mut ws = CorrelationWorkspace::new(n);
            let mut c = vec![0.0; n];
            ws.autocorrelation(&x, &mut c);
            let direct = autocorrelation_direct(&x);
            let scale = direct[0].abs();
            for tau in 0..n {
                assert!(
                    (c[tau] - direct[tau]).abs() <= 1e-13 * scale,
                    "n = {n}, tau = {tau}: {} vs {}",
                    c[tau],
                    direct[tau]
                );
            }
        }
    }

    #[test]
    fn a_shorter_series_in_a_longer_workspace_is_its_own_series() {
        let mut ws = CorrelationWorkspace::new(64);
        for n in [1, 2, 17, 33, 64] {
            let x = series(n);
            let mut own = CorrelationWorkspace::new(n);
            for f in [
                CorrelationWorkspace::autocorrelation,
                CorrelationWorkspace::fluctuation_autocorrelation,
                CorrelationWorkspace::tapered_autocorrelation,
            ] {
                let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
                f(&mut ws, &x, &mut a);
                f(&mut own, &x, &mut b);
                for tau in 0..n {
                    assert!((a[tau] - b[tau]).abs() <= 1e-13 * (1.0 + b[0].abs()), "n = {n}, tau = {tau}");
                }
            }
        }
    }

    #[test]
    fn exact_values_and_no_circular_wrap() {
        // x = (1, 2, 3): C(0) = 14/3, C(1) = (2 + 6)/2 = 4, C(2) = 3/1. A circular correlation
        // would give C(1) = (2 + 6 + 3)/2 and C(2) = (3 + 2 + 6)/1.
        let mut ws = CorrelationWorkspace::new(3);
        let mut c = [0.0; 3];
        ws.autocorrelation(&[1.0, 2.0, 3.0], &mut c);
        let exact = [14.0 / 3.0, 4.0, 3.0];
        for tau in 0..3 {
            assert!((c[tau] - exact[tau]).abs() < 1e-14, "tau = {tau}: {}", c[tau]);
        }
    }

    #[test]
    fn the_tapered_estimate_is_the_direct_sum_of_the_tapered_series() {
        for n in [1, 2, 3, 17, 100, 257] {
            let x = series(n);
            let mean = x.iter().sum::<f64>() / n as f64;
            let y: Vec<f64> = x.iter().enumerate().map(|(t, v)| hann(t, n) * (v - mean)).collect();
            let power: f64 = (0..n).map(|t| hann(t, n).powi(2)).sum();
            let mut ws = CorrelationWorkspace::new(n);
            let mut c = vec![0.0; n];
            ws.tapered_autocorrelation(&x, &mut c);
            for tau in 0..n {
                let direct = (0..n - tau).map(|t| y[t] * y[t + tau]).sum::<f64>() / power;
                assert!((c[tau] - direct).abs() <= 1e-13 * (1.0 + c[0].abs()), "n = {n}, tau = {tau}");
            }
        }
        // Σ h_t² = 3n/8 for n ≥ 2 (the mean of sin⁴ over whole periods).
        let n = 64;
        let power: f64 = (0..n).map(|t| hann(t, n).powi(2)).sum();
        assert!((power - 3.0 * n as f64 / 8.0).abs() < 1e-12);
    }

    #[test]
    fn a_cosine_fluctuation_has_the_closed_form_correlation() {
        // x(t) = a + cos(ω t) over whole periods: the fluctuation is cos(ω t), and
        // Σ_t cos(ωt) cos(ω(t+τ)) = ½ (n − τ) cos(ωτ) + ½ Σ_t cos(ω(2t + τ)), where the last sum
        // is bounded by 1/|sin ω|: C(τ) = ½ cos(ωτ) within 1/(2 |sin ω| (n − τ)).
        let (n, omega) = (4096, 2.0 * std::f64::consts::PI / 64.0);
        let x: Vec<f64> = (0..n).map(|t| 3.0 + (omega * t as f64).cos()).collect();
        let mut ws = CorrelationWorkspace::new(n);
        let mut c = vec![0.0; n];
        ws.fluctuation_autocorrelation(&x, &mut c);
        for tau in [0, 1, 16, 32, 100, 1000] {
            let exact = 0.5 * (omega * tau as f64).cos();
            let bound = 1.0 / (2.0 * omega.sin() * (n - tau) as f64) + 1e-12;
            assert!((c[tau] - exact).abs() <= bound, "tau = {tau}: {} vs {exact}", c[tau]);
        }
    }
}
