//! The production system: Hamilton's equations in the body formulation ([`BodyState`]),
//! restricted at run time to what a scene needs ([`Reduction`]: frozen internal coordinates,
//! `J = 0`, the orientation only when an output needs it), as an [`OdeSystem`]
//! ([`ReducedSystem`]).

use nalgebra::{Quaternion, SVector, UnitQuaternion, Vector3};

use super::body::{BodyState, momenta_from_velocities, quaternion_of_euler};
use super::factor::MetricFactor;
use super::fast::velocities_and_force;
use super::finite::{all_finite, finite};
use super::metric::PIVOT_TOLERANCE;
use super::{HamiltonianError, PhaseState};
use crate::integrate::OdeSystem;
use crate::molecule::{KineticMatrices, Molecule};

/// What a [`ReducedSystem`] integrates of the overall rotation.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum RotationPart {
    /// Everything: the orientation (a quaternion) and the body-frame angular momentum `J`.
    Free,
    /// Zero angular momentum: `J = 0` exactly for all time (`J̇ = J × ω`), so `J` is not stored;
    /// the orientation is integrated only if `orientation` is true, for lab-frame output (a
    /// molecule with `J = 0` still turns as it vibrates).
    ZeroAngularMomentum {
        /// Whether to integrate the orientation.
        orientation: bool,
    },
}

/// Which parts of phase space a [`ReducedSystem`] integrates, chosen at run time.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Reduction<const N: usize> {
    /// `active[k]` is false for an internal coordinate frozen at its value (zero velocity).
    pub active: [bool; N],
    /// What is integrated of the overall rotation.
    pub rotation: RotationPart,
}

impl<const N: usize> Reduction<N> {
    /// Nothing reduced: the same motion as [`super::FastSystem`], in the body formulation.
    pub fn none() -> Self {
        Self { active: [true; N], rotation: RotationPart::Free }
    }

    /// `J = 0`, all internal coordinates active; the orientation integrated if asked for.
    pub fn zero_angular_momentum(orientation: bool) -> Self {
        Self { active: [true; N], rotation: RotationPart::ZeroAngularMomentum { orientation } }
    }

    /// The coordinates with `active[k] == false` frozen, rotation free.
    pub fn frozen(active: [bool; N]) -> Self {
        Self { active, rotation: RotationPart::Free }
    }

    /// The coordinates called `frozen` (names as in [`Kinematics::coordinates`](crate::molecule::Kinematics::coordinates)) frozen, rotation
    /// free: how a scene that names coordinates picks them at run time.
    pub fn freezing<M, const NA: usize>(molecule: &M, frozen: &[&str]) -> Result<Self, ReductionError>
    where
        M: Molecule<N, NA> + ?Sized,
    {
        let coords = molecule.coordinates();
        let mut active = [true; N];
        for name in frozen {
            let k = coords.iter().position(|c| c.name == *name).ok_or_else(|| ReductionError::UnknownCoordinate {
                name: (*name).to_owned(),
                known: coords.iter().map(|c| c.name).collect(),
            })?;
            active[k] = false;
        }
        Ok(Self::frozen(active))
    }

    /// The number of active internal coordinates.
    pub fn active_count(&self) -> usize {
        self.active.iter().filter(|&&a| a).count()
    }

    /// Whether the orientation is integrated.
    pub fn orientation(&self) -> bool {
        matches!(self.rotation, RotationPart::Free | RotationPart::ZeroAngularMomentum { orientation: true })
    }

    /// The dimension of the flat state: `2 n_active + 4 (orientation) + 3 (J)`.
    pub fn dim(&self) -> usize {
        2 * self.active_count()
            + if self.orientation() { 4 } else { 0 }
            + if self.rotation == RotationPart::Free { 3 } else { 0 }
    }
}

/// Why a [`Reduction`] cannot be built, or a full state cannot be mapped onto a
/// [`ReducedSystem`]'s flat state.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ReductionError {
    /// The flat slice has the wrong length.
    #[error("the reduced state has {found} components, expected {expected}")]
    DimensionMismatch {
        /// The system's dimension.
        expected: usize,
        /// The length that was passed.
        found: usize,
    },
    /// A J = 0 system was given a state with non-zero angular momentum.
    #[error("the state has angular momentum J = {j:?}, but this system has zero angular momentum")]
    NonzeroAngularMomentum {
        /// The state's body-frame `J`.
        j: [f64; 3],
    },
    /// [`Reduction::freezing`] was given a name the molecule has no coordinate of.
    #[error("no internal coordinate is called {name:?} (the coordinates are {known:?})")]
    UnknownCoordinate {
        /// The name that was given.
        name: String,
        /// The molecule's coordinate names.
        known: Vec<&'static str>,
    },
    /// A frozen coordinate of the state differs from the value the system holds it at.
    #[error("frozen coordinate q[{index}] is {found} in the state but held at {held}")]
    FrozenCoordinateMoved {
        /// Its index in q.
        index: usize,
        /// Its value in the state.
        found: f64,
        /// The value the system holds.
        held: f64,
    },
    /// A phase-space state at gimbal lock, whose `p_e` does not determine `J`.
    #[error(transparent)]
    Hamiltonian(#[from] HamiltonianError),
}

/// Hamilton's equations in the body formulation, restricted by a [`Reduction`], as an
/// [`OdeSystem`]: the production path, free of the Euler-angle singularity.
///
/// # Equations
///
/// With `J` the body-frame angular momentum and `ς` the unit quaternion of the orientation,
///
/// ```text
/// (ω, q̇) = M(q)⁻¹ (J, p)                 the fast path's factorization
/// ṗ      = ∂T/∂q|_(ω, q̇) − ∂U/∂q          as in the fast path (J does not depend on q)
/// J̇      = J × ω                          L = R J is constant in the lab: 0 = Ṙ J + R J̇, Ṙ = R [ω]×
/// ς̇      = ½ ς ⊗ (0, ω)                   the same Ṙ = R [ω]× for quaternions
/// ```
///
/// These are the G-matrix path's equations with `(Ω_e, p_e)` replaced by `(ς, J = W p_e)`: the
/// Hamiltonian `H = ½ (J, p)ᵀ M⁻¹ (J, p) + U` is the same function, and the tests compare both
/// the right-hand side (through the chain rule) and trajectories with the G-matrix path. The
/// quaternion never feeds back into `q`, `p` or `J`, so its norm (conserved by the exact flow,
/// to the tolerance by DOP853, to rounding by Gauss–Legendre, for which `|ς|²` and `|J|²` are
/// quadratic invariants) only affects the orientation, which is always normalised before use.
///
/// # Flat layout
///
/// ```text
/// [ q_a … | p_a … | ς_w ς_x ς_y ς_z (if the orientation is integrated) | J_x J_y J_z (if RotationPart::Free) ]
/// ```
///
/// where `q_a`, `p_a` are the active coordinates and their momenta in coordinate order
/// (dimension [`Reduction::dim`]). Frozen coordinates stay at the values of the `template`
/// state given to [`ReducedSystem::new`] with zero velocity; when the orientation is not
/// integrated, [`ReducedSystem::expand`] reports the template's.
///
/// # The reduced Hamiltonian
///
/// `H_red = ½ bᵀ M_red⁻¹ b + U(q)` with `b = (J, p_a)` (`J = 0` for a J = 0 system) and `M_red`
/// the full metric with the frozen rows and columns deleted: the Legendre transform of the
/// Lagrangian with the frozen velocities set to zero. Its `p_a` and `J` are the full system's
/// momenta at those velocities.
///
/// # Conditioning
///
/// [`ReducedSystem::with_min_pivot`] sets the smallest relative pivot of the metric the system
/// accepts (default [`PIVOT_TOLERANCE`]); below it every evaluation fails with
/// [`HamiltonianError::IllConditionedMetric`] naming the block and q, so a run stops, with the
/// time, before a near-singular geometry degrades the numbers.
#[derive(Debug)]
pub struct ReducedSystem<'a, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'a M,
    reduction: Reduction<N>,
    /// Frozen q values, and the orientation when it is not integrated.
    template: BodyState<N>,
    /// `index[s]` for `s < n_active`: the coordinate stored in slot `s`.
    index: [usize; N],
    n_active: usize,
    all_active: bool,
    /// Nothing reduced and the molecule has exact lane forms ([`super::lanes::available`]):
    /// [`OdeSystem::rhs`] takes the lane-generic production code at `f64`.
    production_lanes: bool,
    min_pivot: f64,
}

// By hand: a derive would require `M: Clone`, but only a reference to the molecule is held.
impl<M: ?Sized, const N: usize, const NA: usize> Clone for ReducedSystem<'_, M, N, NA> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M: ?Sized, const N: usize, const NA: usize> Copy for ReducedSystem<'_, M, N, NA> {}

/// Where the blocks of a reduced flat state start.
#[derive(Copy, Clone)]
struct Offsets {
    p: usize,
    quaternion: Option<usize>,
    j: Option<usize>,
    dim: usize,
}

/// An unpacked reduced state: full-length q and p, the (not necessarily unit) quaternion, J.
struct Unpacked<const N: usize> {
    q: SVector<f64, N>,
    p: SVector<f64, N>,
    quaternion: Quaternion<f64>,
    j: Vector3<f64>,
}

impl<'a, M, const N: usize, const NA: usize> ReducedSystem<'a, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The reduced system of `molecule`; `template` supplies the frozen coordinates' values and
    /// the orientation reported when it is not integrated (its momenta are not used, and its
    /// Euler angles may be at gimbal lock).
    pub fn new(molecule: &'a M, reduction: Reduction<N>, template: &PhaseState<N>) -> Self {
        let template = BodyState {
            q: template.q,
            p: SVector::zeros(),
            orientation: quaternion_of_euler(&template.euler),
            j: Vector3::zeros(),
        };
        Self::from_body(molecule, reduction, &template)
    }

    /// [`ReducedSystem::new`] with a body-formulation template.
    pub fn from_body(molecule: &'a M, reduction: Reduction<N>, template: &BodyState<N>) -> Self {
        let mut index = [0; N];
        let mut n_active = 0;
        for k in 0..N {
            if reduction.active[k] {
                index[n_active] = k;
                n_active += 1;
            }
        }
        Self {
            molecule,
            reduction,
            template: *template,
            index,
            n_active,
            all_active: n_active == N,
            production_lanes: n_active == N
                && reduction.rotation == RotationPart::Free
                && super::lanes::available(molecule),
            min_pivot: PIVOT_TOLERANCE,
        }
    }

    /// The same system, failing with [`HamiltonianError::IllConditionedMetric`] wherever a
    /// relative pivot of the metric is below `min_pivot` (see [`MetricFactor::with_tolerance`]).
    pub fn with_min_pivot(mut self, min_pivot: f64) -> Self {
        self.min_pivot = min_pivot;
        self
    }

    /// The molecule.
    pub fn molecule(&self) -> &'a M {
        self.molecule
    }

    /// The reduction.
    pub fn reduction(&self) -> &Reduction<N> {
        &self.reduction
    }

    fn offsets(&self) -> Offsets {
        let p = self.n_active;
        let mut next = 2 * self.n_active;
        let quaternion = self.reduction.orientation().then(|| {
            next += 4;
            next - 4
        });
        let j = (self.reduction.rotation == RotationPart::Free).then(|| {
            next += 3;
            next - 3
        });
        Offsets { p, quaternion, j, dim: next }
    }

    /// The full `q`, `p` (zero for frozen coordinates), quaternion and `J` of a flat state.
    #[inline]
    fn unpack(&self, y: &[f64], o: &Offsets) -> Unpacked<N> {
        let mut u = Unpacked {
            q: self.template.q,
            p: SVector::zeros(),
            quaternion: *self.template.orientation.quaternion(),
            j: Vector3::zeros(),
        };
        for (slot, &k) in self.index[..self.n_active].iter().enumerate() {
            u.q[k] = y[slot];
            u.p[k] = y[o.p + slot];
        }
        if let Some(i) = o.quaternion {
            u.quaternion = Quaternion::new(y[i], y[i + 1], y[i + 2], y[i + 3]);
        }
        if let Some(i) = o.j {
            u.j = Vector3::new(y[i], y[i + 1], y[i + 2]);
        }
        u
    }

    /// Kinetic matrices with the frozen rows and columns of `M` replaced by those of the
    /// identity: `a_fj = a_jf = δ_fj`, `A_·f = 0`. The metric is then block diagonal (after a
    /// permutation) as `M_red ⊕ 1`, so `M⁻¹ (J, p)` with `p_f = 0` gives `q̇_f = 0` exactly and
    /// the active block `M_red⁻¹ (J, p_a)`.
    #[inline]
    fn masked(&self, k: &KineticMatrices<N>) -> KineticMatrices<N> {
        let mut k = *k;
        for f in 0..N {
            if !self.reduction.active[f] {
                for j in 0..N {
                    k.a[(f, j)] = 0.0;
                    k.a[(j, f)] = 0.0;
                }
                k.a[(f, f)] = 1.0;
                for r in 0..3 {
                    k.coriolis[(r, f)] = 0.0;
                }
            }
        }
        k
    }

    /// The unpacked state, after checking the slice.
    #[inline]
    fn checked_unpack(&self, y: &[f64], o: &Offsets) -> Result<Unpacked<N>, HamiltonianError> {
        if y.len() != o.dim {
            return Err(HamiltonianError::DimensionMismatch { expected: o.dim, found: y.len() });
        }
        if !all_finite(y) {
            return Err(HamiltonianError::NonFinite { quantity: "state (q, p, orientation, J)" });
        }
        Ok(self.unpack(y, o))
    }

    /// `(ω, q̇) = M_red⁻¹ (J, p)` from the kinetic matrices at `u.q`.
    #[inline(always)]
    fn solve(
        &self,
        k: &KineticMatrices<N>,
        u: &Unpacked<N>,
        o: &Offsets,
    ) -> Result<(Vector3<f64>, SVector<f64, N>), HamiltonianError> {
        let masked;
        let k = if self.all_active {
            k
        } else {
            masked = self.masked(k);
            &masked
        };
        let factor = MetricFactor::with_tolerance(k, &u.q, self.min_pivot)?;
        Ok(match o.j {
            Some(_) => factor.solve(&u.j, &u.p),
            None => factor.solve_zero_j(&u.p),
        })
    }

    /// The unpacked state and the velocities `(ω, q̇)`.
    #[inline]
    fn kinematics(
        &self,
        y: &[f64],
        o: &Offsets,
    ) -> Result<(Unpacked<N>, Vector3<f64>, SVector<f64, N>), HamiltonianError> {
        let u = self.checked_unpack(y, o)?;
        let mut k = KineticMatrices::default();
        self.molecule.kinetic(&u.q, &mut k);
        let (omega, qdot) = self.solve(&k, &u, o)?;
        Ok((u, omega, qdot))
    }

    /// `H_red` of the flat state `y`, in hartree: `½ (ω · J + q̇_a · p_a) + U`.
    pub fn energy(&self, y: &[f64]) -> Result<f64, HamiltonianError> {
        let o = self.offsets();
        let (u, omega, qdot) = self.kinematics(y, &o)?;
        self.energy_at(&u, &omega, &qdot)
    }

    /// `½ (ω · J + q̇_a · p_a) + U` at an unpacked state and its velocities.
    fn energy_at(
        &self,
        u: &Unpacked<N>,
        omega: &Vector3<f64>,
        qdot: &SVector<f64, N>,
    ) -> Result<f64, HamiltonianError> {
        let t = 0.5 * (omega.dot(&u.j) + qdot.dot(&u.p));
        let v = finite(self.molecule.potential(&u.q), "potential U(q)")?;
        finite(t + v, "Hamiltonian H")
    }

    /// Writes the reduced flat state of a body-formulation state into `y`: active q and p, and
    /// (as the reduction keeps them) the orientation and `J`. The momenta of frozen coordinates
    /// are not used (the constraint determines them; see [`ReducedSystem::expand`]).
    ///
    /// Fails if `y` has the wrong length, if the state has `J ≠ 0` for a J = 0 system, or if a
    /// frozen coordinate differs from the value the system holds it at.
    pub fn reduce_body(&self, state: &BodyState<N>, y: &mut [f64]) -> Result<(), ReductionError> {
        let o = self.offsets();
        if y.len() != o.dim {
            return Err(ReductionError::DimensionMismatch { expected: o.dim, found: y.len() });
        }
        if o.j.is_none() && state.j != Vector3::zeros() {
            return Err(ReductionError::NonzeroAngularMomentum { j: state.j.into() });
        }
        for k in 0..N {
            let held = self.template.q[k];
            if !self.reduction.active[k] && state.q[k] != held {
                return Err(ReductionError::FrozenCoordinateMoved { index: k, found: state.q[k], held });
            }
        }
        for (slot, &k) in self.index[..self.n_active].iter().enumerate() {
            y[slot] = state.q[k];
            y[o.p + slot] = state.p[k];
        }
        if let Some(i) = o.quaternion {
            let q = state.orientation.quaternion();
            y[i..i + 4].copy_from_slice(&[q.w, q.i, q.j, q.k]);
        }
        if let Some(i) = o.j {
            y[i..i + 3].copy_from_slice(state.j.as_slice());
        }
        Ok(())
    }

    /// [`ReducedSystem::reduce_body`] of a phase-space state (`J = W p_e`: fails at gimbal lock).
    pub fn reduce(&self, state: &PhaseState<N>, y: &mut [f64]) -> Result<(), ReductionError> {
        // A J = 0 system needs no W, so a state at gimbal lock with p_e = 0 is fine.
        let body = if state.pe == Vector3::zeros() {
            BodyState { q: state.q, p: state.p, orientation: quaternion_of_euler(&state.euler), j: Vector3::zeros() }
        } else {
            BodyState::from_phase(state)?
        };
        self.reduce_body(&body, y)
    }

    /// The body-formulation state of a reduced flat state, for output: frozen coordinates at
    /// their held values, `J = 0` for a J = 0 system, the template's orientation if it is not
    /// integrated (the integrated quaternion normalised otherwise), and each frozen coordinate's
    /// momentum the full system's `p_f = ∂T/∂q̇_f = (Aᵀ ω + a q̇)_f` at the reduced velocities
    /// (so that the full system at the expanded state moves the same way, with `q̇_f = 0`).
    pub fn expand_body(&self, y: &[f64]) -> Result<BodyState<N>, HamiltonianError> {
        Ok(self.expand_body_and_energy(y)?.0)
    }

    /// [`ReducedSystem::expand_body`] and [`ReducedSystem::energy`] together, sharing the one
    /// evaluation of the kinetic matrices and the factorization (what output needs at every
    /// output time).
    pub fn expand_body_and_energy(&self, y: &[f64]) -> Result<(BodyState<N>, f64), HamiltonianError> {
        let o = self.offsets();
        let u = self.checked_unpack(y, &o)?;
        let mut k = KineticMatrices::default();
        self.molecule.kinetic(&u.q, &mut k);
        let (omega, qdot) = self.solve(&k, &u, &o)?;
        let energy = self.energy_at(&u, &omega, &qdot)?;
        let mut p = u.p;
        if !self.all_active {
            // `k` is unmasked here: the full system's momenta at the reduced velocities.
            let (_, p_full) = momenta_from_velocities(&k, &omega, &qdot);
            for f in 0..N {
                if !self.reduction.active[f] {
                    p[f] = p_full[f];
                }
            }
        }
        let orientation = UnitQuaternion::try_new(u.quaternion, 0.0)
            .ok_or(HamiltonianError::NonFinite { quantity: "orientation quaternion (zero norm)" })?;
        Ok((BodyState { q: u.q, p, orientation, j: u.j }, energy))
    }

    /// [`ReducedSystem::expand_body`] as a phase-space state ([`BodyState::to_phase`]).
    pub fn expand(&self, y: &[f64]) -> Result<PhaseState<N>, HamiltonianError> {
        Ok(self.expand_body(y)?.to_phase())
    }
}

impl<M, const N: usize, const NA: usize> OdeSystem for ReducedSystem<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    type Error = HamiltonianError;

    fn dim(&self) -> usize {
        self.offsets().dim
    }

    /// `dydt` in the reduced layout: `(q̇_a, ṗ_a, ς̇, J̇)` as the reduction keeps them.
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), HamiltonianError> {
        // Nothing reduced (the common case): the lane-generic production right-hand side at
        // `f64`, with no index maps and one finiteness test; if it fails, the general path
        // below evaluates the state again and names the error. Molecules without exact lane
        // forms (large ones, see `super::lanes::available`) take the general path.
        if self.production_lanes {
            if super::lanes::production_rhs::<M, f64, N, NA>(self.molecule, y, dydt, self.min_pivot) == 1 {
                return Ok(());
            }
            return self.general_rhs_cold(y, dydt);
        }
        self.general_rhs(y, dydt)
    }
}

impl<M, const N: usize, const NA: usize> ReducedSystem<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// [`Self::general_rhs`] out of line: after the specialised path failed.
    #[cold]
    #[inline(never)]
    fn general_rhs_cold(&self, y: &[f64], dydt: &mut [f64]) -> Result<(), HamiltonianError> {
        self.general_rhs(y, dydt)
    }

    /// The right-hand side for any reduction, with an error that names what failed.
    #[inline(always)]
    fn general_rhs(&self, y: &[f64], dydt: &mut [f64]) -> Result<(), HamiltonianError> {
        let o = self.offsets();
        if dydt.len() != o.dim {
            return Err(HamiltonianError::DimensionMismatch { expected: o.dim, found: dydt.len() });
        }
        let u = self.checked_unpack(y, &o)?;
        let (omega, qdot, pdot) = velocities_and_force(self.molecule, &u.q, |k| self.solve(k, &u, &o))?;
        for (slot, &k) in self.index[..self.n_active].iter().enumerate() {
            dydt[slot] = qdot[k];
            dydt[o.p + slot] = pdot[k];
        }
        if let Some(i) = o.quaternion {
            // ς̇ = ½ ς ⊗ (0, ω).
            let d = u.quaternion * Quaternion::from_imag(omega) * 0.5;
            dydt[i..i + 4].copy_from_slice(&[d.w, d.i, d.j, d.k]);
        }
        if let Some(i) = o.j {
            dydt[i..i + 3].copy_from_slice(u.j.cross(&omega).as_slice());
        }
        if !all_finite(dydt) {
            return Err(HamiltonianError::NonFinite { quantity: "right-hand side of Hamilton's equations" });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flat dimension counts `2` per active coordinate, `4` for the quaternion when it is
    /// integrated and `3` for `J` when the rotation is free.
    #[test]
    fn reduction_dimensions_count_what_is_integrated() {
        assert_eq!(Reduction::<3>::none().dim(), 6 + 4 + 3);
        assert_eq!(Reduction::<3>::zero_angular_momentum(true).dim(), 6 + 4);
        assert_eq!(Reduction::<3>::zero_angular_momentum(false).dim(), 6);
        let frozen = Reduction::<3>::frozen([true, false, true]);
        assert_eq!((frozen.active_count(), frozen.dim()), (2, 4 + 4 + 3));
        let all_frozen =
            Reduction { active: [false; 3], rotation: RotationPart::ZeroAngularMomentum { orientation: false } };
        assert_eq!(all_frozen.dim(), 0);
        assert_eq!(Reduction::<0>::none().dim(), 7);
        assert!(Reduction::<2>::zero_angular_momentum(true).orientation());
        assert!(!Reduction::<2>::zero_angular_momentum(false).orientation());
    }
}
