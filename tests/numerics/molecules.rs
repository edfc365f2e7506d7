//! Physics sanity checks of the shipped molecules (h2o, co2, h2o2, nh3, ch4), as independent of
//! the generated code as each check allows:
//!
//! * the parametrization against the intrinsic coordinates of `common::internal_coordinates`:
//!   q computed back from the generated positions, after an arbitrary rotation and translation,
//!   is q again (to 1e-12);
//! * the torsion sign of h2o2 against the IUPAC convention;
//! * each model potential, as written in its definition file, against a transcription here
//!   evaluated on intrinsic coordinates (for ch4 this checks the dependent sixth angle);
//! * the equilibrium is a stationary point and a minimum (for CO2 at the linear geometry);
//! * harmonic wavenumbers by Wilson's GF method, F the Hessian of U by central differences of
//!   the generated gradient, G = G22 from `InverseMetric`, against the molecule's known
//!   harmonic wavenumbers or observed fundamentals (each test says which, and why its tolerance).

use crate::common;

use common::internal_coordinates::{self as ic, V3};
use common::{Rng, random_q};
use rovib::molecules::{Ch4, Co2, Ethane, H2o, H2o2, Nh3};
use rovib::runtime::hamiltonian::InverseMetric;
use rovib::runtime::nalgebra::{DMatrix, Rotation3, SMatrix, SVector, Vector3};
use rovib::runtime::units::{BOHR_IN_ANGSTROM, HARTREE_IN_WAVENUMBERS};
use rovib::runtime::{Kinematics, KineticMatrices, Molecule};

/// 1 aJ in cm⁻¹ (1e-18 J / (h c)), for quoting force constants.
const AJ_IN_WAVENUMBERS: f64 = 50_341.165_675;

/// The generated positions at q, moved into an arbitrary lab frame (rotated and translated), as
/// the plain arrays the intrinsic-coordinate functions take.
fn lab_positions<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    q: &SVector<f64, N>,
    rng: &mut Rng,
) -> Vec<V3<f64>> {
    let mut r = SMatrix::<f64, 3, NA>::zeros();
    m.positions(q, &mut r);
    let axis = Vector3::from_fn(|_, _| rng.uniform(-2.0, 2.0));
    let rotation = Rotation3::from_scaled_axis(axis);
    let shift = Vector3::from_fn(|_, _| rng.uniform(-5.0, 5.0));
    (0..NA)
        .map(|i| {
            let x = rotation * Vector3::from(r.column(i)) + shift;
            [x[0], x[1], x[2]]
        })
        .collect()
}

/// For random q near the reference, the intrinsic coordinates of the generated positions are q.
fn assert_round_trip<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, q_of_x: fn(&[V3<f64>]) -> Vec<f64>) {
    let mut rng = Rng::new(21);
    for _ in 0..20 {
        let q = random_q(m, &mut rng);
        let x = lab_positions(m, &q, &mut rng);
        let back = q_of_x(&x);
        assert_eq!(back.len(), N, "{}: q_of_x returns {} coordinates", m.name(), back.len());
        for k in 0..N {
            let err = (back[k] - q[k]).abs();
            assert!(
                err <= 1e-12 * q[k].abs().max(1.0),
                "{}: q_{k} = {} comes back as {} ({err:e})",
                m.name(),
                q[k],
                back[k]
            );
        }
    }
}

#[test]
fn intrinsic_coordinates_of_the_generated_positions_are_q() {
    assert_round_trip(&H2o, ic::h2o);
    assert_round_trip(&Co2, ic::co2);
    assert_round_trip(&H2o2, ic::h2o2);
    assert_round_trip(&Nh3, ic::nh3);
    assert_round_trip(&Ch4, ic::ch4);
    assert_round_trip(&Ethane, ic::ethane);
}

/// The h2o2 torsion is the IUPAC dihedral H1–O1–O2–H2: at τ = +90° with both O–O–H angles
/// 90°, looking along O1 → O2 the bond O1–H1 turns clockwise onto O2–H2 (the geometry of the
/// example in `dihedral`'s documentation: a = x̂, b = 0, c = ẑ, d = ẑ + ŷ), and τ = −90° is its
/// mirror image; the round trip holds for both signs.
#[test]
fn h2o2_torsion_has_the_iupac_sign() {
    let m = H2o2;
    let reference = m.reference_geometry().unwrap();
    for sign in [1.0, -1.0] {
        let mut q = reference;
        q[3] = std::f64::consts::FRAC_PI_2;
        q[4] = std::f64::consts::FRAC_PI_2;
        q[5] = sign * std::f64::consts::FRAC_PI_2;
        let mut r = SMatrix::<f64, 3, 4>::zeros();
        m.positions(&q, &mut r);
        let (o1, o2, h1, h2) = (r.column(0), r.column(1), r.column(2), r.column(3));
        // In the body frame O1 → O2 is +z and O1 → H1 is +x; O2 → H2 must be ±y.
        let (axis, b1, b2) = ((o2 - o1).normalize(), (h1 - o1).normalize(), (h2 - o2).normalize());
        assert!((axis - Vector3::z()).amax() < 1e-15 && (b1 - Vector3::x()).amax() < 1e-15);
        assert!((b2 - sign * Vector3::y()).amax() < 1e-15, "τ = {sign}·90°: O2–H2 along {b2:?}");
        let x: Vec<V3<f64>> = (0..4).map(|i| [r[(0, i)], r[(1, i)], r[(2, i)]]).collect();
        let tau = ic::dihedral(x[2], x[0], x[1], x[3]);
        assert!((tau - q[5]).abs() < 1e-15, "dihedral {tau} for τ = {}", q[5]);
    }
    let mut q = reference;
    q[5] = -q[5];
    let mut rng = Rng::new(22);
    let back = ic::h2o2(&lab_positions(&m, &q, &mut rng));
    assert!((back[5] - q[5]).abs() < 1e-12);
}

/// A length in bohr to ångström, and an energy in cm⁻¹ to hartree.
fn angstrom(bohr: f64) -> f64 {
    bohr * BOHR_IN_ANGSTROM
}

fn morse(d: f64, a: f64, re: f64, r_bohr: f64) -> f64 {
    d * (1.0 - (-a * (angstrom(r_bohr) - re)).exp()).powi(2)
}

/// Each definition's potential, transcribed from its header comment and evaluated on the
/// intrinsic coordinates of the generated positions (in cm⁻¹), against the generated potential.
fn assert_potential_matches<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    q_of_x: fn(&[V3<f64>]) -> Vec<f64>,
    model_cm: fn(&[V3<f64>], &[f64]) -> f64,
) {
    let mut rng = Rng::new(23);
    for _ in 0..20 {
        let q = random_q(m, &mut rng);
        let x = lab_positions(m, &q, &mut rng);
        let expected = model_cm(&x, &q_of_x(&x)) / HARTREE_IN_WAVENUMBERS;
        let u = m.potential(&q);
        assert!((u - expected).abs() <= 1e-12 * expected.abs().max(1e-6), "{}: U = {u} vs {expected}", m.name());
    }
}

#[test]
fn potentials_match_their_documented_models() {
    use std::f64::consts::PI;
    assert_potential_matches(&Co2, ic::co2, |_, q| {
        let (re, d, a) = (1.161288, 45441.0, 2.979220);
        morse(d, a, re, q[0])
            + morse(d, a, re, q[1])
            + 63499.57 * (angstrom(q[0]) - re) * (angstrom(q[1]) - re)
            + 0.5 * 39506.67 * (q[2] - PI).powi(2)
    });
    assert_potential_matches(&H2o2, ic::h2o2, |_, q| {
        let (reoo, reoh, the) = (1.45577728, 0.96253006, 101.08194717_f64.to_radians());
        let (doo, doh) = (angstrom(q[0]) - reoo, [angstrom(q[1]) - reoh, angstrom(q[2]) - reoh]);
        let dth = [q[3] - the, q[4] - the];
        let tau = q[5];
        morse(17086.0, 2.528913, reoo, q[0])
            + morse(30188.0, 2.592481, reoh, q[1])
            + morse(30188.0, 2.592481, reoh, q[2])
            + 0.5 * 47245.84 * (dth[0].powi(2) + dth[1].powi(2))
            - 5359.06 * doo * (doh[0] + doh[1])
            - 321.12 * doh[0] * doh[1]
            + 26953.71 * doo * (dth[0] + dth[1])
            - 1147.05 * (doh[0] * dth[0] + doh[1] * dth[1])
            - 22.40 * (doh[0] * dth[1] + doh[1] * dth[0])
            + 3895.54 * dth[0] * dth[1]
            + 795.72256
            + 1002.18481 * tau.cos()
            + 627.77744 * (2.0 * tau).cos()
            + 34.31519 * (3.0 * tau).cos()
    });
    assert_potential_matches(&Nh3, ic::nh3, |_, q| {
        let (re, ae) = (1.01092848, 106.7468338_f64.to_radians());
        let dr: Vec<f64> = q[..3].iter().map(|&r| angstrom(r) - re).collect();
        let da: Vec<f64> = q[3..].iter().map(|&a| a - ae).collect();
        q[..3].iter().map(|&r| morse(37114.0, 2.0879438, re, r)).sum::<f64>()
            - 356.73784 * (dr[0] * dr[1] + dr[0] * dr[2] + dr[1] * dr[2])
            + 0.5 * 27652.4291 * da.iter().map(|d| d * d).sum::<f64>()
            - 4008.0974 * (da[0] * da[1] + da[0] * da[2] + da[1] * da[2])
    });
    assert_potential_matches(&Ethane, ic::ethane, |x, q| {
        let (rcc, rch, te) = (1.53, 1.09, (-1.0_f64 / 3.0).acos());
        // The definition converts with 1 aJ = 50341.166 cm-1 (rounded).
        let aj = 50_341.166;
        let (fcc, fch, fb) = (4.5 * aj, 4.8 * aj, 0.65 * aj);
        let (dcc, dch) = (31500.0, 35400.0);
        let mut u = morse(dcc, (fcc / (2.0 * dcc)).sqrt(), rcc, q[0]);
        // Bond angles at each carbon from the positions: H-C-C' and H-C-H'.
        for (c, other, hs) in [(0, 1, [2, 3, 4]), (1, 0, [5, 6, 7])] {
            for (k, &h) in hs.iter().enumerate() {
                u += morse(dch, (fch / (2.0 * dch)).sqrt(), rch, ic::distance(x[h], x[c]));
                u += 0.5 * fb * (ic::angle(x[h], x[c], x[other]) - te).powi(2);
                for &h2 in &hs[k + 1..] {
                    u += 0.5 * fb * (ic::angle(x[h], x[c], x[h2]) - te).powi(2);
                }
            }
        }
        // Three-fold torsion in the dihedrals H1a-C1-C2-H2x.
        for h in 5..8 {
            u += 1000.0 / 6.0 * (1.0 + (3.0 * ic::dihedral(x[2], x[0], x[1], x[h])).cos());
        }
        u
    });
    assert_potential_matches(&Ch4, ic::ch4, |x, q| {
        let (re, ae) = (1.0858, (-1.0_f64 / 3.0).acos());
        let dr: Vec<f64> = q[..4].iter().map(|&r| angstrom(r) - re).collect();
        // All six H–C–H angles from the positions, the dependent α34 included.
        let pairs = [(1, 2), (1, 3), (2, 3), (1, 4), (2, 4), (3, 4)];
        let da: Vec<f64> = pairs.iter().map(|&(i, j)| ic::angle(x[i], x[0], x[j]) - ae).collect();
        let mut stretch_pairs = 0.0;
        for i in 0..4 {
            for j in i + 1..4 {
                stretch_pairs += dr[i] * dr[j];
            }
        }
        // Angle pairs sharing a hydrogen ("adjacent"); opposite pairs (no common H) uncoupled.
        let mut adjacent = 0.0;
        for i in 0..6 {
            for j in i + 1..6 {
                let ((a, b), (c, d)) = (pairs[i], pairs[j]);
                if a == c || a == d || b == c || b == d {
                    adjacent += da[i] * da[j];
                }
            }
        }
        q[..4].iter().map(|&r| morse(36160.0, 1.8463825, re, r)).sum::<f64>()
            + 2600.5695 * stretch_pairs
            + 0.5 * 25125.548 * da.iter().map(|d| d * d).sum::<f64>()
            - 1258.8093 * adjacent
    });
}

/// The Hessian of U at q by central differences of the generated gradient (symmetrized).
fn hessian<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, q: &SVector<f64, N>) -> SMatrix<f64, N, N> {
    let mut h = SMatrix::<f64, N, N>::zeros();
    for k in 0..N {
        let step = 1e-4;
        let grad_at = |t: f64| {
            let mut x = *q;
            x[k] += t;
            let mut g = SVector::<f64, N>::zeros();
            m.potential_gradient(&x, &mut g);
            g
        };
        // Fourth-order central difference.
        let column =
            (grad_at(-2.0 * step) - 8.0 * grad_at(-step) + 8.0 * grad_at(step) - grad_at(2.0 * step)) / (12.0 * step);
        h.set_column(k, &column);
    }
    (h + h.transpose()) * 0.5
}

/// Harmonic wavenumbers in cm⁻¹, ascending: the eigenvalues λ of G·F are ω² in atomic units
/// (hartree / (bohr² m_e), ħ = 1), so ħω = √λ hartree. Computed as the eigenvalues of the
/// symmetric Lᵀ F L with G = L Lᵀ.
fn gf_wavenumbers<const N: usize>(g: &SMatrix<f64, N, N>, f: &SMatrix<f64, N, N>) -> Vec<f64> {
    let l = g.cholesky().expect("G22 is positive definite").l();
    let s = l.transpose() * f * l;
    let s = DMatrix::from_fn(N, N, |i, j| 0.5 * (s[(i, j)] + s[(j, i)]));
    let mut w: Vec<f64> = s
        .symmetric_eigenvalues()
        .iter()
        .map(|&lambda| {
            assert!(lambda > 0.0, "the equilibrium is not a minimum: λ = {lambda}");
            lambda.sqrt() * HARTREE_IN_WAVENUMBERS
        })
        .collect();
    w.sort_by(f64::total_cmp);
    w
}

/// G22 at q from the generated kinetic matrices.
fn g22<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, q: &SVector<f64, N>) -> SMatrix<f64, N, N> {
    let mut k = KineticMatrices::<N>::default();
    m.kinetic(q, &mut k);
    InverseMetric::new(&k, q).expect("the metric is regular here").g.g22
}

/// ∂U/∂q at q is zero: every component is below `tolerance` times the matching diagonal
/// Hessian element, i.e. the true minimum is less than `tolerance` (bohr or rad) away.
fn assert_stationary<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    q: &SVector<f64, N>,
    f: &SMatrix<f64, N, N>,
    tolerance: f64,
) {
    let mut g = SVector::<f64, N>::zeros();
    m.potential_gradient(q, &mut g);
    for k in 0..N {
        let shift = g[k].abs() / f[(k, k)];
        assert!(shift < tolerance, "{}: ∂U/∂q_{k} = {:e} at the equilibrium (minimum {shift:e} away)", m.name(), g[k]);
    }
}

/// `model` matches `reference` mode by mode (both ascending) within `tolerance` (relative).
fn assert_wavenumbers(name: &str, model: &[f64], reference: &[f64], tolerance: f64) {
    eprintln!("{name}: harmonic wavenumbers {model:.1?} cm-1, reference {reference:.1?}");
    assert_eq!(model.len(), reference.len());
    for (w, r) in model.iter().zip(reference) {
        assert!((w - r).abs() <= tolerance * r, "{name}: {w:.1} cm-1 vs {r:.1} (tolerance {:.0} %)", 100.0 * tolerance);
    }
}

/// Water: h2o.toml promises about 3830, 1650 and 3940 cm-1 against water's harmonic wavenumbers
/// 3832, 1649 and 3943 cm-1 (Benedict, Gailar & Plyler, J. Chem. Phys. 24, 1139 (1956)) within
/// 2 %. The model gives 1646.4, 3831.5 and 3942.0 cm-1.
#[test]
fn water_harmonic_wavenumbers() {
    let m = H2o;
    let q = m.reference_geometry().unwrap();
    let f = hessian(&m, &q);
    assert_stationary(&m, &q, &f, 1e-9);
    let w = gf_wavenumbers(&g22(&m, &q), &f);
    assert_wavenumbers("h2o", &w, &[1648.5, 3832.2, 3942.5], 0.02);
}

/// CO2: the equilibrium (re, re, π) is linear and is the reference geometry, where G22 cannot be
/// had (the inertia tensor is singular); G22 is smooth there (Wilson's G of a bent XY2 deviates
/// by O((π − α)²)), so it is taken at α = π − 10⁻³ rad. F at exactly π. Reference: the harmonic
/// wavenumbers ω2 = 672.85, ω1 = 1354.31 (Fermi-deperturbed), ω3 = 2396.32 cm-1 the force
/// constants were derived from (co2.toml), within 0.1 %: this checks the kinetic code path near
/// linearity and the conversions, not the physics of the constants. (`rovib freq` gives all
/// four modes at exactly linear from the Cartesian Hessian, tests/freq.rs.)
#[test]
fn co2_is_linear_at_equilibrium_and_has_its_harmonic_wavenumbers() {
    let m = Co2;
    let linear = m.reference_geometry().unwrap();
    assert_eq!(linear[2], std::f64::consts::PI, "co2 ships its linear equilibrium as the reference");
    let f = hessian(&m, &linear);
    assert_stationary(&m, &linear, &f, 1e-9);
    let mut near = linear;
    near[2] -= 1e-3;
    let w = gf_wavenumbers(&g22(&m, &near), &f);
    assert_wavenumbers("co2", &w, &[672.85, 1354.31, 2396.32], 1e-3);
}

/// The shared tests draw angles within ±0.15 rad of `chart_centre`: for co2's linear reference
/// that is 130°, so the neighbourhood stays at least 0.72 rad (41°) from the singular linear
/// geometry, where the truncation error of the shared tests' central differences of G11 (step
/// 1e-3 α) stays below ≈ 4e-9; the reference itself is singular for the Euler chart.
#[test]
fn co2_test_neighbourhood_stays_away_from_linear() {
    let centre = common::chart_centre(&Co2);
    assert!(!common::euler_chart_regular(&Co2, &Co2.reference_geometry().unwrap()));
    assert!((centre[2] - 130f64.to_radians()).abs() < 1e-12, "{}", centre[2]);
    assert!(std::f64::consts::PI - (centre[2] + 0.15) > 0.72);
}

/// H2O2: the model's quadratic force field is that of an ab initio surface, so its harmonic
/// wavenumbers are compared with the observed fundamentals (gas phase: ν3 = 865.9 (O–O
/// stretch), ν6 = 1264.6 and ν2 = 1395.9 (OOH bends), ν1 = 3609.8 and ν5 = 3610.7 cm-1 (O–H
/// stretches); Olson et al., J. Mol. Spectrosc. 127, 12 (1988); Perrin et al. (1990)). Harmonic
/// wavenumbers exceed fundamentals by the anharmonic shift, 2-5 % here (most for the O–H
/// stretches), so the check is 0 ≤ (ω − ν)/ν ≤ 6 %. The torsion (large-amplitude, tunnelling
/// through the trans barrier: its fundamental is not a harmonic quantity) is checked against
/// the curvature of the model's own cosine series instead: ω = √(k_τ G_ττ) with
/// k_τ = 1875.9 cm-1/rad² (h2o2.toml), about 388 cm-1.
#[test]
fn h2o2_equilibrium_and_wavenumbers() {
    let m = H2o2;
    let q = m.reference_geometry().unwrap();
    let f = hessian(&m, &q);
    assert_stationary(&m, &q, &f, 1e-7);
    let g = g22(&m, &q);
    let w = gf_wavenumbers(&g, &f);
    eprintln!("h2o2: harmonic wavenumbers {w:.1?} cm-1");
    let observed = [865.9, 1264.6, 1395.9, 3609.8, 3610.7];
    for (omega, nu) in w[1..].iter().zip(observed) {
        let shift = (omega - nu) / nu;
        assert!(
            (0.0..=0.06).contains(&shift),
            "h2o2: harmonic {omega:.1} vs fundamental {nu} cm-1 ({:.1} %)",
            100.0 * shift
        );
    }
    let k_tau = 1875.9 / HARTREE_IN_WAVENUMBERS;
    let torsion = (k_tau * g[(5, 5)]).sqrt() * HARTREE_IN_WAVENUMBERS;
    // The lowest normal mode is nearly the pure torsion (its couplings are small).
    assert!((w[0] - torsion).abs() < 0.05 * torsion, "h2o2: torsion {:.1} vs {torsion:.1} cm-1", w[0]);
    assert!((w[0] - 388.3).abs() < 0.01 * 388.3, "h2o2: torsion {:.1} cm-1", w[0]);
    // The barriers of the cosine series: cis 2460, trans 387 cm-1 above the minimum.
    let u_at = |tau: f64| {
        let mut x = q;
        x[5] = tau;
        (m.potential(&x) - m.potential(&q)) * HARTREE_IN_WAVENUMBERS
    };
    assert!((u_at(0.0) - 2460.0).abs() < 1e-3, "cis barrier {}", u_at(0.0));
    assert!((u_at(std::f64::consts::PI) - 387.0).abs() < 1e-3, "trans barrier {}", u_at(std::f64::consts::PI));
}

/// NH3 and CH4: the effective force fields were solved to reproduce the observed fundamentals
/// (Shimanouchi: NH3 950 (mean of the inversion doublet), 1627 (E), 3337, 3444 (E); CH4 1306
/// (F2), 1534 (E), 2917, 3019 (F2) cm-1) with an independent GF calculation (analytic Wilson B
/// matrix by finite differences of the intrinsic coordinates); this checks the generated
/// positions, kinetic matrices, G22 and the transcription of the constants, to 0.1 %, and the
/// degeneracies of the symmetric molecules to 1e-6.
#[test]
fn nh3_equilibrium_and_wavenumbers() {
    let m = Nh3;
    let q = m.reference_geometry().unwrap();
    let f = hessian(&m, &q);
    assert_stationary(&m, &q, &f, 1e-7);
    let w = gf_wavenumbers(&g22(&m, &q), &f);
    assert_wavenumbers("nh3", &w, &[950.0, 1627.0, 1627.0, 3337.0, 3444.0, 3444.0], 1e-3);
    assert!((w[1] - w[2]).abs() < 1e-6 * w[1] && (w[4] - w[5]).abs() < 1e-6 * w[4], "E pairs: {w:?}");
}

#[test]
fn ch4_equilibrium_and_wavenumbers() {
    let m = Ch4;
    // The equilibrium: all bonds 1.0858 Å, tetrahedral angles (the reference geometry is not
    // the equilibrium, see ch4.toml).
    let (re, ae) = (1.0858 / BOHR_IN_ANGSTROM, (-1.0_f64 / 3.0).acos());
    let q = SVector::<f64, 9>::from_fn(|k, _| if k < 4 { re } else { ae });
    let reference = m.reference_geometry().unwrap();
    assert!((reference[0] - re).abs() < 1e-12 && (reference[5] - ae).abs() < 1e-15);
    let f = hessian(&m, &q);
    assert_stationary(&m, &q, &f, 1e-7);
    let w = gf_wavenumbers(&g22(&m, &q), &f);
    assert_wavenumbers("ch4", &w, &[1306.0, 1306.0, 1306.0, 1534.0, 1534.0, 2917.0, 3019.0, 3019.0, 3019.0], 1e-3);
    for (a, b) in [(0, 1), (1, 2), (3, 4), (6, 7), (7, 8)] {
        assert!((w[a] - w[b]).abs() < 1e-6 * w[a], "ch4 degenerate modes {a}, {b}: {w:?}");
    }
}

/// The force constants quoted in the definitions are consistent with 1 aJ = 50341.17 cm-1.
#[test]
fn quoted_force_constant_conversion() {
    // h = 6.626 070 15e-34 J s, c = 2.997 924 58e10 cm/s (exact SI values).
    let aj = 1e-18 / (6.626_070_15e-34 * 2.997_924_58e10);
    assert!((aj - AJ_IN_WAVENUMBERS).abs() < 1e-4);
    assert!((0.784_779 * AJ_IN_WAVENUMBERS - 39_506.67).abs() < 0.05);
}

/// Ethane's torsional barrier: the eclipsed geometry (C2's azimuths turned by 60°) lies exactly
/// V3 = 1000 cm⁻¹ above the staggered reference, and the reference is a stationary point.
#[test]
fn ethane_torsional_barrier_is_v3() {
    let m = Ethane;
    let q0 = m.reference_geometry().unwrap();
    let names = m.coordinates().map(|c| c.name);
    let mut eclipsed = q0;
    for h in ["d_H2a", "d_H2b", "d_H2c"] {
        let k = names.iter().position(|&n| n == h).unwrap();
        eclipsed[k] -= 60f64.to_radians();
    }
    let barrier = (m.potential(&eclipsed) - m.potential(&q0)) * HARTREE_IN_WAVENUMBERS;
    assert!((barrier - 1000.0).abs() < 1e-8, "barrier {barrier} cm-1");
    let mut grad = SVector::zeros();
    m.potential_gradient(&q0, &mut grad);
    assert!(grad.amax() < 1e-12, "gradient at the reference {grad:?}");
}
