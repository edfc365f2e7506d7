//! The potential and the dipole as parts of their own, so that a surface can come from anywhere.
//!
//! [`Molecule<N, NA>`] is the whole contract the integrators use: its
//! [`crate::molecule::Kinematics`] (atoms, coordinates, positions, their Jacobian, the kinetic
//! matrices and ∂T/∂q, always generated from a definition), a potential and an optional dipole.
//! This module gives the last two as parts of their own:
//!
//! * a **potential**, [`Potential<N>`]: U(q) and ∂U/∂q, an optional lane form;
//! * a **dipole**, [`Dipole<N>`]: μ(q) and its Jacobian.
//!
//! [`WithPotential<M, P>`] composes them: a full [`Molecule`] whose kinematics (and, unless the
//! potential part brings one, dipole) are `M`'s, forwarded by [`HasKinematics`], and whose
//! potential is `P`'s. The generated code
//! is untouched, so a run of a generated molecule costs what it did; an outside potential costs
//! what its own code costs. [`PotentialOf`] is the other direction: the potential part of a
//! generated molecule, for checking one surface against another.
//!
//! [`check_gradient`] compares a potential's ∂U/∂q with central differences before a run.

use nalgebra::{SMatrix, SVector, Vector3};

use crate::lanes::Real;
use crate::molecule::{Coordinate, HasKinematics, Molecule};

pub use crate::dipole::Dipole;

/// A potential energy surface over `N` internal coordinates (atomic units: q in bohr or
/// radians, U in hartree), in the coordinate order of the molecule it is composed with.
pub trait Potential<const N: usize> {
    /// `U(q)`.
    fn energy(&self, q: &SVector<f64, N>) -> f64;

    /// `∂U/∂q` into `grad` (overwritten); returns `U(q)` as well.
    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64;

    /// Whether [`Potential::energy_gradient_lanes`] is real lane-generic code. `false` (the
    /// default) makes ensembles run one trajectory at a time.
    fn has_lane_form(&self) -> bool {
        false
    }

    /// [`Potential::energy_gradient`] for `T::LANES` states at once; the default calls the `f64`
    /// method lane by lane.
    fn energy_gradient_lanes<T: Real>(&self, q: &[T; N], grad: &mut [T; N]) -> T {
        let mut u = T::splat(0.0);
        for lane in 0..T::LANES {
            let mut g = SVector::zeros();
            u.set_lane(lane, self.energy_gradient(&SVector::from_fn(|i, _| q[i].lane(lane)), &mut g));
            for i in 0..N {
                grad[i].set_lane(lane, g[i]);
            }
        }
        u
    }

    /// A dipole surface that comes with this potential (the same outside code), if any; it then
    /// replaces the molecule's in [`WithPotential`].
    fn dipole_part(&self) -> Option<&dyn Dipole<N>> {
        None
    }
}

impl<P: Potential<N> + ?Sized, const N: usize> Potential<N> for &P {
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        (**self).energy(q)
    }
    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        (**self).energy_gradient(q, grad)
    }
    fn has_lane_form(&self) -> bool {
        (**self).has_lane_form()
    }
    fn energy_gradient_lanes<T: Real>(&self, q: &[T; N], grad: &mut [T; N]) -> T {
        (**self).energy_gradient_lanes(q, grad)
    }
    fn dipole_part(&self) -> Option<&dyn Dipole<N>> {
        (**self).dipole_part()
    }
}

/// The potential part of molecule `M` (its generated `potential` and `potential_gradient`, with
/// the compiled-in parameters), as a [`Potential`]; `NA` is `M`'s number of atoms.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct PotentialOf<M, const NA: usize>(pub M);

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Potential<N> for PotentialOf<M, NA> {
    fn energy(&self, q: &SVector<f64, N>) -> f64 {
        self.0.potential(q)
    }
    fn energy_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        self.0.potential_gradient(q, grad)
    }
    fn has_lane_form(&self) -> bool {
        self.0.has_lane_forms()
    }
    fn energy_gradient_lanes<T: Real>(&self, q: &[T; N], grad: &mut [T; N]) -> T {
        self.0.potential_gradient_lanes(q, grad)
    }
}

/// Molecule `M`'s kinematics with potential `P`: a full [`Molecule`].
///
/// The dipole is `P`'s if it brings one ([`Potential::dipole_part`]), else `M`'s. Lane forms
/// are used only when both parts have them. The potential has no parameters (a scene's
/// `[potential.parameters]` is refused) and no closed form in Cartesian positions
/// (`cartesian_potential` is `None`, so the Cartesian chart is not available).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct WithPotential<M, P> {
    /// The molecule whose kinematics are used.
    pub molecule: M,
    /// The potential that replaces the molecule's.
    pub potential: P,
}

impl<M: Molecule<N, NA>, P, const N: usize, const NA: usize> HasKinematics<N, NA> for WithPotential<M, P> {
    type Kinematics = M;
    fn kinematics(&self) -> &M {
        &self.molecule
    }
}

impl<M, P, const N: usize, const NA: usize> Molecule<N, NA> for WithPotential<M, P>
where
    M: Molecule<N, NA>,
    P: Potential<N>,
{
    fn potential(&self, q: &SVector<f64, N>) -> f64 {
        self.potential.energy(q)
    }
    fn potential_gradient(&self, q: &SVector<f64, N>, grad: &mut SVector<f64, N>) -> f64 {
        self.potential.energy_gradient(q, grad)
    }
    fn has_lane_forms(&self) -> bool {
        self.molecule.has_lane_forms() && self.potential.has_lane_form()
    }
    fn potential_gradient_lanes<T: Real>(&self, q: &[T; N], grad: &mut [T; N]) -> T {
        self.potential.energy_gradient_lanes(q, grad)
    }
    fn dipole(&self) -> Option<impl Dipole<N>> {
        match self.potential.dipole_part() {
            Some(d) => Some(Either::Left(d)),
            None => self.molecule.dipole().map(Either::Right),
        }
    }
}

/// One of two dipole surfaces.
enum Either<A, B> {
    Left(A),
    Right(B),
}

impl<A: Dipole<N>, B: Dipole<N>, const N: usize> Dipole<N> for Either<A, B> {
    fn moment(&self, q: &SVector<f64, N>, mu: &mut Vector3<f64>) {
        match self {
            Self::Left(d) => d.moment(q, mu),
            Self::Right(d) => d.moment(q, mu),
        }
    }
    fn moment_jacobian(&self, q: &SVector<f64, N>, dmu: &mut SMatrix<f64, 3, N>) {
        match self {
            Self::Left(d) => d.moment_jacobian(q, dmu),
            Self::Right(d) => d.moment_jacobian(q, dmu),
        }
    }
}

/// A potential's analytic gradient that disagrees with central differences.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GradientError {
    /// `∂U/∂q_k` disagrees with `(U(q + h e_k) − U(q − h e_k)) / 2h`.
    #[error(
        "∂U/∂{coordinate} = {analytic:e} from the surface, but central differences give {numeric:e} (step {step:e}) \
         at q = {q:?}"
    )]
    Mismatch {
        /// The coordinate's name.
        coordinate: &'static str,
        /// Its index.
        index: usize,
        /// Where (atomic units).
        q: Vec<f64>,
        /// The surface's value.
        analytic: f64,
        /// The central difference.
        numeric: f64,
        /// The step h.
        step: f64,
    },
    /// U or ∂U/∂q is not finite at a point inside the coordinates' ranges.
    #[error("the surface gives U = {energy} and ∂U/∂q = {gradient:?} at q = {q:?}, not finite")]
    NotFinite {
        /// Where (atomic units).
        q: Vec<f64>,
        /// U there.
        energy: f64,
        /// ∂U/∂q there.
        gradient: Vec<f64>,
    },
}

/// How [`check_gradient`] samples and what it accepts.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct GradientCheck {
    /// Random points besides the reference geometry.
    pub points: usize,
    /// The seed of the points.
    pub seed: u64,
    /// Half-width (bohr or rad) of the box around the reference geometry the points are drawn
    /// from, cut to each coordinate's range.
    pub half_width: f64,
    /// The central-difference step, relative to `max(1, |q_k|)`.
    pub step: f64,
    /// Accepted: `|analytic − numeric| ≤ relative · max(|analytic|, |numeric|) + absolute`.
    pub relative: f64,
    /// See `relative` (hartree per unit of q).
    pub absolute: f64,
}

impl Default for GradientCheck {
    fn default() -> Self {
        Self { points: 16, seed: 0x5EED_0027, half_width: 0.5, step: 1e-5, relative: 1e-5, absolute: 1e-9 }
    }
}

/// Checks `p`'s ∂U/∂q against central differences at `centre` (usually the reference geometry)
/// and at `check.points` random points (fixed seed) in the box `centre ± half_width` cut to the
/// coordinates' ranges, pulled in by the step so that every difference stays inside.
pub fn check_gradient<P: Potential<N> + ?Sized, const N: usize>(
    p: &P,
    coordinates: &[Coordinate; N],
    centre: &SVector<f64, N>,
    check: &GradientCheck,
) -> Result<(), GradientError> {
    let mut state = check.seed;
    // splitmix64: a fixed, dependency-free sequence of uniform numbers in [0, 1).
    let mut uniform = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let step = |x: f64| check.step * x.abs().max(1.0);
    let mut points = vec![*centre];
    for _ in 0..check.points {
        points.push(SVector::from_fn(|k, _| {
            let c = &coordinates[k];
            let h = step(centre[k] + check.half_width);
            let low = (centre[k] - check.half_width).max(c.range.0 + 2.0 * h);
            let high = (centre[k] + check.half_width).min(c.range.1 - 2.0 * h);
            if low < high { low + (high - low) * uniform() } else { centre[k] }
        }));
    }
    let mut grad = SVector::zeros();
    let mut scratch = SVector::zeros();
    for q in &points {
        let u = p.energy_gradient(q, &mut grad);
        if !u.is_finite() || grad.iter().any(|g| !g.is_finite()) {
            return Err(GradientError::NotFinite {
                q: q.iter().copied().collect(),
                energy: u,
                gradient: grad.iter().copied().collect(),
            });
        }
        for k in 0..N {
            let h = step(q[k]);
            let (mut plus, mut minus) = (*q, *q);
            plus[k] += h;
            minus[k] -= h;
            let numeric = (p.energy_gradient(&plus, &mut scratch) - p.energy_gradient(&minus, &mut scratch))
                / (plus[k] - minus[k]);
            let analytic = grad[k];
            let tolerance = check.relative * analytic.abs().max(numeric.abs()) + check.absolute;
            // NaN (a difference that left the surface's domain) does not agree.
            let agrees = (analytic - numeric).abs() <= tolerance;
            if !agrees {
                return Err(GradientError::Mismatch {
                    coordinate: coordinates[k].name,
                    index: k,
                    q: q.iter().copied().collect(),
                    analytic,
                    numeric,
                    step: h,
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{CoordinateUnit, LengthUnit};

    struct Quartic {
        wrong: f64,
    }

    impl Potential<2> for Quartic {
        fn energy(&self, q: &SVector<f64, 2>) -> f64 {
            q[0].powi(4) + q[0] * q[1] + 0.5 * q[1] * q[1]
        }
        fn energy_gradient(&self, q: &SVector<f64, 2>, grad: &mut SVector<f64, 2>) -> f64 {
            grad[0] = 4.0 * q[0].powi(3) + q[1];
            grad[1] = (q[0] + q[1]) * self.wrong;
            self.energy(q)
        }
    }

    fn coords() -> [Coordinate; 2] {
        let c = |name| Coordinate {
            name,
            unit: CoordinateUnit::Length(LengthUnit::Bohr),
            reference: Some(1.0),
            range: (0.0, f64::INFINITY),
        };
        [c("x"), c("y")]
    }

    #[test]
    fn a_right_gradient_passes_and_a_wrong_one_is_named() {
        let centre = SVector::from([1.0, 1.0]);
        let check = GradientCheck::default();
        assert_eq!(check_gradient(&Quartic { wrong: 1.0 }, &coords(), &centre, &check), Ok(()));
        match check_gradient(&Quartic { wrong: 1.001 }, &coords(), &centre, &check) {
            Err(GradientError::Mismatch { coordinate: "y", index: 1, analytic, numeric, .. }) => {
                assert!((analytic - 2.002).abs() < 1e-12 && (numeric - 2.0).abs() < 1e-8, "{analytic} {numeric}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn points_stay_inside_the_ranges() {
        // U is NaN outside [0.2, 0.5]: every point and every difference must stay inside.
        struct Boxed;
        impl Potential<2> for Boxed {
            fn energy(&self, q: &SVector<f64, 2>) -> f64 {
                if q.iter().all(|&x| (0.2..=0.5).contains(&x)) { q.norm_squared() } else { f64::NAN }
            }
            fn energy_gradient(&self, q: &SVector<f64, 2>, grad: &mut SVector<f64, 2>) -> f64 {
                *grad = 2.0 * q;
                self.energy(q)
            }
        }
        let mut coordinates = coords();
        for c in &mut coordinates {
            c.range = (0.2, 0.5);
        }
        let centre = SVector::from([0.3, 0.45]);
        let check = GradientCheck { points: 200, ..GradientCheck::default() };
        assert_eq!(check_gradient(&Boxed, &coordinates, &centre, &check), Ok(()));
    }
}
