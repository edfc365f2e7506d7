//! The body formulation's state ([`BodyState`]: q, p, the orientation as a unit quaternion and
//! the body-frame angular momentum J), its conversions to and from the Euler-angle phase space,
//! and the Legendre map from velocities to momenta.

use nalgebra::{Matrix3, SVector, UnitQuaternion, Vector3};

use super::euler::EulerTrig;
use super::{HamiltonianError, PhaseState, angular_velocity_matrix, euler_angles};
use crate::molecule::KineticMatrices;

/// The state of the body formulation that [`super::ReducedSystem`] integrates: internal coordinates and
/// momenta, the orientation as a unit quaternion (body → lab, `R = Rz(φ) Rx(θ) Rz(ψ)` of the
/// Euler angles) and the body-frame angular momentum `J = W p_e`.
///
/// Unlike `(Ω_e, p_e)` it has no singular orientation: Euler angles are derived only for output
/// ([`BodyState::to_phase`]), where `p_e = Mᵀ J` is defined even at `θ = 0`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct BodyState<const N: usize> {
    /// Internal coordinates (bohr, rad).
    pub q: SVector<f64, N>,
    /// Their conjugate momenta.
    pub p: SVector<f64, N>,
    /// Body → lab rotation.
    pub orientation: UnitQuaternion<f64>,
    /// Body-frame angular momentum, ħ.
    pub j: Vector3<f64>,
}

impl<const N: usize> BodyState<N> {
    /// From a phase-space state: the quaternion of the Euler angles and `J = W p_e`; fails at
    /// gimbal lock, where `p_e` does not determine `J`.
    pub fn from_phase(s: &PhaseState<N>) -> Result<Self, HamiltonianError> {
        let j = EulerTrig::new(&s.euler)?.j(&s.pe);
        Ok(Self { q: s.q, p: s.p, orientation: quaternion_of_euler(&s.euler), j })
    }

    /// To a phase-space state, for output: Euler angles of the rotation (`θ ∈ [0, π]`; at
    /// `sin θ = 0` the split of `φ ± ψ` is arbitrary) and `p_e = Mᵀ J`, which needs no division.
    pub fn to_phase(&self) -> PhaseState<N> {
        let euler = euler_angles(self.orientation.to_rotation_matrix().matrix());
        PhaseState { q: self.q, p: self.p, euler, pe: angular_velocity_matrix(&euler).transpose() * self.j }
    }

    /// The body → lab rotation matrix.
    pub fn rotation(&self) -> Matrix3<f64> {
        *self.orientation.to_rotation_matrix().matrix()
    }
}

/// The unit quaternion of `R = Rz(φ) Rx(θ) Rz(ψ)`.
pub fn quaternion_of_euler(euler: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), euler[0])
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), euler[1])
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), euler[2])
}

/// The momenta conjugate to the velocities `(ω, q̇)`: `(J, p) = M (ω, q̇)` with the kinetic metric
/// `M = [[I, A], [Aᵀ, a]]` of `k`, i.e. `J = I ω + A q̇` and `p = Aᵀ ω + a q̇` (the Legendre map
/// `p = ∂T/∂q̇`; ħ/bohr or ħ, and ħ for J). Returns `(J, p)`.
pub fn momenta_from_velocities<const N: usize>(
    k: &KineticMatrices<N>,
    omega: &Vector3<f64>,
    qdot: &SVector<f64, N>,
) -> (Vector3<f64>, SVector<f64, N>) {
    (k.inertia * omega + k.coriolis * qdot, k.coriolis.transpose() * omega + k.a * qdot)
}
