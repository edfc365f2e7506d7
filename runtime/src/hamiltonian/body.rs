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

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix3, SMatrix};
    use rand::{RngExt as _, SeedableRng as _};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::hamiltonian::{euler_momenta_from_angular_momentum, rotation_matrix, w_matrix};

    fn random_euler(rng: &mut ChaCha8Rng) -> Vector3<f64> {
        use core::f64::consts::PI;
        Vector3::new(rng.random_range(-PI..PI), rng.random_range(0.1..PI - 0.1), rng.random_range(-PI..PI))
    }

    /// The quaternion of the Euler angles is the rotation `Rz(φ) Rx(θ) Rz(ψ)` of
    /// [`rotation_matrix`], written out independently there.
    #[test]
    fn quaternion_of_euler_is_the_euler_rotation() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..100 {
            let euler = random_euler(&mut rng);
            let from_quaternion = *quaternion_of_euler(&euler).to_rotation_matrix().matrix();
            assert!((from_quaternion - rotation_matrix(&euler)).amax() < 1e-14, "{euler:?}");
        }
    }

    /// `from_phase` gives `J = W p_e` and `to_phase` gives back the same rotation and
    /// `p_e = Mᵀ J`; at gimbal lock `from_phase` fails.
    #[test]
    fn phase_and_body_states_convert_both_ways() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..100 {
            let euler = random_euler(&mut rng);
            let pe = Vector3::from_fn(|_, _| rng.random_range(-2.0..2.0));
            let s = PhaseState::<2> { q: SVector::from([1.0, 2.0]), p: SVector::from([0.5, -0.5]), euler, pe };
            let body = BodyState::from_phase(&s).unwrap();
            assert!((body.j - w_matrix(&euler).unwrap() * pe).amax() < 1e-12 * pe.amax() / euler[1].sin());
            let back = body.to_phase();
            assert!((rotation_matrix(&back.euler) - rotation_matrix(&euler)).amax() < 1e-13);
            assert!((back.pe - euler_momenta_from_angular_momentum(&back.euler, &body.j)).amax() < 1e-15);
            assert_eq!((back.q, back.p), (s.q, s.p));
        }
        let locked = PhaseState::<0> {
            q: SVector::zeros(),
            p: SVector::zeros(),
            euler: Vector3::new(0.1, 0.0, 0.2),
            pe: Vector3::new(1.0, 0.0, 0.0),
        };
        assert!(matches!(BodyState::from_phase(&locked), Err(HamiltonianError::EulerSingular { .. })));
    }

    /// The Legendre map is the metric `M = [[I, A], [Aᵀ, a]]` applied to `(ω, q̇)`, assembled as
    /// one 5 × 5 matrix here.
    #[test]
    fn momenta_from_velocities_is_the_metric_times_the_velocities() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let k = KineticMatrices::<2> {
            inertia: Matrix3::from_fn(|_, _| rng.random_range(-1.0..1.0)),
            coriolis: SMatrix::from_fn(|_, _| rng.random_range(-1.0..1.0)),
            a: SMatrix::from_fn(|_, _| rng.random_range(-1.0..1.0)),
        };
        let mut m = SMatrix::<f64, 5, 5>::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&k.inertia);
        m.fixed_view_mut::<3, 2>(0, 3).copy_from(&k.coriolis);
        m.fixed_view_mut::<2, 3>(3, 0).copy_from(&k.coriolis.transpose());
        m.fixed_view_mut::<2, 2>(3, 3).copy_from(&k.a);
        let (omega, qdot) = (Vector3::new(0.3, -1.0, 2.0), SVector::<f64, 2>::new(0.7, -0.2));
        let v = SVector::<f64, 5>::from_iterator(omega.iter().chain(qdot.iter()).copied());
        let b = m * v;
        let (j, p) = momenta_from_velocities(&k, &omega, &qdot);
        assert!((j - b.fixed_rows::<3>(0)).amax() < 1e-15);
        assert!((p - b.fixed_rows::<2>(3)).amax() < 1e-15);
    }
}
