//! The default `Molecule::kinetic_jacobian` (polarization of the kinetic-energy gradient,
//! `runtime/src/polarization.rs`) against the hand-written water's own ∂a/∂q, ∂A/∂q, ∂I/∂q,
//! which come from the closed-form position derivatives in `common` and share nothing with it
//! but the positions.

mod common;

use common::{Rng, Water, random_water_q};
use rovib_runtime::molecule::{Atom, Coordinate, Kinematics, KineticMatrices, Molecule};
use rovib_runtime::nalgebra::{SMatrix, SVector, Vector3};

/// Water with every method but `kinetic_jacobian`, which takes the trait's default.
struct DefaultJacobian;

impl Kinematics<3, 3> for DefaultJacobian {
    fn name(&self) -> &'static str {
        "water-default-jacobian"
    }
    fn source(&self) -> &'static str {
        "runtime/tests/polarization.rs"
    }
    fn atoms(&self) -> [Atom; 3] {
        Water.atoms()
    }
    fn coordinates(&self) -> [Coordinate; 3] {
        Water.coordinates()
    }
    fn positions(&self, q: &SVector<f64, 3>, r: &mut SMatrix<f64, 3, 3>) {
        Water.positions(q, r)
    }
    fn positions_jacobian(&self, q: &SVector<f64, 3>, dr: &mut [SMatrix<f64, 3, 3>; 3]) {
        Water.positions_jacobian(q, dr)
    }
    fn kinetic(&self, q: &SVector<f64, 3>, k: &mut KineticMatrices<3>) {
        Water.kinetic(q, k)
    }
    fn kinetic_energy_gradient(
        &self,
        q: &SVector<f64, 3>,
        omega: &Vector3<f64>,
        qdot: &SVector<f64, 3>,
        grad: &mut SVector<f64, 3>,
    ) -> f64 {
        Water.kinetic_energy_gradient(q, omega, qdot, grad)
    }
}

impl Molecule<3, 3> for DefaultJacobian {
    fn potential(&self, q: &SVector<f64, 3>) -> f64 {
        Water.potential(q)
    }
    fn potential_gradient(&self, q: &SVector<f64, 3>, grad: &mut SVector<f64, 3>) -> f64 {
        Water.potential_gradient(q, grad)
    }
}

#[test]
fn default_kinetic_jacobian_equals_the_closed_form() {
    let mut rng = Rng::new(41);
    let mut worst = 0f64;
    for _ in 0..50 {
        let q = random_water_q(&mut rng);
        let mut expected = [KineticMatrices::<3>::default(); 3];
        Water.kinetic_jacobian(&q, &mut expected);
        // Garbage in the output: the default must overwrite every entry.
        let mut got = [KineticMatrices::<3> {
            a: SMatrix::repeat(f64::NAN),
            coriolis: SMatrix::repeat(f64::NAN),
            inertia: SMatrix::repeat(f64::NAN),
        }; 3];
        DefaultJacobian.kinetic_jacobian(&q, &mut got);
        let mut k = KineticMatrices::<3>::default();
        Water.kinetic(&q, &mut k);
        let scale = k.inertia.amax().max(k.a.amax());
        for l in 0..3 {
            let e = [
                (got[l].a - expected[l].a).amax(),
                (got[l].coriolis - expected[l].coriolis).amax(),
                (got[l].inertia - expected[l].inertia).amax(),
            ];
            worst =
                worst.max(e.into_iter().fold(0.0, |a, b| if b.is_nan() { f64::INFINITY } else { a.max(b) }) / scale);
        }
    }
    assert!(worst < 1e-14, "default kinetic_jacobian off by {worst:e} of the metric's size");
}
