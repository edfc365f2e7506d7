//! Independent checks of the seed Hamiltonian (`rovib_runtime::hamiltonian`) on hand-written
//! molecules: the right-hand side against finite differences of H, the G matrices against the
//! block inverse of the kinetic metric and Wilson's G matrix, their q-derivatives against finite
//! differences, the Euler-angle kinematics against the rotation matrix, and the error cases.

mod common;

use common::{RigidTop, Rng, Water, derivative, random_euler, random_vector, random_water_q};
use rovib_runtime::hamiltonian::{
    self, Evaluation, HamiltonianError, HamiltonianSystem, InverseMetric, MetricBlock, PhaseState, WMatrices,
    Workspace, angular_velocity_matrix, body_angular_momentum, euler_momenta_from_angular_momentum, rotation_matrix,
    velocities, w_matrix,
};
use rovib_runtime::integrate::OdeSystem;
use rovib_runtime::molecule::{Atom, Coordinate, Kinematics, KineticMatrices, Molecule};
use rovib_runtime::nalgebra::{Matrix3, SMatrix, SVector, Vector3};

const PI: f64 = core::f64::consts::PI;

fn water_state(rng: &mut Rng) -> PhaseState<3> {
    PhaseState {
        q: random_water_q(rng),
        p: random_vector(rng, 5.0),
        euler: random_euler(rng),
        pe: random_vector(rng, 10.0),
    }
}

fn rhs_of<M: Molecule<N, NA>, const N: usize, const NA: usize>(molecule: &M, state: &PhaseState<N>) -> PhaseState<N> {
    let mut ws = Workspace::default();
    hamiltonian::rhs(molecule, state, &mut ws).unwrap()
}

fn flat<const N: usize>(s: &PhaseState<N>) -> Vec<f64> {
    let mut y = vec![0.0; PhaseState::<N>::DIM];
    s.write_to(&mut y).unwrap();
    y
}

/// Hamilton's equations by finite differences of H in each of the 2N + 6 flat components.
fn fd_rhs<M: Molecule<N, NA>, const N: usize, const NA: usize>(molecule: &M, state: &PhaseState<N>) -> PhaseState<N> {
    let y0 = flat(state);
    let dh: Vec<f64> = (0..y0.len())
        .map(|i| {
            let is_momentum = (N..2 * N).contains(&i) || i >= 2 * N + 3;
            let is_angle = (2 * N..2 * N + 3).contains(&i);
            // Steps: H is quadratic in the momenta (any step is exact but for rounding); it
            // varies on a scale of ~1 bohr or rad in q; in θ, the 1/sin θ of W (sin θ ≥ 0.3
            // here) has fast-growing high derivatives, so the angles take a smaller step
            // (measured: 5e-3 balances the O(h⁶) truncation against rounding).
            let h = if is_momentum {
                1e-2 * y0[i].abs().max(1.0)
            } else if is_angle {
                5e-3
            } else {
                1e-2
            };
            let energy = |x: f64| {
                let mut y = y0.clone();
                y[i] = x;
                hamiltonian::hamiltonian(molecule, &PhaseState::read_from(&y).unwrap()).unwrap()
            };
            derivative(energy, y0[i], h)
        })
        .collect();
    let grad = PhaseState::<N>::read_from(&dh).unwrap();
    PhaseState { q: grad.p, p: -grad.q, euler: grad.pe, pe: -grad.euler }
}

/// Largest `|x_i − y_i| / max(|y_i|, 1e-3 ‖y_block‖)` over the four blocks of a state, so that a
/// component that happens to be tiny is judged against the size of its block.
fn worst_relative<const N: usize>(x: &PhaseState<N>, y: &PhaseState<N>) -> f64 {
    let blocks: [(&[f64], &[f64]); 4] = [
        (x.q.as_slice(), y.q.as_slice()),
        (x.p.as_slice(), y.p.as_slice()),
        (x.euler.as_slice(), y.euler.as_slice()),
        (x.pe.as_slice(), y.pe.as_slice()),
    ];
    let mut worst: f64 = 0.0;
    for (a, b) in blocks {
        let norm = b.iter().map(|v| v * v).sum::<f64>().sqrt();
        for (u, v) in a.iter().zip(b) {
            let scale = v.abs().max(1e-3 * norm);
            if scale > 0.0 {
                worst = worst.max((u - v).abs() / scale);
            } else {
                assert_eq!(u, v);
            }
        }
    }
    worst
}

fn max_abs<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> f64 {
    m.iter().fold(0.0, |acc: f64, x| acc.max(x.abs()))
}

fn water_metric(q: &SVector<f64, 3>) -> (KineticMatrices<3>, InverseMetric<3>) {
    let mut k = KineticMatrices::default();
    Water.kinetic(q, &mut k);
    (k, InverseMetric::new(&k, q).unwrap())
}

// ---------------------------------------------------------------- the right-hand side

#[test]
fn rhs_equals_finite_differences_of_h_for_the_triatomic() {
    let mut rng = Rng::new(1);
    let mut worst: f64 = 0.0;
    for _ in 0..25 {
        let state = water_state(&mut rng);
        let analytic = rhs_of(&Water, &state);
        let fd = fd_rhs(&Water, &state);
        let err = worst_relative(&fd, &analytic);
        assert!(err < 1e-8, "state {state:?}: relative error {err:e}\n{analytic:?}\n{fd:?}");
        worst = worst.max(err);
    }
    println!("triatomic: worst relative error rhs vs finite differences of H = {worst:.2e}");
}

#[test]
fn rhs_equals_finite_differences_of_h_for_the_rigid_top() {
    let mut rng = Rng::new(2);
    let mut worst: f64 = 0.0;
    for _ in 0..25 {
        let state = PhaseState::<0> {
            q: SVector::zeros(),
            p: SVector::zeros(),
            euler: random_euler(&mut rng),
            pe: random_vector(&mut rng, 10.0),
        };
        let analytic = rhs_of(&RigidTop, &state);
        let fd = fd_rhs(&RigidTop, &state);
        let err = worst_relative(&fd, &analytic);
        assert!(err < 1e-8, "state {state:?}: relative error {err:e}");
        worst = worst.max(err);
    }
    println!("rigid top: worst relative error rhs vs finite differences of H = {worst:.2e}");
}

#[test]
fn p_phi_is_conserved_to_the_bit() {
    let mut rng = Rng::new(3);
    for _ in 0..200 {
        let state = water_state(&mut rng);
        let d = rhs_of(&Water, &state);
        assert_eq!(d.pe[0].to_bits(), 0.0f64.to_bits(), "ṗ_φ = {:e}", d.pe[0]);
    }
}

#[test]
fn momentum_gradient_agrees_with_the_kinetic_energy_gradient() {
    // ∂H/∂q_k at fixed momenta = −∂T/∂q_k at fixed (ω, q̇) + ∂U/∂q_k: an independent route to
    // eq. (16) through the positions' second derivatives instead of ∂G/∂q.
    let mut rng = Rng::new(4);
    for _ in 0..20 {
        let state = water_state(&mut rng);
        let d = rhs_of(&Water, &state);
        let (omega, qdot) = velocities(&Water, &state).unwrap();
        let mut dt = SVector::zeros();
        let mut du = SVector::zeros();
        let t = Water.kinetic_energy_gradient(&state.q, &omega, &qdot, &mut dt);
        Water.potential_gradient(&state.q, &mut du);
        let expected = -(-dt + du);
        let err = max_abs(&(d.p - expected)) / max_abs(&expected);
        assert!(err < 1e-11, "relative error {err:e}");
        // And T = H − U.
        let h = hamiltonian::hamiltonian(&Water, &state).unwrap();
        let u = Water.potential(&state.q);
        assert!(((h - u) - t).abs() < 1e-13 * t.abs(), "T = {t}, H − U = {}", h - u);
    }
}

#[test]
fn euler_rates_give_the_angular_velocity() {
    let mut rng = Rng::new(5);
    for _ in 0..20 {
        let state = water_state(&mut rng);
        let d = rhs_of(&Water, &state);
        let (omega, qdot) = velocities(&Water, &state).unwrap();
        let from_rates = angular_velocity_matrix(&state.euler) * d.euler;
        assert!((from_rates - omega).norm() < 1e-12 * omega.norm());
        assert_eq!(qdot, d.q);
    }
}

#[test]
fn short_trajectory_conserves_energy() {
    // Classical RK4, written here so that this test does not depend on the integrators.
    let mut rng = Rng::new(6);
    let mut state = water_state(&mut rng);
    state.euler[1] = 1.2;
    let mut system = HamiltonianSystem::new(&Water);
    let mut y = flat(&state);
    let e0 = system.energy(&y).unwrap();
    let dt = 1.0;
    let n = y.len();
    let (mut k1, mut k2, mut k3, mut k4) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut tmp = vec![0.0; n];
    for _ in 0..200 {
        system.rhs(0.0, &y, &mut k1).unwrap();
        (0..n).for_each(|i| tmp[i] = y[i] + 0.5 * dt * k1[i]);
        system.rhs(0.0, &tmp, &mut k2).unwrap();
        (0..n).for_each(|i| tmp[i] = y[i] + 0.5 * dt * k2[i]);
        system.rhs(0.0, &tmp, &mut k3).unwrap();
        (0..n).for_each(|i| tmp[i] = y[i] + dt * k3[i]);
        system.rhs(0.0, &tmp, &mut k4).unwrap();
        (0..n).for_each(|i| y[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
    }
    let e1 = system.energy(&y).unwrap();
    assert!((e1 - e0).abs() < 1e-7 * e0.abs(), "E0 = {e0}, E1 = {e1}");
    // p_φ is a constant of the motion; with ṗ_φ = 0 exactly it does not move at all.
    assert_eq!(y[2 * 3 + 3], state.pe[0]);
    // So is |J| (the body-frame angular momentum only rotates).
    let j0 = body_angular_momentum(&state).unwrap().norm();
    let j1 = body_angular_momentum(&PhaseState::<3>::read_from(&y).unwrap()).unwrap().norm();
    assert!((j1 - j0).abs() < 1e-7 * j0, "|J| {j0} → {j1}");
}

// ---------------------------------------------------------------- the G matrices

#[test]
fn g_blocks_invert_the_kinetic_metric() {
    let mut rng = Rng::new(7);
    let mut worst: f64 = 0.0;
    for _ in 0..50 {
        let q = random_water_q(&mut rng);
        let (k, metric) = water_metric(&q);
        let g = metric.g;
        let mut full = SMatrix::<f64, 6, 6>::zeros();
        let mut inverse = SMatrix::<f64, 6, 6>::zeros();
        full.fixed_view_mut::<3, 3>(0, 0).copy_from(&k.inertia);
        full.fixed_view_mut::<3, 3>(0, 3).copy_from(&k.coriolis);
        full.fixed_view_mut::<3, 3>(3, 0).copy_from(&k.coriolis.transpose());
        full.fixed_view_mut::<3, 3>(3, 3).copy_from(&k.a);
        inverse.fixed_view_mut::<3, 3>(0, 0).copy_from(&g.g11);
        inverse.fixed_view_mut::<3, 3>(0, 3).copy_from(&g.g12);
        inverse.fixed_view_mut::<3, 3>(3, 0).copy_from(&g.g12.transpose());
        inverse.fixed_view_mut::<3, 3>(3, 3).copy_from(&g.g22);
        let err = max_abs(&(full * inverse - SMatrix::<f64, 6, 6>::identity()));
        assert!(err < 1e-12, "q = {q:?}: ‖M G − 1‖_max = {err:e}");
        worst = worst.max(err);
        // The two forms of G12 in eq. (3) agree: −G11 A a⁻¹ = −I⁻¹ A G22.
        let other = -(k.inertia.try_inverse().unwrap() * k.coriolis * g.g22);
        assert!(max_abs(&(other - g.g12)) < 1e-12 * max_abs(&g.g12));
        assert_eq!(g.g11, g.g11.transpose());
        assert_eq!(g.g22, g.g22.transpose());
    }
    println!("block inverse: worst max-entry error of M·G − 1 = {worst:.2e}");
}

#[test]
fn g22_is_wilsons_g_matrix_of_the_bent_triatomic() {
    let (mx, my) = (1.0 / Water::m_x(), 1.0 / Water::m_y());
    let mut worst: f64 = 0.0;
    for (r1, r2, alpha) in
        [(Water::RE, Water::RE, Water::ALPHA_E), (1.6, 2.1, 1.3), (2.0, 1.7, 2.6), (1.9, 1.5, 0.9), (1.75, 1.85, 2.95)]
    {
        let q = SVector::<f64, 3>::new(r1, r2, alpha);
        let (s, c) = alpha.sin_cos();
        #[rustfmt::skip]
        let wilson = Matrix3::new(
            mx + my,         c * mx,          -s / r2 * mx,
            c * mx,          mx + my,         -s / r1 * mx,
            -s / r2 * mx,    -s / r1 * mx,
            (mx + my) * (1.0 / (r1 * r1) + 1.0 / (r2 * r2)) - 2.0 * c / (r1 * r2) * mx,
        );
        let g22 = water_metric(&q).1.g.g22;
        for i in 0..3 {
            for j in 0..3 {
                let err = (g22[(i, j)] - wilson[(i, j)]).abs() / wilson[(i, j)].abs();
                assert!(err < 1e-12, "q = {q:?}, G[{i}][{j}]: relative error {err:e}");
                worst = worst.max(err);
            }
        }
    }
    println!("Wilson G: worst relative error of G22 = {worst:.2e}");
}

#[test]
fn g_derivatives_equal_finite_differences_of_g() {
    let mut rng = Rng::new(8);
    let mut worst: f64 = 0.0;
    for _ in 0..10 {
        let q = random_water_q(&mut rng);
        let (_, metric) = water_metric(&q);
        let mut dk = [KineticMatrices::default(); 3];
        Water.kinetic_jacobian(&q, &mut dk);
        for k in 0..3 {
            let dg = metric.derivative(&dk[k]);
            let g_at = |x: f64| {
                let mut qq = q;
                qq[k] = x;
                water_metric(&qq).1.g
            };
            let mut check = |analytic: &[f64], entry: &dyn Fn(usize, f64) -> f64| {
                let scale = analytic.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for (i, a) in analytic.iter().enumerate() {
                    let fd = derivative(|x| entry(i, x), q[k], 1e-2);
                    let err = (fd - a).abs() / scale;
                    assert!(err < 1e-9, "q = {q:?}, ∂/∂q_{k} entry {i}: {a} vs {fd}");
                    worst = worst.max(err);
                }
            };
            check(dg.g11.as_slice(), &|i, x| g_at(x).g11.as_slice()[i]);
            check(dg.g12.as_slice(), &|i, x| g_at(x).g12.as_slice()[i]);
            check(dg.g22.as_slice(), &|i, x| g_at(x).g22.as_slice()[i]);
        }
    }
    println!("∂G/∂q: worst error vs finite differences (relative to the block's largest entry) = {worst:.2e}");
}

#[test]
fn metric_errors_name_the_matrix() {
    let q = SVector::<f64, 1>::new(0.5);
    let good = KineticMatrices::<1> {
        a: SMatrix::<f64, 1, 1>::new(2.0),
        coriolis: SMatrix::<f64, 3, 1>::new(0.1, 0.2, 0.3),
        inertia: Matrix3::new(3.0, 0.1, 0.0, 0.1, 2.0, 0.0, 0.0, 0.0, 1.0),
    };
    assert!(InverseMetric::new(&good, &q).is_ok());
    let singular = |k: KineticMatrices<1>| match InverseMetric::new(&k, &q) {
        Err(HamiltonianError::SingularMetric { matrix, q }) => {
            assert_eq!(q, vec![0.5]);
            matrix
        }
        other => panic!("expected a singular-metric error, got {other:?}"),
    };
    let mut k = good;
    k.inertia[(2, 2)] = -1.0;
    assert_eq!(singular(k), MetricBlock::Inertia);
    let mut k = good;
    k.a[(0, 0)] = 0.0;
    assert_eq!(singular(k), MetricBlock::Vibrational);
    // I and a are positive definite but the whole metric is not: the coupling is too strong.
    let mut k = good;
    k.coriolis = SMatrix::<f64, 3, 1>::new(3.0, 0.0, 0.0);
    assert_eq!(singular(k), MetricBlock::G11Inverse);
    let mut k = good;
    k.coriolis[1] = f64::NAN;
    assert_eq!(
        InverseMetric::new(&k, &q).unwrap_err(),
        HamiltonianError::NonFinite { quantity: "kinetic matrices a, A, I" }
    );
}

// ---------------------------------------------------------------- Euler angles

#[test]
fn w_is_the_inverse_transpose_of_m() {
    let mut rng = Rng::new(9);
    for _ in 0..100 {
        let euler = random_euler(&mut rng);
        let w = w_matrix(&euler).unwrap();
        let m = angular_velocity_matrix(&euler);
        let err = max_abs(&(w * m.transpose() - Matrix3::identity()));
        assert!(err < 1e-14, "{euler:?}: ‖W Mᵀ − 1‖ = {err:e}");
    }
}

#[test]
fn w_derivatives_equal_finite_differences() {
    let mut rng = Rng::new(10);
    for _ in 0..20 {
        let euler = random_euler(&mut rng);
        let wm = WMatrices::new(&euler).unwrap();
        for (axis, analytic) in [(0, Matrix3::zeros()), (1, wm.dw_dtheta), (2, wm.dw_dpsi)] {
            for i in 0..9 {
                let fd = derivative(
                    |x| {
                        let mut e = euler;
                        e[axis] = x;
                        w_matrix(&e).unwrap().as_slice()[i]
                    },
                    euler[axis],
                    1e-3,
                );
                let scale = max_abs(&analytic).max(1.0);
                let a = analytic.as_slice()[i];
                assert!((fd - a).abs() < 1e-10 * scale, "{euler:?}, axis {axis}: {a} vs {fd}");
            }
        }
    }
}

#[test]
fn rotation_matrix_is_consistent_with_the_angular_velocity() {
    // ω = M Ω̇ must be the axial vector of Rᵀ Ṙ, with Ṙ by finite differences along
    // Ω(t) = Ω + t Ω̇: everything downstream (the sign of J, the frames) depends on it.
    let mut rng = Rng::new(11);
    for _ in 0..50 {
        let euler = random_euler(&mut rng);
        let rates = random_vector::<3>(&mut rng, 1.0);
        let r = rotation_matrix(&euler);
        assert!(max_abs(&(r.transpose() * r - Matrix3::identity())) < 1e-14);
        assert!((r.determinant() - 1.0).abs() < 1e-14);
        let rdot = Matrix3::from_fn(|i, j| derivative(|t| rotation_matrix(&(euler + rates * t))[(i, j)], 0.0, 1e-2));
        let s = r.transpose() * rdot;
        assert!(max_abs(&(s + s.transpose())) < 1e-10, "Rᵀ Ṙ is not skew: {s}");
        let axial = Vector3::new(s[(2, 1)], s[(0, 2)], s[(1, 0)]);
        let omega = angular_velocity_matrix(&euler) * rates;
        assert!((axial - omega).norm() < 1e-10 * omega.norm().max(1.0), "{axial} vs {omega}");
    }
    // The convention itself: R = Rz(φ) Rx(θ) Rz(ψ) maps the body z axis to
    // (sin φ sin θ, −cos φ sin θ, cos θ).
    let (phi, theta) = (0.4, 1.1);
    let z_lab = rotation_matrix(&Vector3::new(phi, theta, 0.7)) * Vector3::z();
    let expected = Vector3::new(phi.sin() * theta.sin(), -phi.cos() * theta.sin(), theta.cos());
    assert!((z_lab - expected).norm() < 1e-15);
}

#[test]
fn angular_momentum_and_both_forms_of_h_agree() {
    let mut rng = Rng::new(12);
    for _ in 0..30 {
        let s = water_state(&mut rng);
        let w = w_matrix(&s.euler).unwrap();
        let j = body_angular_momentum(&s).unwrap();
        assert_eq!(j, w * s.pe);
        let pe = euler_momenta_from_angular_momentum(&s.euler, &j);
        assert!((pe - s.pe).norm() < 1e-13 * s.pe.norm());

        // H written with p_e, eq. (1), against the implementation (written with J).
        let g = water_metric(&s.q).1.g;
        let h_pe = 0.5 * s.p.dot(&(g.g22 * s.p))
            + s.pe.dot(&(w.transpose() * g.g12 * s.p))
            + 0.5 * s.pe.dot(&(w.transpose() * g.g11 * w * s.pe))
            + Water.potential(&s.q);
        let h = hamiltonian::hamiltonian(&Water, &s).unwrap();
        assert!((h - h_pe).abs() < 1e-13 * h.abs(), "{h} vs {h_pe}");
    }
}

// ---------------------------------------------------------------- rigid molecule (N = 0)

#[test]
fn rigid_top_has_g11_equal_to_the_inverse_inertia() {
    let q = SVector::<f64, 0>::zeros();
    let mut k = KineticMatrices::default();
    RigidTop.kinetic(&q, &mut k);
    let g = InverseMetric::new(&k, &q).unwrap().g;
    let i_inv = k.inertia.try_inverse().unwrap();
    assert!(max_abs(&(g.g11 - i_inv)) < 1e-14 * max_abs(&i_inv));
    assert_eq!((g.g12.nrows(), g.g12.ncols(), g.g22.nrows()), (3, 0, 0));

    let mut rng = Rng::new(13);
    for _ in 0..20 {
        let s = PhaseState::<0> {
            q,
            p: SVector::zeros(),
            euler: random_euler(&mut rng),
            pe: random_vector(&mut rng, 10.0),
        };
        let j = body_angular_momentum(&s).unwrap();
        let h = hamiltonian::hamiltonian(&RigidTop, &s).unwrap();
        let expected = 0.5 * j.dot(&(i_inv * j)) + RigidTop::U0;
        assert!((h - expected).abs() < 1e-14 * expected.abs());
        let (omega, _) = velocities(&RigidTop, &s).unwrap();
        assert!((k.inertia * omega - j).norm() < 1e-12 * j.norm());
    }
}

// ---------------------------------------------------------------- errors

fn rhs_err<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    molecule: &M,
    state: &PhaseState<N>,
) -> HamiltonianError {
    let mut ws = Workspace::default();
    let err = hamiltonian::rhs(molecule, state, &mut ws).unwrap_err();
    // H and the velocities fail the same way (they need the same W and G).
    assert_eq!(hamiltonian::hamiltonian(molecule, state).unwrap_err(), err);
    err
}

#[test]
fn gimbal_lock_is_an_euler_error() {
    let mut s = water_state(&mut Rng::new(14));
    for theta in [0.0, PI, -PI, 1e-9] {
        s.euler[1] = theta;
        assert_eq!(rhs_err(&Water, &s), HamiltonianError::EulerSingular { theta });
        assert_eq!(body_angular_momentum(&s).unwrap_err(), HamiltonianError::EulerSingular { theta });
    }
    let msg = HamiltonianError::EulerSingular { theta: 0.0 }.to_string();
    assert!(msg.starts_with("the Euler angle θ = 0 rad"), "{msg}");
}

#[test]
fn singular_geometries_are_metric_errors_naming_the_matrix() {
    let mut s = water_state(&mut Rng::new(15));
    // Linear (α = π) and a vanishing bond (r1 = 0): the atoms are collinear, I is singular.
    for q in [
        SVector::<f64, 3>::new(1.8, 1.8, PI),
        SVector::<f64, 3>::new(0.0, 1.8, 1.8),
        SVector::<f64, 3>::new(1.8, 1.8, PI - 1e-7),
    ] {
        s.q = q;
        let err = rhs_err(&Water, &s);
        assert_eq!(err, HamiltonianError::SingularMetric { matrix: MetricBlock::Inertia, q: q.as_slice().to_vec() });
        let msg = err.to_string();
        assert!(msg.starts_with("the inertia tensor I is singular"), "{msg}");
    }
    // Slightly bent is fine.
    s.q = SVector::<f64, 3>::new(1.8, 1.8, PI - 1e-3);
    assert!(hamiltonian::hamiltonian(&Water, &s).is_ok());
}

#[test]
fn non_finite_inputs_are_reported_by_quantity() {
    let base = water_state(&mut Rng::new(16));
    let cases: [(usize, &str); 4] = [
        (1, "internal coordinates q"),
        (4, "internal momenta p"),
        (8, "Euler angles (φ, θ, ψ)"),
        (11, "Euler momenta (p_φ, p_θ, p_ψ)"),
    ];
    for (index, quantity) in cases {
        for bad in [f64::NAN, f64::INFINITY] {
            let mut y = flat(&base);
            y[index] = bad;
            let s = PhaseState::<3>::read_from(&y).unwrap();
            assert_eq!(rhs_err(&Water, &s), HamiltonianError::NonFinite { quantity });
        }
    }
    assert_eq!(
        HamiltonianError::NonFinite { quantity: "internal momenta p" }.to_string(),
        "non-finite internal momenta p"
    );
}

/// Water with a potential that is NaN beyond r1 = 2 bohr, as a broken generated molecule might.
struct BrokenPotential;

impl Kinematics<3, 3> for BrokenPotential {
    fn name(&self) -> &'static str {
        "broken"
    }
    fn source(&self) -> &'static str {
        "runtime/tests/hamiltonian.rs"
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
    fn kinetic_jacobian(&self, q: &SVector<f64, 3>, dk: &mut [KineticMatrices<3>; 3]) {
        Water.kinetic_jacobian(q, dk)
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

impl Molecule<3, 3> for BrokenPotential {
    fn potential(&self, q: &SVector<f64, 3>) -> f64 {
        if q[0] > 2.0 { f64::NAN } else { Water.potential(q) }
    }
    fn potential_gradient(&self, q: &SVector<f64, 3>, grad: &mut SVector<f64, 3>) -> f64 {
        let u = Water.potential_gradient(q, grad);
        if q[0] > 2.0 {
            grad[0] = f64::NAN;
        }
        u
    }
}

#[test]
fn non_finite_molecule_results_are_reported() {
    let mut s = water_state(&mut Rng::new(17));
    s.q[0] = 2.1;
    let mut ws = Workspace::default();
    assert_eq!(
        hamiltonian::rhs(&BrokenPotential, &s, &mut ws).unwrap_err(),
        HamiltonianError::NonFinite { quantity: "potential gradient ∂U/∂q" }
    );
    assert_eq!(
        hamiltonian::hamiltonian(&BrokenPotential, &s).unwrap_err(),
        HamiltonianError::NonFinite { quantity: "potential U(q)" }
    );
    s.q[0] = 1.9;
    assert!(hamiltonian::rhs(&BrokenPotential, &s, &mut ws).is_ok());
}

// ---------------------------------------------------------------- layout and the ODE system

#[test]
fn flat_layout_is_q_p_angles_momenta() {
    let s = PhaseState::<3> {
        q: SVector::<f64, 3>::new(1.0, 2.0, 3.0),
        p: SVector::<f64, 3>::new(4.0, 5.0, 6.0),
        euler: Vector3::new(7.0, 8.0, 9.0),
        pe: Vector3::new(10.0, 11.0, 12.0),
    };
    let y = flat(&s);
    assert_eq!(y, (1..=12).map(f64::from).collect::<Vec<_>>());
    assert_eq!(PhaseState::<3>::read_from(&y).unwrap(), s);
    assert_eq!(PhaseState::<3>::DIM, 12);
    assert_eq!(PhaseState::<0>::DIM, 6);
    assert_eq!(
        PhaseState::<3>::read_from(&y[..11]).unwrap_err(),
        HamiltonianError::DimensionMismatch { expected: 12, found: 11 }
    );
    let mut short = [0.0; 13];
    assert_eq!(s.write_to(&mut short).unwrap_err(), HamiltonianError::DimensionMismatch { expected: 12, found: 13 });
}

#[test]
fn ode_system_wraps_the_seed_rhs() {
    let s = water_state(&mut Rng::new(18));
    let mut system = HamiltonianSystem::new(&Water);
    assert_eq!(system.dim(), 12);
    let y = flat(&s);
    let mut dydt = vec![0.0; 12];
    system.rhs(0.0, &y, &mut dydt).unwrap();
    assert_eq!(dydt, flat(&rhs_of(&Water, &s)));
    assert_eq!(system.energy(&y).unwrap(), hamiltonian::hamiltonian(&Water, &s).unwrap());
    assert_eq!(
        system.rhs(0.0, &y[..10], &mut dydt).unwrap_err(),
        HamiltonianError::DimensionMismatch { expected: 12, found: 10 }
    );
    assert!(matches!(
        system.rhs(0.0, &y, &mut dydt[..11]),
        Err(HamiltonianError::DimensionMismatch { expected: 12, found: 11 })
    ));

    let mut rigid = HamiltonianSystem::new(&RigidTop);
    assert_eq!(rigid.dim(), 6);
    let mut d = [0.0; 6];
    rigid.rhs(0.0, &[0.1, 0.8, -0.4, 1.0, 2.0, 3.0], &mut d).unwrap();
    assert_eq!(d[3], 0.0);
}

#[test]
fn evaluation_collects_everything_eval_prints() {
    let s = water_state(&mut Rng::new(19));
    let e: Evaluation<3, 3> = hamiltonian::evaluate(&Water, &s).unwrap();
    let mut r = SMatrix::zeros();
    Water.positions(&s.q, &mut r);
    assert_eq!(e.positions, r);
    // Centre of mass at the origin.
    let masses = Water.masses();
    let com: Vector3<f64> = (0..3).map(|i| r.column(i) * masses[i]).sum();
    assert!(com.norm() < 1e-12);
    let (k, metric) = water_metric(&s.q);
    assert_eq!(e.kinetic, k);
    assert_eq!(e.g, metric.g);
    assert_eq!(e.hamiltonian, hamiltonian::hamiltonian(&Water, &s).unwrap());
    assert_eq!(e.potential, Water.potential(&s.q));
    assert!((e.kinetic_energy + e.potential - e.hamiltonian).abs() < 1e-15);
    assert_eq!(e.rhs, rhs_of(&Water, &s));
    assert_eq!(e.angular_momentum, body_angular_momentum(&s).unwrap());
    assert_eq!((e.omega, e.qdot), velocities(&Water, &s).unwrap());
    let system = HamiltonianSystem::new(&Water);
    assert_eq!(system.evaluate(&flat(&s)).unwrap(), e);
}

// ---------------------------------------------------------------- the test molecule itself

#[test]
fn test_molecule_derivatives_match_finite_differences() {
    // The hand-written first and second position derivatives feed the kinetic Jacobian; check
    // them so that a slip there cannot hide behind the finite-difference tests of H.
    let mut rng = Rng::new(20);
    for _ in 0..5 {
        let q = random_water_q(&mut rng);
        let mut dr = [SMatrix::zeros(); 3];
        Water.positions_jacobian(&q, &mut dr);
        let mut dk = [KineticMatrices::default(); 3];
        Water.kinetic_jacobian(&q, &mut dk);
        let mut grad = SVector::zeros();
        let u = Water.potential_gradient(&q, &mut grad);
        assert_eq!(u, Water.potential(&q));
        for k in 0..3 {
            let at = |x: f64| {
                let mut qq = q;
                qq[k] = x;
                qq
            };
            for i in 0..9 {
                let fd = derivative(
                    |x| {
                        let mut r = SMatrix::zeros();
                        Water.positions(&at(x), &mut r);
                        r.as_slice()[i]
                    },
                    q[k],
                    1e-2,
                );
                assert!((fd - dr[k].as_slice()[i]).abs() < 1e-10);
                let kin = |x: f64| {
                    let mut m = KineticMatrices::default();
                    Water.kinetic(&at(x), &mut m);
                    m
                };
                let fd_a = derivative(|x| kin(x).a.as_slice()[i], q[k], 1e-2);
                let fd_c = derivative(|x| kin(x).coriolis.as_slice()[i], q[k], 1e-2);
                let fd_i = derivative(|x| kin(x).inertia.as_slice()[i], q[k], 1e-2);
                let scale = 1e-9 * Water::m_x() * 10.0;
                assert!((fd_a - dk[k].a.as_slice()[i]).abs() < scale);
                assert!((fd_c - dk[k].coriolis.as_slice()[i]).abs() < scale);
                assert!((fd_i - dk[k].inertia.as_slice()[i]).abs() < scale);
            }
            let fd_u = derivative(|x| Water.potential(&at(x)), q[k], 1e-2);
            assert!((fd_u - grad[k]).abs() < 1e-11);
        }
    }
}
