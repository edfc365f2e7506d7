//! Pair ensembles: the dipole correlation of a non-stationary ensemble, its spectrum and its
//! spectral moments, and the same moments from the sampled phase space.
//!
//! # The estimator
//!
//! A thermal ensemble of pairs sampled in a region of configuration space is not stationary:
//! pairs leave the region and none come in, so averaging a trajectory's product μ(t)·μ(t+τ) over
//! time origins t, or subtracting its time mean, does not estimate the equilibrium correlation.
//! The only time origin at which the ensemble is the equilibrium one is the sampled point, t = 0:
//!
//! ```text
//! C(τ) = ⟨μ(0)·μ(τ)⟩,   τ ∈ [−T, T],
//! ```
//!
//! each trajectory integrated forward and backward in time from its sampled phase point. The
//! backward run is the forward run of the time-reversed state (momenta p and J reversed, the
//! configuration and orientation kept): its configuration at t is the original's at −t, and μ
//! depends on the configuration only. By time-reversal symmetry of the canonical ensemble
//! C(−τ) = C(τ) in expectation; the two halves are estimated from different runs, so their
//! agreement is a check. `C(0) = ⟨|μ|²⟩` of the sampled distribution exactly. A trajectory
//! stopped by `run.stop_outside` contributes μ = 0 after its stop (the dipole is taken to vanish
//! outside the stop bounds); every completed trajectory counts at every lag.
//!
//! # Spectrum and moments
//!
//! The spectral density is the cosine transform of the even part `C_e(τ) = ½ (C(τ) + C(−τ))`,
//! under a flat-top window (1 for |τ| ≤ T/2, a cos² taper to 0 at |τ| = T), which leaves C and its
//! derivatives at τ = 0, and so the spectral moments, unchanged. The moments written beside each
//! other in moments.csv:
//!
//! ```text
//! M0 = ∫ I(ω) dω = C(0) = ⟨|μ|²⟩,     M2 = ∫ ω² I(ω) dω = −C''(0) = ⟨|dμ/dt|²⟩
//! ```
//!
//! (ω over (−∞, ∞), I even): from the spectrum (twice its integral over the written range), and
//! by Monte Carlo over the sampled states, with dμ/dt = S (∂μ/∂q q̇ + ω × μ) from the velocities
//! `(ω, q̇) = M⁻¹ (J, p)` of each state.

use std::path::{Path, PathBuf};

use serde_json::json;

use super::quantity::Quantity;
use super::runner::{Accumulators, Plan};
use crate::output::OutputFile;
use crate::runtime::Molecule;
use crate::runtime::ensemble::Moments;
use crate::runtime::hamiltonian::BodyState;
use crate::runtime::molecule::KineticMatrices;
use crate::runtime::nalgebra::{DMatrix, DVector, SMatrix, Vector3};
use crate::runtime::sample::Sampler;
use crate::runtime::spectrum::Spectrum;
use crate::runtime::surface::Dipole;
use crate::runtime::units::HARTREE_IN_WAVENUMBERS;

/// The time-reversed state: momenta and angular momentum reversed, configuration and
/// orientation kept.
pub fn reversed<const N: usize>(s: &BodyState<N>) -> BodyState<N> {
    BodyState { q: s.q, p: -s.p, orientation: s.orientation, j: -s.j }
}

/// Folds one trajectory's forward (`kf` outputs) and backward (`kb` outputs) observations into
/// the correlations: index `lags − 1 + k` holds `x(0) x(kΔt)`, index `lags − 1 − k` holds
/// `x(0) x(−kΔt)`; lags after a stop contribute 0.
pub fn fold_pair<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    acc: &mut Accumulators,
    forward: &[f64],
    kf: usize,
    backward: &[f64],
    kb: usize,
) {
    let nq = plan.quantities.len();
    let lags = plan.correlation_lags();
    if lags == 0 || kf == 0 {
        return;
    }
    for (ci, &qi) in plan.correlations.iter().enumerate() {
        let x0 = forward[qi];
        let c = &mut acc.correlations[ci];
        for k in 0..lags {
            let f = if k < kf { forward[k * nq + qi] } else { 0.0 };
            c[lags - 1 + k].add(x0 * f);
            if k > 0 {
                let b = if k < kb { backward[k * nq + qi] } else { 0.0 };
                c[lags - 1 - k].add(x0 * b);
            }
        }
    }
}

/// The summed dipole correlation ⟨μ(0)·μ(τ)⟩ of a pair plan, τ from −T to T
/// (`2·lags − 1` values), if the plan correlates the three components and some trajectory
/// completed.
pub fn two_sided_dipole_correlation<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
) -> Option<Vec<f64>> {
    let span = plan.correlation_span();
    let mut c = vec![0.0; span];
    for axis in 0..3 {
        let ci = plan.correlations.iter().position(|&qi| plan.quantities[qi] == Quantity::LabDipole(axis))?;
        if acc.correlations[ci].first()?.count() == 0 {
            return None;
        }
        for (sum, m) in c.iter_mut().zip(&acc.correlations[ci]) {
            *sum += m.mean();
        }
    }
    Some(c)
}

/// The flat-top window at lag k of n: 1 for k ≤ n/2, then `cos²(π (k − n/2) / n)` down to 0 at n.
pub fn flat_top(k: usize, n: usize) -> f64 {
    let (k, n) = (k as f64, n as f64);
    if k <= 0.5 * n { 1.0 } else { (std::f64::consts::PI * (k - 0.5 * n) / n).cos().powi(2) }
}

/// The spectrum of a pair plan: the cosine transform of the windowed even part of C.
pub fn spectrum<M, const N: usize, const NA: usize>(plan: &Plan<'_, M, N, NA>, acc: &Accumulators) -> Option<Spectrum> {
    let c = two_sided_dipole_correlation(plan, acc)?;
    let lags = plan.correlation_lags();
    let even: Vec<f64> = (0..lags).map(|k| 0.5 * (c[lags - 1 + k] + c[lags - 1 - k]) * flat_top(k, lags)).collect();
    Some(Spectrum::from_correlation(&even, plan.interval, plan.spectrum.max_wavenumber, super::spectrum::PADDING))
}

/// `(M0, M2)` of a spectrum: `2 ∫ I dω` and `2 ∫ ω² I dω` over the written range (ω in hartree).
pub fn spectral_moments(s: &Spectrum) -> (f64, f64) {
    let (lo, hi) = (0.0, f64::INFINITY);
    let w2: Vec<f64> =
        s.wavenumber.iter().zip(&s.lineshape).map(|(nu, i)| (nu / HARTREE_IN_WAVENUMBERS).powi(2) * i).collect();
    let m0 = 2.0 * s.integral(&s.lineshape, lo, hi) / HARTREE_IN_WAVENUMBERS;
    let m2 = 2.0 * s.integral(&w2, lo, hi) / HARTREE_IN_WAVENUMBERS;
    (m0, m2)
}

/// The dipole moments over the sampled states.
#[derive(Clone, Debug, Default)]
pub struct PhaseSpace {
    /// The lab-frame dipole's components, e·bohr.
    pub mu: [Moments; 3],
    /// |μ|², (e·bohr)².
    pub m0: Moments,
    /// |dμ/dt|², (e·bohr)² per (a.u. of time)² (= hartree² with ħ = 1).
    pub m2: Moments,
    /// States the sampler could not draw, or whose velocities are not defined.
    pub left_out: u64,
    /// `(ln Z, relative standard error)` of the sampler's configurational integral, if known.
    pub integral: Option<(f64, f64)>,
}

/// The dipole moments over the states `0..n` of `sampler` (the ensemble's initial states), for a
/// molecule with a dipole surface.
pub fn phase_space<M, const N: usize, const NA: usize>(m: &M, sampler: &dyn Sampler<N>, n: u64) -> PhaseSpace
where
    M: Molecule<N, NA>,
{
    let mut out = PhaseSpace { integral: sampler.configurational_integral(), ..PhaseSpace::default() };
    let Some(dipole) = m.dipole() else {
        // Without a dipole surface no state has a dipole moment.
        out.left_out = n;
        return out;
    };
    let mut kin = KineticMatrices::default();
    let mut dmu = SMatrix::<f64, 3, N>::zeros();
    let mut mu = Vector3::zeros();
    for index in 0..n {
        let Ok(s) = sampler.draw(index) else {
            out.left_out += 1;
            continue;
        };
        m.kinetic(&s.q, &mut kin);
        // (ω, q̇) = M⁻¹ (J, p), M = [[I, A], [Aᵀ, a]].
        let metric = DMatrix::from_fn(3 + N, 3 + N, |i, j| match (i < 3, j < 3) {
            (true, true) => kin.inertia[(i, j)],
            (true, false) => kin.coriolis[(i, j - 3)],
            (false, true) => kin.coriolis[(j, i - 3)],
            (false, false) => kin.a[(i - 3, j - 3)],
        });
        let momenta = DVector::from_fn(3 + N, |i, _| if i < 3 { s.j[i] } else { s.p[i - 3] });
        let Some(v) = metric.lu().solve(&momenta) else {
            out.left_out += 1;
            continue;
        };
        let omega = Vector3::new(v[0], v[1], v[2]);
        let qdot = crate::runtime::nalgebra::SVector::<f64, N>::from_fn(|i, _| v[3 + i]);
        dipole.moment(&s.q, &mut mu);
        dipole.moment_jacobian(&s.q, &mut dmu);
        let rate = dmu * qdot + omega.cross(&mu);
        if !(mu.iter().chain(rate.iter()).all(|x| x.is_finite())) {
            out.left_out += 1;
            continue;
        }
        let lab = s.orientation * mu;
        for (a, x) in out.mu.iter_mut().zip(lab.iter()) {
            a.add(*x);
        }
        out.m0.add(mu.norm_squared());
        out.m2.add(rate.norm_squared());
    }
    out
}

/// Writes `moments.csv`: M0 and M2 from the sampled phase space (with standard errors) and from
/// the spectrum, for a plan whose spectrum exists.
pub fn write_moments(phase: &PhaseSpace, spectrum: Option<&Spectrum>, dir: &Path) -> Result<PathBuf, crate::Error> {
    let (s0, s2) = spectrum.map_or((f64::NAN, f64::NAN), spectral_moments);
    let mut f = OutputFile::create(dir, "moments.csv")?;
    f.line("moment,unit,phase_space,phase_space_stderr,spectrum")?;
    f.line(&format!("M0,(e*bohr)^2,{:?},{:?},{s0:?}", phase.m0.mean(), phase.m0.standard_error()))?;
    f.line(&format!("M2,(e*bohr)^2*hartree^2,{:?},{:?},{s2:?}", phase.m2.mean(), phase.m2.standard_error()))?;
    f.flush()?;
    Ok(f.path().to_owned())
}

/// The summary.json block of the spectrum: estimator, configurational integral, moments.
pub fn summary<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    phase: Option<&PhaseSpace>,
    spectrum: Option<&Spectrum>,
) -> serde_json::Value {
    let (s0, s2) = spectrum.map_or((f64::NAN, f64::NAN), spectral_moments);
    let finite = |x: f64| x.is_finite().then_some(x);
    json!({
        "estimator": plan.spectrum.estimator.name(),
        "max_wavenumber_cm-1": plan.spectrum.max_wavenumber,
        "pair_volume_bohr3": plan.spectrum.pair_volume,
        "configurational_integral": phase.and_then(|p| p.integral).map(|(log, rel)| json!({
            "ln_Z": log,
            "Z": log.exp(),
            "relative_standard_error": rel,
            "unit": "bohr^(3*atoms-3)",
            "definition": "integral of exp(-U/kT) over the sampled region, Cartesian measure with the centre of mass fixed, U from the potential's own zero",
        })),
        "moments": phase.map(|p| json!({
            "unit_M0": "(e*bohr)^2",
            "unit_M2": "(e*bohr)^2*hartree^2",
            "phase_space_states": p.m0.count(),
            "phase_space_left_out": p.left_out,
            "M0_phase_space": finite(p.m0.mean()),
            "M0_phase_space_stderr": finite(p.m0.standard_error()),
            "M2_phase_space": finite(p.m2.mean()),
            "M2_phase_space_stderr": finite(p.m2.standard_error()),
            "M0_spectrum": finite(s0),
            "M2_spectrum": finite(s2),
            "mu_lab_mean": p.mu.iter().map(|m| finite(m.mean())).collect::<Vec<_>>(),
            "mu_lab_mean_stderr": p.mu.iter().map(|m| finite(m.standard_error())).collect::<Vec<_>>(),
        })),
    })
}
