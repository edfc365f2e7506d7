//! The generated code of every shipped molecule against independent evaluations: the kinetic
//! matrices recomputed from the generated positions with finite-difference jacobians, every
//! q-derivative against finite differences, and the centre of mass at the origin.

use crate::common;

use common::for_each_molecule;

use common::{Rng, central_difference, fd_step, random_q, rel_diff, richardson_derivative};
use rovib::runtime::nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rovib::runtime::{Kinematics, KineticMatrices, Molecule, MoleculeVisitor};

const POINTS: usize = 5;

#[derive(Copy, Clone)]
struct CentreOfMass;
impl MoleculeVisitor for CentreOfMass {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let masses = m.masses();
        let total: f64 = masses.iter().sum();
        let mut rng = Rng::new(1);
        for _ in 0..POINTS {
            let q = random_q(&m, &mut rng);
            let mut r = SMatrix::<f64, 3, NA>::zeros();
            m.positions(&q, &mut r);
            let com: Vector3<f64> = (0..NA).map(|i| r.column(i) * masses[i]).sum::<Vector3<f64>>() / total;
            let size = r.amax();
            assert!(com.amax() <= 1e-14 * size, "{}: centre of mass {com:?}", m.name());
        }
    }
}

#[test]
fn centre_of_mass_is_at_the_origin() {
    for_each_molecule(CentreOfMass);
}

#[derive(Copy, Clone)]
struct PositionsJacobian;
impl MoleculeVisitor for PositionsJacobian {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(2);
        for _ in 0..POINTS {
            let q = random_q(&m, &mut rng);
            let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
            m.positions_jacobian(&q, &mut dr);
            for k in 0..N {
                let fd = central_difference(&q, k, |x| {
                    let mut r = SMatrix::<f64, 3, NA>::zeros();
                    m.positions(x, &mut r);
                    r
                });
                let e = rel_diff(&dr[k], &fd, 1e-300);
                assert!(e < 1e-8, "{}: ∂R/∂q_{k} off by {e:e}", m.name());
            }
        }
    }
}

#[test]
fn position_jacobian_matches_finite_differences() {
    for_each_molecule(PositionsJacobian);
}

/// a, A and I computed directly from the generated positions, with the jacobian by finite
/// differences: no generated kinetic code involved.
fn kinetic_by_hand<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    q: &SVector<f64, N>,
) -> KineticMatrices<N> {
    let masses = m.masses();
    let mut r = SMatrix::<f64, 3, NA>::zeros();
    m.positions(q, &mut r);
    let dr: Vec<SMatrix<f64, 3, NA>> = (0..N)
        .map(|k| {
            central_difference(q, k, |x| {
                let mut r = SMatrix::<f64, 3, NA>::zeros();
                m.positions(x, &mut r);
                r
            })
        })
        .collect();
    let mut out = KineticMatrices::<N>::default();
    for i in 0..NA {
        let ri: Vector3<f64> = r.column(i).into();
        out.inertia += masses[i] * (Matrix3::identity() * ri.norm_squared() - ri * ri.transpose());
        for j in 0..N {
            let dj: Vector3<f64> = dr[j].column(i).into();
            for k in 0..N {
                let dk: Vector3<f64> = dr[k].column(i).into();
                out.a[(j, k)] += masses[i] * dj.dot(&dk);
            }
            let c = ri.cross(&dj);
            for axis in 0..3 {
                out.coriolis[(axis, j)] += masses[i] * c[axis];
            }
        }
    }
    out
}

#[derive(Copy, Clone)]
struct KineticMatchesPositions;
impl MoleculeVisitor for KineticMatchesPositions {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(3);
        for _ in 0..POINTS {
            let q = random_q(&m, &mut rng);
            let mut k = KineticMatrices::<N>::default();
            m.kinetic(&q, &mut k);
            let hand = kinetic_by_hand(&m, &q);
            let name = m.name();
            let e = rel_diff(&k.a, &hand.a, 1e-300);
            assert!(e < 1e-8, "{name}: a off by {e:e}");
            let e = rel_diff(&k.coriolis, &hand.coriolis, hand.inertia.amax() * 1e-12);
            assert!(e < 1e-8, "{name}: A off by {e:e}");
            let e = rel_diff(&k.inertia, &hand.inertia, 1e-300);
            assert!(e < 1e-13, "{name}: I off by {e:e}");
        }
    }
}

#[test]
fn kinetic_matrices_match_a_direct_evaluation_from_the_positions() {
    for_each_molecule(KineticMatchesPositions);
}

#[derive(Copy, Clone)]
struct KineticJacobian;
impl MoleculeVisitor for KineticJacobian {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(4);
        let mut worst = 0f64;
        for _ in 0..POINTS {
            let q = random_q(&m, &mut rng);
            let mut dk = [KineticMatrices::<N>::default(); N];
            m.kinetic_jacobian(&q, &mut dk);
            let mut k0 = KineticMatrices::<N>::default();
            m.kinetic(&q, &mut k0);
            for l in 0..N {
                let eval = |x: &SVector<f64, N>| {
                    let mut k = KineticMatrices::<N>::default();
                    m.kinetic(x, &mut k);
                    k
                };
                let fd_a = central_difference(&q, l, |x| eval(x).a);
                let fd_c = central_difference(&q, l, |x| eval(x).coriolis);
                let fd_i = central_difference(&q, l, |x| eval(x).inertia);
                // Relative to the size of the matrix being differentiated, so that an entry
                // whose derivative happens to be tiny is not held to an impossible standard.
                let e = [
                    rel_diff(&dk[l].a, &fd_a, k0.a.amax()),
                    rel_diff(&dk[l].coriolis, &fd_c, k0.inertia.amax()),
                    rel_diff(&dk[l].inertia, &fd_i, k0.inertia.amax()),
                ];
                worst = worst.max(e.into_iter().fold(0.0, f64::max));
            }
        }
        assert!(worst < 1e-9, "{}: ∂(a, A, I)/∂q off by {worst:e}", m.name());
    }
}

#[test]
fn kinetic_derivatives_match_finite_differences() {
    for_each_molecule(KineticJacobian);
}

#[derive(Copy, Clone)]
struct EnergyGradient;
impl MoleculeVisitor for EnergyGradient {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(5);
        for _ in 0..POINTS {
            let q = random_q(&m, &mut rng);
            let omega = Vector3::from_fn(|_, _| rng.uniform(-1e-3, 1e-3));
            let qdot = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-1e-3, 1e-3));
            // T = ½ vᵀ M v from the kinetic matrices, v = (ω, q̇).
            let t_of = |x: &SVector<f64, N>| {
                let mut k = KineticMatrices::<N>::default();
                m.kinetic(x, &mut k);
                let t = 0.5 * omega.dot(&(k.inertia * omega))
                    + omega.dot(&(k.coriolis * qdot))
                    + 0.5 * qdot.dot(&(k.a * qdot));
                SMatrix::<f64, 1, 1>::new(t)
            };
            let mut grad = SVector::<f64, N>::zeros();
            let t = m.kinetic_energy_gradient(&q, &omega, &qdot, &mut grad);
            let t_ref = t_of(&q)[0];
            assert!((t - t_ref).abs() <= 1e-13 * t_ref.abs(), "{}: T = {t} vs {t_ref}", m.name());
            for k in 0..N {
                let fd = central_difference(&q, k, t_of)[0];
                assert!((grad[k] - fd).abs() <= 1e-8 * t_ref.abs(), "{}: ∂T/∂q_{k} = {} vs {fd}", m.name(), grad[k]);
            }
        }
    }
}

#[test]
fn kinetic_energy_gradient_matches_finite_differences() {
    for_each_molecule(EnergyGradient);
}

#[derive(Copy, Clone)]
struct PotentialGradient;
impl MoleculeVisitor for PotentialGradient {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(6);
        for _ in 0..POINTS {
            let q = random_q(&m, &mut rng);
            let mut grad = SVector::<f64, N>::zeros();
            let u = m.potential_gradient(&q, &mut grad);
            assert_eq!(u, m.potential(&q), "the two entry points compute the same U");
            let scale = grad.amax().max(1e-6);
            for k in 0..N {
                // Richardson-extrapolated (sixth order): a van der Waals well (σ/12 ≈ 0.5 bohr)
                // is too sharp for the plain fourth-order difference at this tolerance.
                let mut u = |x: &[f64]| m.potential(&SVector::from_column_slice(x));
                let fd = richardson_derivative(q.as_slice(), k, fd_step(&q, k), &mut u);
                assert!((grad[k] - fd).abs() <= 1e-8 * scale, "{}: ∂U/∂q_{k} = {} vs {fd}", m.name(), grad[k]);
            }
        }
    }
}

#[test]
fn potential_gradient_matches_finite_differences() {
    for_each_molecule(PotentialGradient);
}

/// The fused `kinetic_and_gradient` gives exactly what `kinetic` and `kinetic_energy_gradient`
/// give separately (the same expressions, computed once), and hands the kinetic matrices to
/// the velocity callback before using the velocities.
#[derive(Copy, Clone)]
struct Fused;
impl MoleculeVisitor for Fused {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(7);
        for _ in 0..POINTS {
            let q = random_q(&m, &mut rng);
            let omega = Vector3::from_fn(|_, _| rng.uniform(-1e-3, 1e-3));
            let qdot = SVector::<f64, N>::from_fn(|_, _| rng.uniform(-1e-3, 1e-3));
            let mut k = KineticMatrices::<N>::default();
            let mut grad = SVector::<f64, N>::zeros();
            let mut seen = None;
            let (w, qd, t) = m
                .kinetic_and_gradient(
                    &q,
                    &mut k,
                    |k| {
                        seen = Some(*k);
                        Ok::<_, ()>((omega, qdot))
                    },
                    &mut grad,
                )
                .unwrap();
            let mut k_ref = KineticMatrices::<N>::default();
            m.kinetic(&q, &mut k_ref);
            let mut grad_ref = SVector::<f64, N>::zeros();
            let t_ref = m.kinetic_energy_gradient(&q, &omega, &qdot, &mut grad_ref);
            assert_eq!(seen, Some(k_ref), "{}: the callback sees the finished kinetic matrices", m.name());
            assert_eq!(k, k_ref);
            assert_eq!((w, qd), (omega, qdot));
            assert_eq!(grad, grad_ref, "{}", m.name());
            assert_eq!(t, t_ref);
            // An error from the callback is returned as is.
            let err =
                m.kinetic_and_gradient(&q, &mut k, |_| Err::<(Vector3<f64>, SVector<f64, N>), _>("stop"), &mut grad);
            assert_eq!(err, Err("stop"));
        }
    }
}

#[test]
fn fused_kinetic_and_gradient_equals_the_separate_functions() {
    for_each_molecule(Fused);
}

#[derive(Copy, Clone)]
struct Ranges;
impl MoleculeVisitor for Ranges {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        use rovib::runtime::units::CoordinateUnit;
        for c in m.coordinates() {
            let (low, high) = c.range;
            assert!(low < high, "{}: {} has an empty range", m.name(), c.name);
            if let CoordinateUnit::Length(_) = c.unit {
                assert!(low >= 0.0, "{}: length {} may be negative", m.name(), c.name);
            }
        }
        if let Some(q) = m.reference_geometry() {
            assert_eq!(m.in_range(&q), Ok(()), "{}: reference geometry outside the ranges", m.name());
            // Just past a bound is outside, and reported by index.
            for (k, c) in m.coordinates().iter().enumerate() {
                if c.range.1.is_finite() {
                    let mut beyond = q;
                    beyond[k] = c.range.1 * (1.0 + 1e-12) + 1e-300;
                    assert_eq!(m.in_range(&beyond), Err(k), "{}: {}", m.name(), c.name);
                }
            }
        }
    }
}

/// Every coordinate's valid range is an interval, lengths are non-negative, the reference
/// geometry lies inside, and bond angles end at π (as their definitions declare).
#[test]
fn coordinate_ranges_hold_the_reference_geometry() {
    for_each_molecule(Ranges);
    let water = rovib::molecules::H2o.coordinates();
    assert_eq!(water[2].range, (0.0, std::f64::consts::PI));
    assert_eq!(water[0].range, (0.0, f64::INFINITY));
}
