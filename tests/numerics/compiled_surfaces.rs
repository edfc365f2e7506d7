//! Potentials from source files named by a definition (`[potential] rust`, `c`, `cpp`,
//! `fortran`; the definitions of `tests/surfaces`, built with the `surface-demos` feature): the
//! arn2 spline × Legendre surface as a Rust file, in Fortran, in C++ and in C gives the
//! trajectories of the same surface in the definition language (`molecules/arn2.toml`) to
//! 1e-12 bohr, and the same U and ∂U/∂q pointwise.

use rovib::molecules::{Arn2, Arn2C, Arn2Cpp, Arn2Fortran, Arn2Rust};
use rovib::runtime::Molecule;
use rovib::runtime::nalgebra::SVector;

use crate::surfaces::{max_q_difference, trajectory};

/// U and ∂U/∂q of `m` against arn2's at points over every spline interval and the tail.
fn same_surface<M: Molecule<2, 3>>(m: &M) {
    for r in [4.5, 5.5, 6.0, 6.54, 7.5, 8.2, 9.7, 10.5, 11.9, 12.0, 14.0] {
        for theta in [0.0, 0.3, 1.0, std::f64::consts::FRAC_PI_2, 2.2, std::f64::consts::PI] {
            let q = SVector::from([r, theta]);
            let (mut g1, mut g2) = (SVector::zeros(), SVector::zeros());
            let (u1, u2) = (m.potential_gradient(&q, &mut g1), Arn2.potential_gradient(&q, &mut g2));
            assert!((u1 - u2).abs() <= 1e-13 * u2.abs().max(1e-6), "{}: U at {q:?}: {u1:e} vs {u2:e}", m.name());
            assert_eq!(m.potential(&q), u1, "{}: potential and potential_gradient disagree", m.name());
            assert!((g1 - g2).norm() <= 1e-12 * g2.norm().max(1e-6), "{}: ∂U/∂q at {q:?}: {g1:?} vs {g2:?}", m.name());
        }
    }
}

#[test]
fn rust_fortran_cpp_and_c_sources_are_the_definitions_surface() {
    same_surface(&Arn2Rust);
    same_surface(&Arn2Fortran);
    same_surface(&Arn2Cpp);
    same_surface(&Arn2C);
}

#[test]
fn rust_fortran_cpp_and_c_sources_give_the_definitions_trajectory() {
    let generated = trajectory(&Arn2);
    for (name, t) in [
        ("rust", trajectory(&Arn2Rust)),
        ("fortran", trajectory(&Arn2Fortran)),
        ("cpp", trajectory(&Arn2Cpp)),
        ("c", trajectory(&Arn2C)),
    ] {
        let d = max_q_difference(&t, &generated);
        eprintln!("max |Δq| {name} vs definition: {d:e}");
        assert!(d <= 1e-12, "{name}: {d:e}");
    }
}

#[test]
fn the_lane_form_of_a_source_potential_is_the_scalar_one_lane_by_lane() {
    use rovib::runtime::lanes::Real;
    type L = rovib::runtime::lanes::F64x4;
    let q = [L::from_array([6.0, 6.5, 9.1, 13.0]), L::from_array([0.2, 1.1, 2.0, 3.0])];
    let mut g = [L::splat(0.0); 2];
    let u = Arn2Fortran.potential_gradient_lanes(&q, &mut g);
    assert!(Arn2Fortran.has_lane_forms());
    for lane in 0..4 {
        let qs = SVector::from([q[0].lane(lane), q[1].lane(lane)]);
        let mut gs = SVector::zeros();
        assert_eq!(Arn2Fortran.potential_gradient(&qs, &mut gs), u.lane(lane));
        assert_eq!([gs[0], gs[1]], [g[0].lane(lane), g[1].lane(lane)]);
    }
}
