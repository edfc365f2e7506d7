//! Exact rejection sampling of the configuration q (and, at fixed |J|, the direction of J) from
//! an unnormalised density, with an envelope found once when the sampler is built.
//!
//! # Method
//!
//! A proposal φ (a Gaussian about the minimum of U with covariance `s·kT_eff·F⁻¹`, F the
//! Hessian there, for several widths s, with angles that turn through a whole period, such as
//! torsions, uniform instead; or uniform in the region's box when the box is finite)
//! is drawn from; a candidate q is accepted with probability `r(q) / r_max`, where
//! `r = target / φ` and `r_max` bounds r over the region. Accepted points are then distributed
//! exactly as the target, and each draw uses only its own trajectory's stream, so trajectory i
//! depends on `(seed, i)` alone.
//!
//! `r_max` is found at build time: 2000 points from each candidate proposal, 2000 from it at
//! three times its width and, where the box is finite, 2000 uniform in the box; a pattern
//! search from the best eight of them; and a safety
//! factor [`SAFETY`]. The candidate with the largest estimated acceptance rate
//! `E_φ[r] / r_max` is used. Every draw checks `r(q) ≤ r_max`: a point above it (the density
//! somewhere larger than the search found) is an error naming q, never a silently wrong
//! sample. The build-time search is deterministic (a fixed internal stream), so the envelope
//! does not depend on the seed.
//!
//! # Cost
//!
//! One candidate costs one potential and one kinetic-matrix evaluation and a block Cholesky
//! factorization of M (~1 µs for water); the expected number of candidates per draw is the
//! inverse of the acceptance rate, `r_max / E_φ[r]`, about 2–4 for water and 5–15 for methane
//! at 300 K (`Configuration::acceptance`).

use nalgebra::{DMatrix, Matrix3, SMatrix, SVector, Vector3};
use rand::RngExt as _;
use rand_distr::StandardNormal;

use super::{SampleError, TrajectoryRng, stream, uniform_direction};
use crate::hamiltonian::fast::MetricFactor;
use crate::modes;
use crate::molecule::{KineticMatrices, Molecule};
use crate::units::CoordinateUnit;

/// The factor between the largest `target / proposal` ratio found at build time and the bound
/// used for rejection.
pub const SAFETY: f64 = 2.0;

/// `ln(det M / det M(centre))` below which a local minimum of det M along an angle is taken
/// for a singular geometry that ends the angle's default range.
const SINGULAR_LOG_DET: f64 = -4.605_170_185_988_091; // ln 0.01

/// Points drawn per candidate proposal when the envelope is searched.
const SEARCH_POINTS: usize = 2000;

/// The smallest estimated acceptance rate accepted when building: below it the region is so
/// large (or the density so far from the proposals) that a draw would take thousands of
/// evaluations, which usually means the region does not bound the density.
const MIN_ACCEPTANCE: f64 = 1e-3;

/// The weight of the uniform part of a Gaussian proposal mixed with the box (finite boxes).
const BOX_WEIGHT: f64 = 0.1;

/// Starting points (the best of the random points) of the pattern search for the envelope.
const SEARCH_STARTS: usize = 8;

/// Proposals tried per draw before a draw fails.
const MAX_TRIES: usize = 1_000_000;

/// The unnormalised log density of the configuration.
#[derive(Copy, Clone, Debug, PartialEq)]
pub(crate) enum Target {
    /// `−(U − U_shift)/kT + [½ ln det M]` (the bracket unless `metric` is false, which is wrong
    /// on purpose and only for tests).
    Boltzmann { kt: f64, metric: bool },
    /// `½ ln det M + power · ln(E − U)`.
    Shell { energy: f64, power: f64 },
    /// `½ ln det S + power · ln(E − U − ½ j² ĵᵀ I⁻¹ ĵ)`, S = a − Aᵀ I⁻¹ A.
    ShellFixedJ { energy: f64, j: f64, power: f64 },
}

/// The Cholesky factor of the kinetic metric `M = [[I, A], [Aᵀ, a]] = L Lᵀ` in blocks:
/// `L = [[L1, 0], [B, L2]]` with `I = L1 L1ᵀ`, `B = Aᵀ L1⁻ᵀ`, `S = a − Aᵀ I⁻¹ A = L2 L2ᵀ`.
#[derive(Copy, Clone, Debug)]
pub(crate) struct MetricCholesky<const N: usize> {
    pub l1: Matrix3<f64>,
    pub b: SMatrix<f64, N, 3>,
    pub l2: SMatrix<f64, N, N>,
    /// `½ ln det I`.
    pub half_log_det_i: f64,
    /// `½ ln det S`.
    pub half_log_det_s: f64,
}

impl<const N: usize> MetricCholesky<N> {
    /// None where M is singular, not positive definite or not finite (zero density).
    pub fn new(k: &KineticMatrices<N>) -> Option<Self> {
        let l1 = k.inertia.cholesky()?.l();
        let x = l1.solve_lower_triangular(&k.coriolis)?;
        let s = k.a - x.transpose() * x;
        let s = (s + s.transpose()) * 0.5;
        let l2 = s.cholesky()?.l();
        let half_log_det_i = (0..3).map(|i| l1[(i, i)].ln()).sum::<f64>();
        let half_log_det_s = (0..N).map(|i| l2[(i, i)].ln()).sum::<f64>();
        (half_log_det_i.is_finite() && half_log_det_s.is_finite()).then_some(Self {
            l1,
            b: x.transpose(),
            l2,
            half_log_det_i,
            half_log_det_s,
        })
    }

    /// `(J, p) = L (z1, z2)`.
    pub fn apply(&self, z1: &Vector3<f64>, z2: &SVector<f64, N>) -> (Vector3<f64>, SVector<f64, N>) {
        (self.l1 * z1, self.b * z1 + self.l2 * z2)
    }

    /// `Aᵀ I⁻¹ J = B L1⁻¹ J`, the p of the velocities `(I⁻¹ J, 0)`.
    pub fn p_of_j(&self, j: &Vector3<f64>) -> SVector<f64, N> {
        let y = self.l1.solve_lower_triangular(j).unwrap_or_else(Vector3::zeros);
        self.b * y
    }

    /// `½ Jᵀ I⁻¹ J`.
    pub fn rotational_energy(&self, j: &Vector3<f64>) -> f64 {
        let y = self.l1.solve_lower_triangular(j).unwrap_or_else(Vector3::zeros);
        0.5 * y.norm_squared()
    }
}

/// One accepted configuration with what the momenta need.
#[derive(Copy, Clone, Debug)]
pub(crate) struct Point<const N: usize> {
    pub q: SVector<f64, N>,
    pub u: f64,
    pub chol: MetricCholesky<N>,
    pub kinetic: KineticMatrices<N>,
    /// The direction of J (fixed-|J| shells), else zero.
    pub j_dir: Vector3<f64>,
}

#[derive(Clone, Debug)]
enum Proposal<const N: usize> {
    /// `q = centre + l z`, z standard normal, except that the coordinates marked `uniform`
    /// (angles free to turn through a whole period, such as a torsion, whose Boltzmann factor
    /// may have several wells) are uniform in their box; `ln φ = −½ Σ z_k²` over the others.
    ///
    /// In a finite box the Gaussian may be mixed with the uniform distribution on the box: a
    /// proposal is uniform with probability `box_weight`, and `ln φ` is that of the mixture,
    /// `ln((1 − w) e^{−½ Σ z_k²} + e^{log_box})` with `log_box = ln(w |det l| (2π)^{d/2} / V)`
    /// (V the box volume in the Gaussian coordinates, d their number). The uniform part keeps
    /// `target / φ` bounded in the tails, where a potential that levels off (a Morse bond)
    /// falls more slowly than any Gaussian.
    Gaussian { centre: SVector<f64, N>, l: SMatrix<f64, N, N>, uniform: [bool; N], box_weight: f64, log_box: f64 },
    /// Uniform in the (finite) box; `ln φ = 0`.
    Uniform,
}

/// The configuration sampler: a target, a region and the envelope.
pub(crate) struct Configuration<'m, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'m M,
    target: Target,
    low: SVector<f64, N>,
    high: SVector<f64, N>,
    /// Absolute upper bound on U (hartree), from the energy cap.
    u_cap: Option<f64>,
    /// Subtracted from U in the Boltzmann factor (keeps the exponent small).
    u_shift: f64,
    proposal: Proposal<N>,
    log_bound: f64,
    /// Estimated acceptance rate of the chosen proposal.
    pub acceptance: f64,
    /// The lowest U found in the region (hartree).
    pub u_min: f64,
}

/// The region's box and cap: see [`super::Region`].
pub(crate) struct Bounds<const N: usize> {
    pub low: SVector<f64, N>,
    pub high: SVector<f64, N>,
    pub u_cap: Option<f64>,
}

/// The stationary point of U found from the reference geometry (the reference itself when
/// Newton fails) and the Hessian there (None if not finite).
pub(crate) fn centre<M, const N: usize, const NA: usize>(
    molecule: &M,
) -> Result<(SVector<f64, N>, Option<SMatrix<f64, N, N>>), SampleError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let reference = molecule.reference_geometry().ok_or_else(|| {
        SampleError::Invalid(format!(
            "{} has no reference geometry (every coordinate needs a `reference` in {})",
            molecule.name(),
            molecule.source()
        ))
    })?;
    let q = modes::stationary_point(molecule, &reference).unwrap_or(reference);
    let f = modes::hessian(molecule, &q);
    Ok((q, f.iter().all(|x| x.is_finite()).then_some(f)))
}

/// The box of the region, always within each coordinate's valid range
/// ([`crate::molecule::Coordinate::range`]; limits reaching outside it are an error): given
/// limits, else lengths in (0, ∞) and angles within the interval
/// about `centre` where the metric stays regular, at most ±π (one period), found by a scan in
/// steps of 0.01 rad along each angle with the others at `centre`. The scan stops where the
/// metric is singular or the positions undefined, and at a local minimum of det M below 1 % of
/// its value at the centre (a bond angle reaching π: stepping over it would count mirror
/// images twice). The part of the range lost this way is at most one step, where √det M is
/// small. An angle that keeps a regular metric through a whole period (a torsion) gets one
/// full period and is then proposed uniformly.
pub(crate) fn bounds<M, const N: usize, const NA: usize>(
    molecule: &M,
    region: &super::Region<N>,
    centre: &SVector<f64, N>,
) -> Result<Bounds<N>, SampleError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let coords = molecule.coordinates();
    let mut low = SVector::zeros();
    let mut high = SVector::zeros();
    for k in 0..N {
        let (lo, hi) = match region.limits[k] {
            Some((lo, hi)) => {
                if lo.partial_cmp(&hi) != Some(std::cmp::Ordering::Less) {
                    return Err(SampleError::Invalid(format!(
                        "the limits of {} are empty ([{lo}, {hi}]): give a lower limit below the upper one",
                        coords[k].name
                    )));
                }
                let (rlo, rhi) = coords[k].range;
                // A unit conversion's rounding (180° as π) is not "outside": clamped below.
                let slack = |x: f64| 1e-12 * x.abs().max(1.0);
                if lo < rlo - slack(rlo) || hi > rhi + slack(rhi) {
                    return Err(SampleError::Invalid(format!(
                        "the limits of {} ([{lo}, {hi}], atomic units) reach outside its valid range [{rlo}, {rhi}]: \
                         give limits within the range",
                        coords[k].name
                    )));
                }
                (lo, hi)
            }
            None => match coords[k].unit {
                CoordinateUnit::Length(_) => (0.0, f64::INFINITY),
                CoordinateUnit::Angle(_) => {
                    // ln det M along the coordinate, None where the metric is singular or the
                    // positions are not defined.
                    let log_det = |t: f64| {
                        let mut q = *centre;
                        q[k] += t;
                        let mut kin = KineticMatrices::default();
                        molecule.kinetic(&q, &mut kin);
                        MetricFactor::new(&kin, &q).ok()?;
                        MetricCholesky::new(&kin).map(|c| 2.0 * (c.half_log_det_i + c.half_log_det_s))
                    };
                    let at_centre = log_det(0.0).unwrap_or(f64::NAN);
                    let scan = |dir: f64| {
                        let (mut t, mut previous) = (0.0, at_centre);
                        let mut falling = false;
                        while t < std::f64::consts::PI {
                            let next = (t + 0.01).min(std::f64::consts::PI);
                            let Some(ld) = log_det(dir * next) else { break };
                            // A minimum of det M far below its value at the centre is a
                            // singular geometry stepped over (a bond angle through π).
                            if falling && ld > previous && previous < at_centre + SINGULAR_LOG_DET {
                                break;
                            }
                            falling = ld < previous;
                            (t, previous) = (next, ld);
                        }
                        t
                    };
                    (centre[k] - scan(-1.0), centre[k] + scan(1.0))
                }
            },
        };
        // Never beyond the coordinate's valid range (a bond angle stays in [0, π]: beyond it
        // the same geometry would be drawn twice, once as its mirror image).
        low[k] = lo.max(coords[k].range.0);
        high[k] = hi.min(coords[k].range.1);
        if low[k].partial_cmp(&high[k]) != Some(std::cmp::Ordering::Less) {
            return Err(SampleError::Invalid(format!(
                "{} has no room to vary: the box [{lo}, {hi}] meets its valid range [{}, {}] in at most a point",
                coords[k].name, coords[k].range.0, coords[k].range.1
            )));
        }
    }
    let u_cap = match (region.energy_cap, molecule.reference_geometry()) {
        (Some(cap), Some(r)) => Some(molecule.potential(&r) + cap),
        (Some(_), None) => {
            return Err(SampleError::Invalid(format!(
                "an energy cap is relative to the reference geometry, which {} does not give",
                molecule.name()
            )));
        }
        (None, _) => None,
    };
    Ok(Bounds { low, high, u_cap })
}

impl<'m, M, const N: usize, const NA: usize> Configuration<'m, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// Builds the sampler: candidate proposals about `centre` (Gaussians of covariance
    /// `s·kt_eff·F⁻¹` for s from 0.5 to 5, when F is positive definite; uniform when the box is
    /// finite), each with its envelope; keeps the one with the best acceptance.
    pub fn new(
        molecule: &'m M,
        target: Target,
        bounds: Bounds<N>,
        centre: SVector<f64, N>,
        hessian: Option<SMatrix<f64, N, N>>,
        kt_eff: f64,
    ) -> Result<Self, SampleError> {
        let u_centre = molecule.potential(&centre);
        let mut this = Self {
            molecule,
            target,
            low: bounds.low,
            high: bounds.high,
            u_cap: bounds.u_cap,
            u_shift: if u_centre.is_finite() { u_centre } else { 0.0 },
            proposal: Proposal::Uniform,
            log_bound: 0.0,
            acceptance: 0.0,
            u_min: f64::INFINITY,
        };
        let finite_box = (0..N).all(|k| this.low[k].is_finite() && this.high[k].is_finite());
        let candidates = this.candidates(centre, hessian, kt_eff, finite_box);
        let mut best: Option<(f64, f64, Proposal<N>)> = None;
        let mut u_min = f64::INFINITY;
        if let Some(p) = this.evaluate(&centre, &Vector3::z()) {
            u_min = p.0.u;
        }
        for (i, proposal) in candidates.into_iter().enumerate() {
            this.proposal = proposal.clone();
            let Some((acceptance, log_bound)) = this.envelope(i as u64, finite_box, &mut u_min) else { continue };
            if best.as_ref().is_none_or(|b| acceptance > b.0) {
                best = Some((acceptance, log_bound, proposal));
            }
        }
        let Some((acceptance, log_bound, proposal)) = best else {
            return Err(SampleError::Invalid(
                "no configuration with a non-zero density was found in the region: widen the coordinate limits or \
                 raise the energy (or the energy cap)"
                    .into(),
            ));
        };
        if acceptance < MIN_ACCEPTANCE {
            return Err(SampleError::Invalid(format!(
                "rejection sampling of the region would accept about {acceptance:.1e} of its proposals (estimated from \
                 {SEARCH_POINTS} points per proposal tried, with the largest density-to-proposal ratio found), and at \
                 least {MIN_ACCEPTANCE:.0e} is needed (else a draw takes more than {:.0} evaluations): the density is \
                 spread over a region much larger than where it is concentrated, or the potential falls without bound \
                 along some direction; give every length coordinate limits or narrow them, or give a lower energy cap",
                1.0 / MIN_ACCEPTANCE
            )));
        }
        this.proposal = proposal;
        this.log_bound = log_bound;
        this.acceptance = acceptance;
        this.u_min = u_min;
        Ok(this)
    }

    /// The proposals to try: Gaussians about `centre` of covariance `s·kt_eff·F⁻¹` for s from
    /// 0.5 to 5 over the coordinates not drawn uniformly (when that part of F is positive
    /// definite), each also mixed with the uniform box when the box is finite; and the uniform
    /// box itself. Angles whose box spans a whole period are drawn uniformly.
    fn candidates(
        &self,
        centre: SVector<f64, N>,
        hessian: Option<SMatrix<f64, N, N>>,
        kt_eff: f64,
        finite_box: bool,
    ) -> Vec<Proposal<N>> {
        let mut candidates = Vec::new();
        let uniform: [bool; N] = std::array::from_fn(|k| {
            matches!(self.molecule.coordinates()[k].unit, CoordinateUnit::Angle(_))
                && self.high[k] - self.low[k] >= std::f64::consts::TAU - 1e-9
        });
        if let Some(f) = hessian {
            let gaussian: Vec<usize> = (0..N).filter(|&k| !uniform[k]).collect();
            let sub = DMatrix::from_fn(gaussian.len(), gaussian.len(), |i, j| f[(gaussian[i], gaussian[j])]);
            if let Some(sub_inv) = sub.cholesky().map(|c| c.inverse()) {
                for s in [0.5, 0.75, 1.0, 1.5, 2.25, 3.4, 5.0] {
                    let mut cov = SMatrix::<f64, N, N>::identity();
                    for (i, &a) in gaussian.iter().enumerate() {
                        for (j, &b) in gaussian.iter().enumerate() {
                            cov[(a, b)] = s * kt_eff * sub_inv[(i, j)];
                        }
                    }
                    if let Some(c) = cov.cholesky() {
                        let l = c.l();
                        candidates.push(Proposal::Gaussian { centre, l, uniform, box_weight: 0.0, log_box: 0.0 });
                        if finite_box {
                            let w = BOX_WEIGHT;
                            let log_box = w.ln()
                                + gaussian
                                    .iter()
                                    .map(|&k| {
                                        l[(k, k)].abs().ln() + 0.5 * std::f64::consts::TAU.ln()
                                            - (self.high[k] - self.low[k]).ln()
                                    })
                                    .sum::<f64>();
                            candidates.push(Proposal::Gaussian { centre, l, uniform, box_weight: w, log_box });
                        }
                    }
                }
            }
        }
        if finite_box {
            candidates.push(Proposal::Uniform);
        }
        candidates
    }

    /// The current proposal's estimated acceptance and log envelope (with the safety factor),
    /// from `SEARCH_POINTS` draws of stream `i` and a search for the largest density-to-proposal
    /// ratio; `None` when no draw had a non-zero density. Lowers `u_min` to the lowest energy met.
    fn envelope(&self, i: u64, finite_box: bool, u_min: &mut f64) -> Option<(f64, f64)> {
        let mut rng = stream(0x005e_ed0f_e4e1_09e5, i);
        let mut points: Vec<(f64, SVector<f64, N>)> = Vec::with_capacity(SEARCH_POINTS);
        let mut sum = 0.0;
        let mut max = f64::NEG_INFINITY;
        let mut ratios = Vec::with_capacity(SEARCH_POINTS);
        for _ in 0..SEARCH_POINTS {
            let (x, q) = self.propose(&mut rng);
            let j_dir = uniform_direction(&mut rng);
            let (log_r, u) = match self.evaluate(&q, &j_dir) {
                Some((p, log_t)) => (log_t - self.log_proposal(&x), p.u),
                None => (f64::NEG_INFINITY, f64::INFINITY),
            };
            *u_min = u_min.min(u);
            ratios.push(log_r);
            max = max.max(log_r);
            let worst = self.search_objective(&x);
            points.push((worst, x));
        }
        if !max.is_finite() {
            return None;
        }
        // Exploration beyond the proposal's bulk, where the ratio can rise again (a Morse
        // bond softer than its harmonic proposal): points from the proposal at three times
        // its width and, in a finite box, uniform in the box.
        for _ in 0..SEARCH_POINTS {
            let (mut x, _) = self.propose(&mut rng);
            if let Proposal::Gaussian { uniform, .. } = &self.proposal {
                for k in 0..N {
                    if !uniform[k] {
                        x[k] *= 3.0;
                    }
                }
            }
            points.push((self.search_objective(&x), x));
            if finite_box
                && let Some(x) = self
                    .x_of(&SVector::from_fn(|k, _| self.low[k] + (self.high[k] - self.low[k]) * rng.random::<f64>()))
            {
                points.push((self.search_objective(&x), x));
            }
        }
        // The envelope: the largest worst-case ratio found, improved by a pattern search.
        points.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut top = points[0].0.max(max);
        for (v, x) in points.iter().take(SEARCH_STARTS) {
            if v.is_finite() {
                top = top.max(self.pattern_search(*x, *v));
            }
        }
        for &r in &ratios {
            if r.is_finite() {
                sum += (r - top).exp();
            }
        }
        Some((sum / SEARCH_POINTS as f64 / SAFETY, top + SAFETY.ln()))
    }

    /// A proposal: the proposal coordinates x (z for a Gaussian, q for uniform) and q.
    fn propose(&self, rng: &mut TrajectoryRng) -> (SVector<f64, N>, SVector<f64, N>) {
        match &self.proposal {
            Proposal::Gaussian { box_weight, .. } if *box_weight > 0.0 && rng.random::<f64>() < *box_weight => {
                let q =
                    SVector::<f64, N>::from_fn(|k, _| self.low[k] + (self.high[k] - self.low[k]) * rng.random::<f64>());
                (self.x_of(&q).unwrap_or_else(|| SVector::from_element(f64::NAN)), q)
            }
            Proposal::Gaussian { centre, l, uniform, .. } => {
                let mut z = SVector::<f64, N>::from_fn(|_, _| rng.sample(StandardNormal));
                for k in 0..N {
                    if uniform[k] {
                        z[k] = self.low[k] + (self.high[k] - self.low[k]) * rng.random::<f64>();
                    }
                }
                (z, self.gaussian_q(centre, l, uniform, &z))
            }
            Proposal::Uniform => {
                let q =
                    SVector::<f64, N>::from_fn(|k, _| self.low[k] + (self.high[k] - self.low[k]) * rng.random::<f64>());
                (q, q)
            }
        }
    }

    /// q of the proposal coordinates x: `centre + l z` with z = x on the Gaussian coordinates
    /// (the Cholesky factor of the block-diagonal covariance does not mix the two kinds), x
    /// itself on the uniform ones.
    fn gaussian_q(
        &self,
        centre: &SVector<f64, N>,
        l: &SMatrix<f64, N, N>,
        uniform: &[bool; N],
        x: &SVector<f64, N>,
    ) -> SVector<f64, N> {
        let z = SVector::<f64, N>::from_fn(|k, _| if uniform[k] { 0.0 } else { x[k] });
        let mut q = centre + l * z;
        for k in 0..N {
            if uniform[k] {
                q[k] = x[k];
            }
        }
        q
    }

    /// The proposal coordinates of q (the inverse of [`Self::q_of`]).
    fn x_of(&self, q: &SVector<f64, N>) -> Option<SVector<f64, N>> {
        match &self.proposal {
            Proposal::Gaussian { centre, l, uniform, .. } => {
                let d = SVector::<f64, N>::from_fn(|k, _| if uniform[k] { 0.0 } else { q[k] - centre[k] });
                let mut z = l.solve_lower_triangular(&d)?;
                for k in 0..N {
                    if uniform[k] {
                        z[k] = q[k];
                    }
                }
                Some(z)
            }
            Proposal::Uniform => Some(*q),
        }
    }

    fn q_of(&self, x: &SVector<f64, N>) -> SVector<f64, N> {
        match &self.proposal {
            Proposal::Gaussian { centre, l, uniform, .. } => self.gaussian_q(centre, l, uniform, x),
            Proposal::Uniform => *x,
        }
    }

    fn log_proposal(&self, x: &SVector<f64, N>) -> f64 {
        match &self.proposal {
            Proposal::Gaussian { uniform, box_weight, log_box, .. } => {
                let gauss = -0.5 * (0..N).filter(|&k| !uniform[k]).map(|k| x[k] * x[k]).sum::<f64>();
                if *box_weight > 0.0 {
                    let (a, b) = ((1.0 - box_weight).ln() + gauss, *log_box);
                    let top = a.max(b);
                    top + ((a - top).exp() + (b - top).exp()).ln()
                } else {
                    gauss
                }
            }
            Proposal::Uniform => 0.0,
        }
    }

    /// `ln r` at x with the direction of J that maximises the target (for fixed |J|: J along
    /// the axis of the largest moment of inertia), an upper bound over directions.
    fn search_objective(&self, x: &SVector<f64, N>) -> f64 {
        let q = self.q_of(x);
        let dir = match self.target {
            Target::ShellFixedJ { .. } => {
                let mut kin = KineticMatrices::default();
                self.molecule.kinetic(&q, &mut kin);
                let e = kin.inertia.symmetric_eigen();
                let imax = e.eigenvalues.imax();
                e.eigenvectors.column(imax).into_owned()
            }
            _ => Vector3::z(),
        };
        match self.evaluate(&q, &dir) {
            Some((_, log_t)) => log_t - self.log_proposal(x),
            None => f64::NEG_INFINITY,
        }
    }

    /// Maximises [`Self::search_objective`] from x by a compass search: steps ±h_k along each
    /// proposal coordinate, a step that improves grows by 1.5 (so that a ratio rising towards
    /// the edge of the region, or without bound, is followed there quickly), all steps halve
    /// when none improves; 80 rounds.
    fn pattern_search(&self, mut x: SVector<f64, N>, mut value: f64) -> f64 {
        let mut h = SVector::<f64, N>::from_fn(|k, _| match self.proposal {
            Proposal::Gaussian { uniform, .. } if !uniform[k] => 0.5,
            _ => 0.05 * (self.high[k] - self.low[k]),
        });
        for _ in 0..80 {
            let mut improved = false;
            for k in 0..N {
                for sign in [1.0, -1.0] {
                    let mut y = x;
                    y[k] += sign * h[k];
                    let v = self.search_objective(&y);
                    if v > value {
                        (x, value, improved) = (y, v, true);
                        h[k] *= 1.5;
                        break;
                    }
                }
            }
            if !improved {
                h *= 0.5;
            }
        }
        value
    }

    /// The point at q (None where the density is zero: outside the region, a singular metric,
    /// a non-finite potential, or no kinetic energy left on a shell) and its log target.
    fn evaluate(&self, q: &SVector<f64, N>, j_dir: &Vector3<f64>) -> Option<(Point<N>, f64)> {
        if (0..N).any(|k| !(q[k] >= self.low[k] && q[k] <= self.high[k])) {
            return None;
        }
        let u = self.molecule.potential(q);
        if !u.is_finite() || self.u_cap.is_some_and(|c| u > c) {
            return None;
        }
        let mut kinetic = KineticMatrices::default();
        self.molecule.kinetic(q, &mut kinetic);
        let chol = MetricCholesky::new(&kinetic)?;
        let log_t = match self.target {
            Target::Boltzmann { kt, metric } => {
                -(u - self.u_shift) / kt + if metric { chol.half_log_det_i + chol.half_log_det_s } else { 0.0 }
            }
            Target::Shell { energy, power } => {
                let k = energy - u;
                if k <= 0.0 {
                    return None;
                }
                chol.half_log_det_i + chol.half_log_det_s + power * k.ln()
            }
            Target::ShellFixedJ { energy, j, power } => {
                let k = energy - u - chol.rotational_energy(&(j_dir * j));
                if k <= 0.0 {
                    return None;
                }
                chol.half_log_det_s + power * k.ln()
            }
        };
        log_t.is_finite().then_some((Point { q: *q, u, chol, kinetic, j_dir: *j_dir }, log_t))
    }

    /// `ln ∫ e^{−U(q)/kT} √det M(q) dq` over the region (U from the potential's own zero) and the
    /// standard error of the estimate relative to the integral, for the Boltzmann target with
    /// the metric factor (None for any other target): importance sampling with the proposal the
    /// rejection uses, `∫ t dq = C · E_φ[t/φ̃]`, where φ̃ is the unnormalised proposal and `C`
    /// its normaliser (a Gaussian's `(2π)^{d/2} det l` times the uniform angles' widths, or the
    /// box volume), from `points` proposals of `rng`.
    pub fn log_integral(&self, rng: &mut TrajectoryRng, points: usize) -> Option<(f64, f64)> {
        let Target::Boltzmann { kt, metric: true } = self.target else { return None };
        let log_c = match &self.proposal {
            Proposal::Gaussian { l, uniform, .. } => (0..N)
                .map(|k| {
                    if uniform[k] {
                        (self.high[k] - self.low[k]).ln()
                    } else {
                        l[(k, k)].abs().ln() + 0.5 * std::f64::consts::TAU.ln()
                    }
                })
                .sum::<f64>(),
            Proposal::Uniform => (0..N).map(|k| (self.high[k] - self.low[k]).ln()).sum::<f64>(),
        };
        // Ratios relative to the envelope (at most 1 where the envelope holds): no overflow.
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..points {
            let (x, q) = self.propose(rng);
            let r = match self.evaluate(&q, &Vector3::z()) {
                Some((_, log_t)) => (log_t - self.log_proposal(&x) - self.log_bound).exp(),
                None => 0.0,
            };
            sum += r;
            sum2 += r * r;
        }
        let n = points.max(2) as f64;
        let mean = sum / n;
        if mean.is_nan() || mean <= 0.0 {
            return None;
        }
        let variance = (sum2 / n - mean * mean).max(0.0) * n / (n - 1.0);
        let log = log_c + mean.ln() + self.log_bound - self.u_shift / kt;
        Some((log, (variance / n).sqrt() / mean))
    }

    /// One configuration from the trajectory's stream.
    pub fn draw(&self, rng: &mut TrajectoryRng) -> Result<Point<N>, SampleError> {
        for _ in 0..MAX_TRIES {
            let (x, q) = self.propose(rng);
            let j_dir = match self.target {
                Target::ShellFixedJ { .. } => uniform_direction(rng),
                _ => Vector3::zeros(),
            };
            let accept: f64 = 1.0 - rng.random::<f64>();
            let Some((point, log_t)) = self.evaluate(&q, &j_dir) else { continue };
            let log_r = log_t - self.log_proposal(&x);
            if log_r > self.log_bound {
                return Err(SampleError::Invalid(format!(
                    "the rejection envelope is exceeded at q = {:?} (the density there is {:.2} times the bound found \
                     when the sampler was built): give tighter coordinate limits or a lower energy cap",
                    q.as_slice(),
                    (log_r - self.log_bound).exp()
                )));
            }
            if accept.ln() < log_r - self.log_bound {
                return Ok(point);
            }
        }
        Err(SampleError::Invalid(format!(
            "no configuration accepted in {MAX_TRIES} proposals: give tighter coordinate limits or a lower energy cap"
        )))
    }
}
