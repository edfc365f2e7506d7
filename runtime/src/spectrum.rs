//! The classical infrared absorption spectrum from a dipole autocorrelation function
//! (docs/src/reference/equations.md, section 11).
//!
//! Given the tapered autocorrelation `C_h(τ)` of the lab-frame dipole at `τ = kΔt`,
//! `k = 0 … n−1` (e²·bohr², a.u. of time; [`crate::ensemble::CorrelationWorkspace::tapered_autocorrelation`]
//! of each component, summed, averaged over an ensemble), the line shape is its cosine transform
//!
//! ```text
//! I(ω) = (1/2π) Σ_{|k|<n} C_h(|k|) e^{−iωkΔt} Δt = (Δt/π) [½ C_h(0) + Σ_{k≥1} C_h(k) cos(ωkΔt)]
//! ```
//!
//! evaluated by one FFT with zero padding (the padding only interpolates). For one trajectory
//! this is the Hann-tapered periodogram `Δt |Σ_t y(t) e^{−iωtΔt}|² / (2π Σ h²)`, never negative;
//! the taper `h` (over the whole trajectory, length `T = nΔt`) is the window, and a line comes
//! out with the shape of the taper's power spectrum, full width at half maximum 1.441/T, i.e.
//! [`HANN_FWHM`]`/(cT)` in wavenumbers: the resolution is set by the trajectory length. The
//! absorption cross section per molecule (atomic units, 4πε₀ = ħ = 1) is
//!
//! ```text
//! σ(ω) = (4π² ω / 3c) (1 − e^{−βω}) Q(ω) I(ω)
//! ```
//!
//! with the quantum correction `Q` of [`QuantumCorrection`].

use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

use crate::units::{BOHR_IN_ANGSTROM, HARTREE_IN_WAVENUMBERS};

/// The speed of light in atomic units (1/α, CODATA 2018).
pub const SPEED_OF_LIGHT_AU: f64 = 137.035_999_084;

/// Boltzmann's constant in hartree per kelvin (CODATA 2018).
pub const BOLTZMANN_HARTREE_PER_K: f64 = 3.166_811_563e-6;

/// Avogadro's number (exact since 2019).
pub const AVOGADRO: f64 = 6.022_140_76e23;

/// The full width at half maximum of the power spectrum of a Hann taper over a time T, in units
/// of 1/T: the root of `(sinc x / (1 − x²))² = ½` (sinc x = sin πx / πx) is x = 0.72057.
pub const HANN_FWHM: f64 = 1.441_14;

/// How the classical line shape stands in for the quantum one (docs/src/reference/equations.md, section 11).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum QuantumCorrection {
    /// Q = 1: the classical function used as it is (detailed balance is not obeyed).
    None,
    /// Q = βω / (1 − e^{−βω}): σ ∝ β ω² I(ω), exact for a harmonic oscillator with a linear dipole.
    Harmonic,
    /// Q = e^{βω/2} (Schofield): σ ∝ 2 ω sinh(βω/2) I(ω).
    Standard,
}

impl QuantumCorrection {
    /// All three, in the order of the columns of `spectrum.csv`.
    pub const ALL: [QuantumCorrection; 3] =
        [QuantumCorrection::None, QuantumCorrection::Harmonic, QuantumCorrection::Standard];

    /// The name in files.
    pub fn name(self) -> &'static str {
        match self {
            QuantumCorrection::None => "none",
            QuantumCorrection::Harmonic => "harmonic",
            QuantumCorrection::Standard => "standard",
        }
    }

    /// `(1 − e^{−βω}) Q(ω)` at angular frequency `omega` (hartree) and `beta` (1/hartree).
    pub fn factor(self, omega: f64, beta: f64) -> f64 {
        let x = beta * omega;
        match self {
            QuantumCorrection::None => -(-x).exp_m1(),
            QuantumCorrection::Harmonic => x,
            QuantumCorrection::Standard => 2.0 * (0.5 * x).sinh(),
        }
    }
}

/// A spectrum on a wavenumber grid.
#[derive(Clone, Debug)]
pub struct Spectrum {
    /// Grid, cm⁻¹ (spacing set by the zero padding; the resolution is [`Spectrum::resolution`]).
    pub wavenumber: Vec<f64>,
    /// Line shape I(ω), e²·bohr² per hartree (ħ = 1: per unit of angular frequency).
    pub lineshape: Vec<f64>,
    /// Trajectory length T, a.u. of time.
    pub length: f64,
}

impl Spectrum {
    /// The cosine transform of the tapered correlation `c` (n values at spacing `dt`, a.u.) up
    /// to `max_wavenumber` cm⁻¹, on a grid `padding` times finer than 1/(2nΔt) (padding ≥ 1).
    pub fn from_correlation(c: &[f64], dt: f64, max_wavenumber: f64, padding: usize) -> Self {
        let n = c.len().max(1);
        let len = (2 * n * padding.max(1)).next_power_of_two();
        let mut buffer = vec![Complex::new(0.0, 0.0); len];
        for (k, &v) in c.iter().enumerate() {
            let half = if k == 0 { 0.5 } else { 1.0 };
            buffer[k] = Complex::new(half * v, 0.0);
        }
        FftPlanner::new().plan_fft_forward(len).process(&mut buffer);
        // Bin j is ω_j = 2π j / (len Δt), in hartree (ħ = 1); cm⁻¹ = ω · HARTREE_IN_WAVENUMBERS.
        let mut wavenumber = Vec::new();
        let mut lineshape = Vec::new();
        for (j, b) in buffer.iter().enumerate().take(len / 2) {
            let nu = 2.0 * std::f64::consts::PI * j as f64 / (len as f64 * dt) * HARTREE_IN_WAVENUMBERS;
            if nu > max_wavenumber {
                break;
            }
            wavenumber.push(nu);
            lineshape.push(dt / std::f64::consts::PI * b.re);
        }
        Spectrum { wavenumber, lineshape, length: n as f64 * dt }
    }

    /// The resolution, cm⁻¹: the full width at half maximum of a line under the Hann taper,
    /// [`HANN_FWHM`]/(cT).
    pub fn resolution(&self) -> f64 {
        // HANN_FWHM/T in ordinary frequency; ω = 2π f is an energy in hartree (ħ = 1).
        HANN_FWHM * 2.0 * std::f64::consts::PI / self.length * HARTREE_IN_WAVENUMBERS
    }

    /// The absorption cross section σ per molecule in cm², at each grid point, for temperature
    /// `kelvin` and the given correction.
    pub fn cross_section(&self, kelvin: f64, correction: QuantumCorrection) -> Vec<f64> {
        let beta = 1.0 / (BOLTZMANN_HARTREE_PER_K * kelvin);
        let bohr_cm2 = (BOHR_IN_ANGSTROM * 1e-8).powi(2);
        self.wavenumber
            .iter()
            .zip(&self.lineshape)
            .map(|(&nu, &i)| {
                let omega = nu / HARTREE_IN_WAVENUMBERS;
                4.0 * std::f64::consts::PI.powi(2) * omega / (3.0 * SPEED_OF_LIGHT_AU)
                    * correction.factor(omega, beta)
                    * i
                    * bohr_cm2
            })
            .collect()
    }

    /// ∫ v dν̃ over `[low, high]` cm⁻¹ of `values` given on the grid, taken as piecewise linear
    /// between grid points (the trapezoid rule, with the partial intervals at both ends).
    pub fn integral(&self, values: &[f64], low: f64, high: f64) -> f64 {
        let mut sum = 0.0;
        for j in 1..self.wavenumber.len().min(values.len()) {
            let (a, b) = (self.wavenumber[j - 1], self.wavenumber[j]);
            let (lo, hi) = (a.max(low), b.min(high));
            if hi > lo {
                let at = |x: f64| values[j - 1] + (values[j] - values[j - 1]) * (x - a) / (b - a);
                sum += 0.5 * (at(lo) + at(hi)) * (hi - lo);
            }
        }
        sum
    }

    /// ∫ σ dν̃ over `[low, high]` cm⁻¹ ([`Spectrum::integral`]), in km/mol.
    pub fn band_intensity(&self, sigma: &[f64], low: f64, high: f64) -> f64 {
        self.integral(sigma, low, high) * AVOGADRO * 1e-5
    }
}

/// The double-harmonic integrated intensity of a band, km/mol, from `|∂μ/∂Q|²` in
/// e²·bohr² per (m_e·bohr²) (Q mass-weighted, atomic units): ∫σ dω = (2π²/3c)|∂μ/∂Q|².
pub fn double_harmonic_km_per_mol(dmu_dq_squared: f64) -> f64 {
    let bohr_cm2 = (BOHR_IN_ANGSTROM * 1e-8).powi(2);
    2.0 * std::f64::consts::PI.powi(2) / (3.0 * SPEED_OF_LIGHT_AU)
        * dmu_dq_squared
        * HARTREE_IN_WAVENUMBERS
        * bohr_cm2
        * AVOGADRO
        * 1e-5
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cosine_gives_one_line_at_its_frequency_with_its_power() {
        // x(t) = cos(ω0 t): the power ½ splits into ±ω0, so the line at ω0 has area ¼ (in ω).
        let (nu0, dt, n) = (1500.0, 20.0, 4000);
        let omega0 = nu0 / HARTREE_IN_WAVENUMBERS;
        let x: Vec<f64> = (0..n).map(|k| (omega0 * k as f64 * dt).cos()).collect();
        let mut c = vec![0.0; n];
        crate::ensemble::CorrelationWorkspace::new(n).tapered_autocorrelation(&x, &mut c);
        let s = Spectrum::from_correlation(&c, dt, 4000.0, 8);
        assert!(s.lineshape.iter().all(|&v| v > -1e-12 * s.lineshape[0].abs().max(1.0)), "a periodogram");
        let peak = (0..s.lineshape.len()).max_by(|&a, &b| s.lineshape[a].total_cmp(&s.lineshape[b])).unwrap();
        let spacing = s.wavenumber[1] - s.wavenumber[0];
        assert!((s.wavenumber[peak] - nu0).abs() <= spacing, "peak at {} cm-1", s.wavenumber[peak]);
        let integral: f64 = s.lineshape.iter().sum::<f64>() * spacing / HARTREE_IN_WAVENUMBERS;
        assert!((integral - 0.25).abs() < 1e-3, "∫ I dω = {integral}");
        // The half maximum width is the stated resolution, within the grid spacing.
        let half = s.lineshape[peak] / 2.0;
        let above = s.lineshape.iter().filter(|&&v| v > half).count() as f64 * spacing;
        assert!((above - s.resolution()).abs() < 1.5 * spacing, "FWHM {above} vs {}", s.resolution());
        // Far from the line (20 resolutions) the taper leaves less than 1e-6 of the peak (2.0e-7
        // measured; a low-frequency band 1e4 times stronger than a vibrational one, the rotation
        // of a polar molecule at low T, must not show through).
        let far = s.wavenumber.iter().zip(&s.lineshape).filter(|(w, _)| (*w - nu0).abs() > 20.0 * s.resolution());
        let worst = far.map(|(_, v)| v.abs()).fold(0.0, f64::max) / s.lineshape[peak];
        assert!(worst < 1e-6, "{worst:e} of the peak 20 resolutions away");
    }

    #[test]
    fn the_integral_is_exact_for_a_linear_function_between_any_bounds() {
        let s = Spectrum { wavenumber: (0..11).map(|j| 1.5 * j as f64).collect(), lineshape: Vec::new(), length: 1.0 };
        let v: Vec<f64> = s.wavenumber.iter().map(|x| 2.0 + 3.0 * x).collect();
        for (lo, hi) in [(0.0, 15.0), (0.7, 14.2), (2.0, 2.9), (-5.0, 30.0)] {
            let (a, b) = (f64::max(lo, 0.0), f64::min(hi, 15.0));
            let exact = 2.0 * (b - a) + 1.5 * (b * b - a * a);
            assert!((s.integral(&v, lo, hi) - exact).abs() < 1e-12, "[{lo}, {hi}]");
        }
    }

    #[test]
    fn the_double_harmonic_constant_is_the_textbook_one() {
        // A_k = (N_A π / 3c²)(1/4πε₀)|∂μ/∂Q_k|² = 42.2561 km/mol for ∂μ/∂Q = 1 D Å⁻¹ u^-½
        // (e.g. Neugebauer, Reiher, Kind & Hess, J. Comput. Chem. 23, 895 (2002)).
        use crate::units::{DALTON_IN_ELECTRON_MASSES, DEBYE_IN_E_BOHR};
        let unit = DEBYE_IN_E_BOHR / (1.0 / BOHR_IN_ANGSTROM * DALTON_IN_ELECTRON_MASSES.sqrt());
        let a = double_harmonic_km_per_mol(unit * unit);
        assert!((a - 42.2561).abs() < 1e-3, "{a} km/mol");
    }

    #[test]
    fn the_corrections_agree_at_low_frequency_and_obey_their_formulas() {
        let beta = 1.0 / (BOLTZMANN_HARTREE_PER_K * 300.0);
        let w = 1e-7;
        for c in QuantumCorrection::ALL {
            assert!((c.factor(w, beta) / (beta * w) - 1.0).abs() < 1e-3, "{}", c.name());
        }
        let w = 3000.0 / HARTREE_IN_WAVENUMBERS;
        let x = beta * w;
        assert!((QuantumCorrection::None.factor(w, beta) - (1.0 - (-x).exp())).abs() < 1e-15);
        assert!((QuantumCorrection::Standard.factor(w, beta) - ((x / 2.0).exp() - (-x / 2.0).exp())).abs() < 1e-9);
    }
}
