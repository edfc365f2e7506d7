//! The seed-path Hamiltonian on the generated molecules, against independent references:
//! finite differences of H, the block-inverse identity, Wilson's G matrix for water, finite
//! differences of G, and the exact symmetries (p_φ conserved, J = W p_e).

use crate::common;

use common::for_each_molecule;

use common::{Rng, random_q, random_state, rel_diff, richardson_derivative};
use rovib::molecules::{self, H2o};
use rovib::runtime::hamiltonian::{
    HamiltonianSystem, InverseMetric, PhaseState, Workspace, hamiltonian, rhs, w_matrix,
};
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{DMatrix, SVector};
use rovib::runtime::{Kinematics, KineticMatrices, Molecule, MoleculeVisitor};

const STATES: usize = 8;

/// Every component of the right-hand side equals the matching finite difference of H:
/// q̇ = ∂H/∂p, ṗ = −∂H/∂q, Ω̇ = ∂H/∂p_e, ṗ_e = −∂H/∂Ω.
#[derive(Copy, Clone)]
struct RhsIsTheGradientOfH;
impl MoleculeVisitor for RhsIsTheGradientOfH {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(11);
        let mut system = HamiltonianSystem::new(&m);
        let dim = system.dim();
        assert_eq!(dim, 2 * N + 6);
        let mut worst = 0f64;
        for _ in 0..STATES {
            let s = random_state(&m, &mut rng);
            let mut y = vec![0.0; dim];
            s.write_to(&mut y).unwrap();
            let mut dy = vec![0.0; dim];
            system.rhs(0.0, &y, &mut dy).unwrap();
            let mut h_of = |x: &[f64]| system.energy(x).unwrap();
            // Conjugate pairs in the flat layout: (q_k, p_k) and (Ω_a, p_e,a).
            let pairs: Vec<(usize, usize)> =
                (0..N).map(|k| (k, N + k)).chain((0..3).map(|a| (2 * N + a, 2 * N + 3 + a))).collect();
            for (x, p) in pairs {
                let hx = 1e-3 * y[x].abs().max(1.0);
                let hp = 1e-3 * y[p].abs().max(1.0);
                let dh_dp = richardson_derivative(&y, p, hp, &mut h_of);
                let dh_dx = richardson_derivative(&y, x, hx, &mut h_of);
                // Scale: the largest entry of the block, so a component that is nearly zero is
                // judged against the size of its neighbours.
                let scale_x = dy[..N].iter().chain(&dy[2 * N..2 * N + 3]).fold(1e-12_f64, |m, v| m.max(v.abs()));
                let scale_p = dy[N..2 * N].iter().chain(&dy[2 * N + 3..]).fold(1e-12_f64, |m, v| m.max(v.abs()));
                worst = worst.max((dy[x] - dh_dp).abs() / scale_x).max((dy[p] + dh_dx).abs() / scale_p);
            }
        }
        assert!(worst < 1e-7, "{}: rhs vs finite differences of H, worst relative error {worst:e}", m.name());
        eprintln!("{}: rhs vs finite differences of H: worst relative error {worst:.2e}", m.name());
    }
}

#[test]
fn rhs_equals_finite_differences_of_h() {
    for_each_molecule(RhsIsTheGradientOfH);
}

/// [[I, A], [Aᵀ, a]] · [[G11, G12], [G12ᵀ, G22]] = 1.
#[derive(Copy, Clone)]
struct BlockInverse;
impl MoleculeVisitor for BlockInverse {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(12);
        for _ in 0..STATES {
            let q = random_q(&m, &mut rng);
            let mut k = KineticMatrices::<N>::default();
            m.kinetic(&q, &mut k);
            let g = InverseMetric::new(&k, &q).unwrap().g;
            let d = N + 3;
            let mut metric = DMatrix::zeros(d, d);
            let mut inverse = DMatrix::zeros(d, d);
            metric.view_mut((0, 0), (3, 3)).copy_from(&k.inertia);
            metric.view_mut((0, 3), (3, N)).copy_from(&k.coriolis);
            metric.view_mut((3, 0), (N, 3)).copy_from(&k.coriolis.transpose());
            metric.view_mut((3, 3), (N, N)).copy_from(&k.a);
            inverse.view_mut((0, 0), (3, 3)).copy_from(&g.g11);
            inverse.view_mut((0, 3), (3, N)).copy_from(&g.g12);
            inverse.view_mut((3, 0), (N, 3)).copy_from(&g.g12.transpose());
            inverse.view_mut((3, 3), (N, N)).copy_from(&g.g22);
            let err = (&metric * &inverse - DMatrix::identity(d, d)).amax();
            assert!(err < 1e-12, "{}: M·M⁻¹ − 1 = {err:e}", m.name());
        }
    }
}

#[test]
fn g_matrices_are_the_blocks_of_the_inverse_metric() {
    common::for_each_well_conditioned_molecule(BlockInverse);
}

/// Wilson's G matrix of a bent XY2 in valence coordinates (r1, r2, α), X central.
fn wilson_g(q: &SVector<f64, 3>, m_x: f64, m_y: f64) -> rovib::runtime::nalgebra::Matrix3<f64> {
    let (r1, r2, a) = (q[0], q[1], q[2]);
    let (mux, muy) = (1.0 / m_x, 1.0 / m_y);
    let g11 = mux + muy;
    let g12 = a.cos() * mux;
    let g13 = -a.sin() / (r2 * m_x);
    let g23 = -a.sin() / (r1 * m_x);
    let g33 = (mux + muy) * (1.0 / (r1 * r1) + 1.0 / (r2 * r2)) - 2.0 * a.cos() / (r1 * r2 * m_x);
    rovib::runtime::nalgebra::Matrix3::new(g11, g12, g13, g12, g11, g23, g13, g23, g33)
}

#[test]
fn g22_of_water_is_wilsons_g_matrix() {
    let m = H2o;
    let masses = m.masses();
    let mut rng = Rng::new(13);
    let mut worst = 0f64;
    // Several geometries, from strongly bent to nearly linear, stretched and compressed.
    let mut geometries: Vec<SVector<f64, 3>> = (0..6).map(|_| random_q(&m, &mut rng)).collect();
    geometries.push(SVector::<f64, 3>::new(1.2, 2.5, 0.6));
    geometries.push(SVector::<f64, 3>::new(1.9, 1.7, 2.9));
    for q in geometries {
        let mut k = KineticMatrices::<3>::default();
        m.kinetic(&q, &mut k);
        let g22 = InverseMetric::new(&k, &q).unwrap().g.g22;
        let wilson = wilson_g(&q, masses[0], masses[1]);
        for i in 0..3 {
            for j in 0..3 {
                // Entry-wise relative error, with each entry's own scale.
                let scale = (wilson[(i, i)] * wilson[(j, j)]).sqrt();
                worst = worst.max((g22[(i, j)] - wilson[(i, j)]).abs() / scale);
            }
        }
    }
    assert!(worst < 1e-12, "G22 vs Wilson's G: {worst:e}");
    eprintln!("h2o: G22 vs Wilson's G, worst relative error {worst:.2e}");
}

/// ∂G/∂q_k from eqs. (10)–(14) agrees with finite differences of G.
#[derive(Copy, Clone)]
struct GDerivatives;
impl MoleculeVisitor for GDerivatives {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(14);
        let g_at = |x: &SVector<f64, N>| {
            let mut k = KineticMatrices::<N>::default();
            m.kinetic(x, &mut k);
            InverseMetric::new(&k, x).unwrap().g
        };
        for _ in 0..STATES {
            let q = random_q(&m, &mut rng);
            let mut k = KineticMatrices::<N>::default();
            m.kinetic(&q, &mut k);
            let metric = InverseMetric::new(&k, &q).unwrap();
            let mut dk = [KineticMatrices::<N>::default(); N];
            m.kinetic_jacobian(&q, &mut dk);
            for l in 0..N {
                let dg = metric.derivative(&dk[l]);
                let fd11 = common::central_difference(&q, l, |x| g_at(x).g11);
                let fd12 = common::central_difference(&q, l, |x| g_at(x).g12);
                let fd22 = common::central_difference(&q, l, |x| g_at(x).g22);
                let g = &metric.g;
                let e = [
                    rel_diff(&dg.g11, &fd11, g.g11.amax()),
                    rel_diff(&dg.g12, &fd12, g.g12.amax().max(g.g11.amax() * 1e-6)),
                    rel_diff(&dg.g22, &fd22, g.g22.amax()),
                ];
                for (name, err) in ["G11", "G12", "G22"].iter().zip(e) {
                    assert!(err < 1e-8, "{}: ∂{name}/∂q_{l} off by {err:e}", m.name());
                }
            }
        }
    }
}

#[test]
fn g_derivatives_match_finite_differences() {
    for_each_molecule(GDerivatives);
}

/// ∂H/∂φ = 0 exactly; J = W p_e; H written with J equals H written with p_e.
#[derive(Copy, Clone)]
struct Symmetries;
impl MoleculeVisitor for Symmetries {
    type Output = ();
    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) {
        let mut rng = Rng::new(15);
        let mut ws = Workspace::<N>::default();
        for _ in 0..STATES {
            let s = random_state(&m, &mut rng);
            let d = rhs(&m, &s, &mut ws).unwrap();
            assert_eq!(d.pe[0].to_bits(), 0f64.to_bits(), "ṗ_φ must be exactly +0");
            // H does not depend on φ at all: shifting φ changes nothing, to the bit.
            let mut shifted = s;
            shifted.euler[0] += 1.234;
            assert_eq!(hamiltonian(&m, &s).unwrap(), hamiltonian(&m, &shifted).unwrap());
            // H with J: ½ pᵀG22p + JᵀG12p + ½JᵀG11J + U, J = W p_e.
            let j = w_matrix(&s.euler).unwrap() * s.pe;
            let mut k = KineticMatrices::<N>::default();
            m.kinetic(&s.q, &mut k);
            let g = InverseMetric::new(&k, &s.q).unwrap().g;
            let h_j =
                0.5 * s.p.dot(&(g.g22 * s.p)) + j.dot(&(g.g12 * s.p)) + 0.5 * j.dot(&(g.g11 * j)) + m.potential(&s.q);
            let h = hamiltonian(&m, &s).unwrap();
            assert!((h - h_j).abs() <= 1e-13 * h.abs().max(1e-3), "{}: {h} vs {h_j}", m.name());
            assert_eq!(rovib::runtime::hamiltonian::body_angular_momentum(&s).unwrap(), j);
        }
    }
}

#[test]
fn p_phi_is_conserved_exactly_and_j_is_w_pe() {
    for_each_molecule(Symmetries);
}

#[test]
fn rigid_water_has_g11_equal_to_the_inverse_inertia() {
    let m = molecules::H2oRigid;
    let q = SVector::<f64, 0>::zeros();
    let mut k = KineticMatrices::<0>::default();
    m.kinetic(&q, &mut k);
    let g = InverseMetric::new(&k, &q).unwrap().g;
    let inv = k.inertia.try_inverse().unwrap();
    assert!((g.g11 - inv).amax() <= 1e-15 * inv.amax());
    let s = PhaseState::<0> { euler: [0.3, 1.1, -0.4].into(), pe: [2.0, -1.0, 3.0].into(), ..PhaseState::zeros() };
    let j = w_matrix(&s.euler).unwrap() * s.pe;
    let h = hamiltonian(&m, &s).unwrap();
    assert!((h - 0.5 * j.dot(&(inv * j))).abs() <= 1e-15 * h);
}
