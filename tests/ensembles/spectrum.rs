//! The classical IR spectrum of an ensemble (`spectrum.csv`), checked against what is known
//! independently of rovib's dynamics:
//!
//! - at low temperature the bands sit at the harmonic wavenumbers of `rovib freq` (an
//!   independent GF calculation, itself checked against a Cartesian Hessian in tests/freq.rs),
//!   within half the stated resolution 1/(cT);
//! - the integrated band intensities follow the double-harmonic formula
//!   (2π²/3c)|∂μ/∂Q_k|² (docs/src/reference/equations.md, section 11), with ∂μ/∂Q_k computed here from the
//!   definition's point charges and the atoms' displacements along the mode (not from the
//!   generated dipole code);
//! - the pure rotational band of a rigid symmetric top follows the classical rigid-rotor
//!   envelope, computed here by quadrature over the Boltzmann distribution of J.
//!
//! Each ensemble is small and short (a few seconds in the test profile); the tolerances come
//! from the standard errors stated at each check.

use crate::common;

use std::path::{Path, PathBuf};

use common::ensemble::{column, options};
use rovib::ensemble::run_ensemble;
use rovib::freq::frequencies;
use rovib::molecules::{H2o, Hcn, Nh3};
use rovib::runtime::modes::{NormalModes, stationary_point};
use rovib::runtime::nalgebra::{Matrix3, SMatrix, SVector, SymmetricEigen, Vector3};
use rovib::runtime::spectrum::{BOLTZMANN_HARTREE_PER_K, QuantumCorrection, Spectrum, double_harmonic_km_per_mol};
use rovib::runtime::surface::Dipole;
use rovib::runtime::units::HARTREE_IN_WAVENUMBERS;
use rovib::runtime::{HasKinematics, Kinematics, Molecule};
use rovib::scene::parse_scene;

/// Water's fixed charges from molecules/h2o.toml (O, H1, H2), e.
const WATER_CHARGES: [f64; 3] = [-2.0 * 0.32922, 0.32922, 0.32922];

/// Ammonia's fixed charges from molecules/nh3.toml (N, H1, H2, H3), e.
const AMMONIA_CHARGES: [f64; 4] = [-3.0 * 0.268515, 0.268515, 0.268515, 0.268515];

fn temp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-spectrum-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Runs the ensemble scene `text` into `dir` and reads its spectrum.csv back as a [`Spectrum`]
/// (line shape only), with the columns of the file.
fn run_spectrum(text: &str, dir: &Path) -> (Spectrum, Vec<String>, Vec<Vec<f64>>) {
    let scene = parse_scene("ir.toml", text).unwrap();
    let report = run_ensemble(&scene, &options(dir.to_owned(), 2)).unwrap();
    assert_eq!(report.outcome.completed, report.requested, "every trajectory completes");
    read_spectrum(dir)
}

/// `dir/spectrum.csv`: the line shape with the trajectory length from the file's comment line,
/// and the header and rows of the file.
fn read_spectrum(dir: &Path) -> (Spectrum, Vec<String>, Vec<Vec<f64>>) {
    let csv = std::fs::read_to_string(dir.join("spectrum.csv")).unwrap();
    let mut lines = csv.lines();
    let comment = lines.next().unwrap();
    let length: f64 = comment.split_whitespace().nth(10).unwrap().parse().unwrap();
    let header: Vec<String> = lines.next().unwrap().split(',').map(str::to_owned).collect();
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    let (nu, shape) = (column(&header, "wavenumber_cm-1"), column(&header, "lineshape_e2bohr2_per_hartree"));
    let s = Spectrum {
        wavenumber: rows.iter().map(|r| r[nu]).collect(),
        lineshape: rows.iter().map(|r| r[shape]).collect(),
        length,
    };
    (s, header, rows)
}

/// ∫ I(ω) dω over [low, high] cm⁻¹ (piecewise linear on the file's grid), e²·bohr².
fn lineshape_integral(s: &Spectrum, low: f64, high: f64) -> f64 {
    s.integral(&s.lineshape, low, high) / HARTREE_IN_WAVENUMBERS
}

const BANDS_SCENE: &str = r#"molecule = "h2o"
[ensemble]
trajectories = 8
seed = 7
method = "thermal"
temperature = 10.0
region = { energy_cap = 0.01 }
[statistics]
means = ["H"]
correlations = ["mu_x", "mu_y", "mu_z"]
[integrator]
method = "dop853"
rtol = 1e-9
atol = 1e-9
[run]
end = 100000.0
output_interval = 20.0
"#;

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 15 s unoptimised on a loaded 2-core machine"]
fn low_temperature_bands_sit_at_the_harmonic_wavenumbers() {
    let dir = temp_dir("bands");
    let (s, header, rows) = run_spectrum(BANDS_SCENE, &dir);
    let resolution = s.resolution();
    let (nu, sigma) = (column(&header, "wavenumber_cm-1"), column(&header, "sigma_harmonic_cm2"));
    // T = 1e5 a.u. = 2.42 ps: 1.441/(cT) = 19.9 cm-1.
    assert!((resolution - 19.87).abs() < 0.05, "resolution {resolution}");
    let harmonic = frequencies("h2o").unwrap().wavenumbers;
    for &w in &harmonic {
        // The band's centroid within ±50 cm-1 (the bands are 111 cm-1 apart or more; the
        // rotational contour at 10 K is ±20 cm-1 wide).
        let band: Vec<&Vec<f64>> = rows.iter().filter(|r| (r[nu] - w).abs() < 50.0).collect();
        let weight: f64 = band.iter().map(|r| r[sigma]).sum();
        let centroid = band.iter().map(|r| r[nu] * r[sigma]).sum::<f64>() / weight;
        assert!(weight > 0.0);
        assert!(
            (centroid - w).abs() < resolution / 2.0,
            "band at {centroid:.2} cm-1, harmonic {w:.2} cm-1 (resolution {resolution:.2})"
        );
        let wide: f64 = rows.iter().filter(|r| (r[nu] - w).abs() < 150.0).map(|r| r[sigma]).sum();
        println!(
            "band {w:.1} cm-1: centroid {centroid:.2} cm-1, {:.2} of the absorption within ±150 cm-1",
            weight / wide
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The lab-frame dipole derivative along each normal mode of water (e·bohr per bohr·√m_e),
/// from the charges and the atoms' displacements: `δR_i = Σ_j ∂R_i/∂q_j l_jk`, plus the small
/// rotation `δθ = −I⁻¹ Σ_i m_i R_i × δR_i` that keeps the angular momentum of the displacement
/// zero (a vibration at J = 0 turns the body frame of the definition; the lab frame does not
/// turn), then `∂μ/∂Q_k = Σ_i q_i (δR_i + δθ × R_i)`. With the harmonic wavenumbers.
fn water_dipole_derivatives(rotation_term: bool) -> Vec<(f64, Vector3<f64>)> {
    let m = H2o;
    let q0 = stationary_point(&m, &m.reference_geometry().unwrap()).unwrap();
    let modes = NormalModes::at(&m, &q0).unwrap();
    let mut r = SMatrix::<f64, 3, 3>::zeros();
    m.positions(&q0, &mut r);
    let mut dr = [SMatrix::<f64, 3, 3>::zeros(); 3];
    m.positions_jacobian(&q0, &mut dr);
    let masses: Vec<f64> = m.atoms().iter().map(|a| a.mass).collect();
    let mut inertia = Matrix3::zeros();
    for (i, &mass) in masses.iter().enumerate() {
        let x: Vector3<f64> = r.column(i).into();
        inertia += mass * (Matrix3::identity() * x.dot(&x) - x * x.transpose());
    }
    let inverse = inertia.try_inverse().unwrap();
    (0..3)
        .map(|k| {
            let mut d = SMatrix::<f64, 3, 3>::zeros();
            for (j, drj) in dr.iter().enumerate() {
                d += drj * modes.vectors[(j, k)];
            }
            let mut h = Vector3::zeros();
            for (i, &mass) in masses.iter().enumerate() {
                let (x, dx): (Vector3<f64>, Vector3<f64>) = (r.column(i).into(), d.column(i).into());
                h += mass * x.cross(&dx);
            }
            let theta = if rotation_term { -inverse * h } else { Vector3::zeros() };
            let mut dmu = Vector3::zeros();
            for (i, &charge) in WATER_CHARGES.iter().enumerate() {
                let (x, dx): (Vector3<f64>, Vector3<f64>) = (r.column(i).into(), d.column(i).into());
                dmu += charge * (dx + theta.cross(&x));
            }
            (modes.omega[k] * HARTREE_IN_WAVENUMBERS, dmu)
        })
        .collect()
}

/// Water at 10 K with every normal mode at its thermal mean energy kT (random phases; the
/// rotation thermal at 10 K): for a harmonic mode with a linear dipole this has the same
/// ⟨Q_k(0)Q_k(t)⟩ = (kT/ω_k²) cos ω_k t as the canonical ensemble, without the exponential
/// scatter of a canonical mode energy (relative standard deviation 1 per trajectory), so a few
/// trajectories per batch suffice.
fn intensity_scene(seed: u64) -> String {
    let kt = BOLTZMANN_HARTREE_PER_K * INTENSITY_KELVIN;
    format!(
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = 6\nseed = {seed}\nmethod = \"normal-modes\"\n\
         mode_energies = [{kt:e}, {kt:e}, {kt:e}]\ntemperature = {INTENSITY_KELVIN}\n[statistics]\nmeans = [\"H\"]\n\
         correlations = [\"mu_x\", \"mu_y\", \"mu_z\"]\n[integrator]\nmethod = \"dop853\"\nrtol = 1e-9\n\
         atol = 1e-9\n[run]\nend = 80000.0\noutput_interval = 25.0\n"
    )
}

const INTENSITY_KELVIN: f64 = 10.0;

/// Half-width of the window integrated around each band, cm⁻¹: for T = 80 000 a.u. the
/// resolution (FWHM) is 24.8 cm⁻¹ and the Hann line is ±34.5 cm⁻¹ wide at its base, the
/// rotational contour at 10 K about ±20 cm⁻¹; the two stretching bands are 102 cm⁻¹ apart.
const BAND_HALF_WIDTH: f64 = 51.0;

/// Batches (independent seeds) whose spread gives the standard error.
const BATCHES: u64 = 4;

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 46 s unoptimised on a loaded 2-core machine"]
fn integrated_band_intensities_follow_the_double_harmonic_formula() {
    let derivatives = water_dipole_derivatives(true);
    let mut per_batch: Vec<Vec<f64>> = Vec::new();
    for b in 0..BATCHES {
        let dir = temp_dir(&format!("intensity{b}"));
        let (s, _, _) = run_spectrum(&intensity_scene(100 + b), &dir);
        let sigma = s.cross_section(INTENSITY_KELVIN, QuantumCorrection::Harmonic);
        per_batch.push(
            derivatives
                .iter()
                .map(|(w, _)| s.band_intensity(&sigma, w - BAND_HALF_WIDTH, w + BAND_HALF_WIDTH))
                .collect(),
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
    let without_rotation = water_dipole_derivatives(false);
    for (k, (w, dmu)) in derivatives.iter().enumerate() {
        let expected = double_harmonic_km_per_mol(dmu.norm_squared());
        let values: Vec<f64> = per_batch.iter().map(|v| v[k]).collect();
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let se = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
        // Tolerance: 5 standard errors of the batch mean (Student's t with 3 degrees of
        // freedom exceeds 5.84 with probability 1 %; 5 SE is about 1.5 %), plus 2 % for what the
        // double-harmonic formula leaves out at 10 K and what the window loses (anharmonicity
        // O(kT/D) ~ 1e-4, Coriolis coupling with the rotation at J ~ 1, the Hann side lobes
        // beyond ±51 cm⁻¹ ~ 0.3 %).
        let tolerance = 5.0 * se + 0.02 * expected;
        let wrong_frame = double_harmonic_km_per_mol(without_rotation[k].1.norm_squared());
        println!(
            "band {w:.1} cm-1: {mean:.4} ± {se:.4} km/mol (batches {values:.4?}), double harmonic {expected:.4} \
             km/mol (without the frame's rotation {wrong_frame:.4})"
        );
        assert!(
            (mean - expected).abs() < tolerance,
            "band {w:.1} cm-1: integrated {mean} km/mol, double harmonic {expected} km/mol (tolerance {tolerance})"
        );
    }
}

/// The classical pure rotational band of a rigid symmetric top whose dipole μ lies along its
/// figure axis. The figure axis precesses about the fixed angular momentum L at Ω = |L|/I_⊥
/// (whatever K), on a cone of half-angle θ with cos θ = L_∥/|L|, so
/// `μ_lab(0)·μ_lab(t) = μ² (cos²θ + sin²θ cos Ωt)`, and the line shape for ω > 0 is
/// `I(ω) = ½ μ² ⟨sin²θ δ(ω − |L|/I_⊥)⟩` over the Boltzmann distribution of L (Gaussian
/// components with variances kT·I_⊥, kT·I_⊥, kT·I_∥ along the principal axes).
/// Returns `E[sin²θ; Ω ∈ [a, b]]` and `E[sin⁴θ; Ω ∈ [a, b]]` (a, b in hartree) by quadrature.
fn symmetric_top_band(i_perp: f64, i_par: f64, kt: f64, a: f64, b: f64) -> (f64, f64) {
    let (s_perp, s_par) = ((i_perp * kt).sqrt(), (i_par * kt).sqrt());
    let norm = (2.0 * std::f64::consts::PI).powf(-1.5) / (s_perp * s_perp * s_par);
    // Simpson in |L| over the bin and in u = cos θ over [−1, 1] (even, so [0, 1] twice).
    let simpson = |n: usize, lo: f64, hi: f64, f: &dyn Fn(f64) -> f64| {
        let h = (hi - lo) / n as f64;
        (0..=n)
            .map(|i| {
                let w = if i == 0 || i == n {
                    1.0
                } else if i % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                w * f(lo + i as f64 * h)
            })
            .sum::<f64>()
            * h
            / 3.0
    };
    let moment = |power: i32| {
        simpson(400, a * i_perp, b * i_perp, &|l: f64| {
            let inner = simpson(400, 0.0, 1.0, &|u: f64| {
                let s2 = 1.0 - u * u;
                s2.powi(power) * (-(l * l) * (s2 / (2.0 * s_perp * s_perp) + u * u / (2.0 * s_par * s_par))).exp()
            });
            2.0 * std::f64::consts::PI * l * l * norm * 2.0 * inner
        })
    };
    (moment(1), moment(2))
}

/// Ammonia held rigid at its equilibrium (every coordinate frozen, no vibrational energy; J
/// thermal at 300 K): a symmetric top with its dipole along the C3 axis.
const ROTOR_KELVIN: f64 = 300.0;
const ROTOR_TRAJECTORIES: u64 = 2000;
const ROTOR_SCENE: &str = r#"molecule = "nh3"
[ensemble]
trajectories = 2000
seed = 13
method = "normal-modes"
mode_energies = [0, 0, 0, 0, 0, 0]
temperature = 300.0
[statistics]
means = ["H"]
correlations = ["mu_x", "mu_y", "mu_z"]
[integrator]
method = "dop853"
rtol = 1e-8
atol = 1e-8
[run]
end = 110000.0
output_interval = 250.0
frozen = ["r1", "r2", "r3", "a12", "a13", "a23"]
"#;

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 151 s unoptimised on a loaded 2-core machine"]
fn a_rigid_symmetric_top_follows_the_classical_rotational_envelope() {
    // Independent of the dynamics: the principal moments and the dipole from the definition's
    // masses, positions at the minimum and charges.
    let m = Nh3;
    let q0 = stationary_point(&m, &m.reference_geometry().unwrap()).unwrap();
    let mut r = SMatrix::<f64, 3, 4>::zeros();
    m.positions(&q0, &mut r);
    let mut inertia = Matrix3::zeros();
    let mut mu = Vector3::zeros();
    for (i, atom) in m.atoms().iter().enumerate() {
        let x: Vector3<f64> = r.column(i).into();
        inertia += atom.mass * (Matrix3::identity() * x.dot(&x) - x * x.transpose());
        mu += AMMONIA_CHARGES[i] * x;
    }
    let eig = SymmetricEigen::new(inertia);
    let mut order = [0, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    let (i1, i2, i3) = (eig.eigenvalues[order[0]], eig.eigenvalues[order[1]], eig.eigenvalues[order[2]]);
    // Oblate: I_⊥ = I1 = I2 < I_∥ = I3, and μ along the unique axis.
    assert!((i1 - i2).abs() < 1e-9 * i1 && i3 > i2 * 1.2, "moments {i1} {i2} {i3}");
    let axis: Vector3<f64> = eig.eigenvectors.column(order[2]).into();
    assert!((mu.dot(&axis).abs() / mu.norm() - 1.0).abs() < 1e-9);
    let (i_perp, i_par, mu2) = (i1, i3, mu.norm_squared());

    let dir = temp_dir("rotor");
    let (s, _, _) = run_spectrum(ROTOR_SCENE, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    let kt = BOLTZMANN_HARTREE_PER_K * ROTOR_KELVIN;
    let n = ROTOR_TRAJECTORIES as f64;
    // Bins of 40 cm⁻¹ from 20 cm⁻¹ (below, a trajectory slower than a few turns in T loses
    // part of its line to the subtraction of its time mean): the resolution is 9.1 cm⁻¹.
    let mut total = (0.0, 0.0, 0.0);
    for bin in 0..9 {
        let (lo, hi) = (20.0 + 40.0 * bin as f64, 60.0 + 40.0 * bin as f64);
        let (a, b) = (lo / HARTREE_IN_WAVENUMBERS, hi / HARTREE_IN_WAVENUMBERS);
        let (s1, s2) = symmetric_top_band(i_perp, i_par, kt, a, b);
        let expected = 0.5 * mu2 * s1;
        // One trajectory puts its whole line ½ μ² sin²θ into one bin: the per-trajectory
        // variance of the bin integral is ¼ μ⁴ E[sin⁴θ; bin] − expected².
        let se = ((0.25 * mu2 * mu2 * s2 - expected * expected) / n).sqrt();
        let found = lineshape_integral(&s, lo, hi);
        println!("{lo:>4.0}-{hi:<4.0} cm-1: {found:.5e} e2bohr2, envelope {expected:.5e} ± {se:.1e}");
        // 4 standard errors, plus 1 % of the bin for the window's spread across bin edges.
        assert!(
            (found - expected).abs() < 4.0 * se + 0.01 * expected,
            "bin {lo}-{hi} cm-1: {found:e}, classical envelope {expected:e} (standard error {se:e})"
        );
        total.0 += found;
        total.1 += expected;
        total.2 += 0.25 * mu2 * mu2 * s2;
    }
    // The whole band from 20 to 380 cm⁻¹: the bins are disjoint, so the variance per trajectory
    // is Σ ¼μ⁴ E[sin⁴θ; bin] − (Σ expected)².
    let se = ((total.2 - total.1 * total.1) / n).sqrt();
    println!("20-380 cm-1: {:.5e}, envelope {:.5e} ± {se:.1e}", total.0, total.1);
    assert!((total.0 - total.1).abs() < 4.0 * se + 0.01 * total.1, "20-380 cm-1: {} against {}", total.0, total.1);
}

/// HCN (molecules/hcn.toml, which has no dipole surface) with a point-charge dipole of this
/// test's own, `μ = Σ_i q_i R_i` about the centre of mass: linear at its minimum, so its
/// stretching bands are parallel bands with a P and an R branch and no Q branch.
#[derive(Copy, Clone)]
struct ChargedHcn;

/// The test dipole's charges (H, C, N), e: a model, not HCN's; only the band's shape matters.
const HCN_CHARGES: [f64; 3] = [0.2, 0.2, -0.4];

impl HasKinematics<3, 3> for ChargedHcn {
    type Kinematics = Hcn;
    fn kinematics(&self) -> &Hcn {
        &Hcn
    }
}

impl Molecule<3, 3> for ChargedHcn {
    fn potential(&self, q: &SVector<f64, 3>) -> f64 {
        Hcn.potential(q)
    }
    fn potential_gradient(&self, q: &SVector<f64, 3>, grad: &mut SVector<f64, 3>) -> f64 {
        Hcn.potential_gradient(q, grad)
    }
    fn cartesian_potential(&self, x: &SMatrix<f64, 3, 3>) -> Option<f64> {
        Hcn.cartesian_potential(x)
    }
    fn cartesian_potential_gradient(&self, x: &SMatrix<f64, 3, 3>, grad: &mut SMatrix<f64, 3, 3>) -> Option<f64> {
        Hcn.cartesian_potential_gradient(x, grad)
    }
    fn dipole(&self) -> Option<impl Dipole<3>> {
        Some(HcnCharges)
    }
}

/// The point-charge dipole of [`ChargedHcn`].
struct HcnCharges;

impl Dipole<3> for HcnCharges {
    fn moment(&self, q: &SVector<f64, 3>, mu: &mut Vector3<f64>) {
        let mut r = SMatrix::<f64, 3, 3>::zeros();
        Hcn.positions(q, &mut r);
        *mu = (0..3).map(|i| HCN_CHARGES[i] * r.column(i)).sum();
    }
    fn moment_jacobian(&self, q: &SVector<f64, 3>, dmu: &mut SMatrix<f64, 3, 3>) {
        let mut dr = [SMatrix::<f64, 3, 3>::zeros(); 3];
        Hcn.positions_jacobian(q, &mut dr);
        for (k, d) in dr.iter().enumerate() {
            dmu.set_column(k, &(0..3).map(|i| HCN_CHARGES[i] * d.column(i)).sum::<Vector3<f64>>());
        }
    }
}

/// HCN's rotational constant B_e (cm⁻¹) at its linear minimum, from the masses and bond lengths
/// alone: `B = 1/(2I)` hartree with `I = Σ m_i z_i²` about the centre of mass.
fn hcn_rotational_constant() -> f64 {
    let q = Hcn.reference_geometry().unwrap();
    let (rch, rcn) = (q[0], q[1]);
    let m: Vec<f64> = Hcn.atoms().iter().map(|a| a.mass).collect();
    let z = [0.0, rch, rch + rcn];
    let com = (0..3).map(|i| m[i] * z[i]).sum::<f64>() / m.iter().sum::<f64>();
    let inertia: f64 = (0..3).map(|i| m[i] * (z[i] - com).powi(2)).sum();
    HARTREE_IN_WAVENUMBERS / (2.0 * inertia)
}

/// The classical P–R separation of a parallel band, `√(8 kT B)` in cm⁻¹ (docs/src/reference/equations.md,
/// section 11): `2.3583·√(B·T)` with B in cm⁻¹ and T in K.
fn classical_pr_separation(b: f64, kelvin: f64) -> f64 {
    2.3583 * (b * kelvin).sqrt()
}

/// The Hann taper's power spectrum (the shape of one line), at `x` = (f − f₀)·T.
fn hann_line(x: f64) -> f64 {
    if x.abs() < 1e-9 {
        return 1.0;
    }
    if (x.abs() - 1.0).abs() < 1e-9 {
        return 0.25;
    }
    let s = (std::f64::consts::PI * x).sin() / (std::f64::consts::PI * x);
    (s / (1.0 - x * x)).powi(2)
}

/// The classical contour of a parallel band, `|Δ| exp(−Δ²/2s²)` (Δ = ν − ν₀; maxima at ±s),
/// seen through the window of resolution `resolution` (FWHM, cm⁻¹), at `nu − nu0`.
fn windowed_contour(d: f64, s: f64, resolution: f64) -> f64 {
    let x_per_cm = rovib::runtime::spectrum::HANN_FWHM / resolution;
    let step = resolution / 40.0;
    let n = (6.0 * s / step).ceil() as i64;
    (-n..=n)
        .map(|i| {
            let delta = i as f64 * step;
            delta.abs() * (-delta * delta / (2.0 * s * s)).exp() * hann_line((d - delta) * x_per_cm)
        })
        .sum::<f64>()
        * step
}

/// What the P–R test reads off one band of a spectrum.
struct Band {
    /// The band centre (the centroid), cm⁻¹.
    centre: f64,
    /// The width s of the least-squares windowed classical contour: its maxima at centre ± s.
    fitted: f64,
    /// The maxima located directly (a parabola through the points within ±`resolution` of the
    /// highest point of each branch), cm⁻¹.
    p: f64,
    r: f64,
}

/// The band of `s` around `guess` (cm⁻¹), fitted within ±`half` cm⁻¹ of its centroid.
fn pr_band(s: &Spectrum, guess: f64, half: f64) -> Band {
    let resolution = s.resolution();
    let points = |lo: f64, hi: f64| -> Vec<(f64, f64)> {
        s.wavenumber.iter().zip(&s.lineshape).filter(|(nu, _)| (lo..=hi).contains(*nu)).map(|(&a, &b)| (a, b)).collect()
    };
    let wide = points(guess - half, guess + half);
    let weight: f64 = wide.iter().map(|p| p.1).sum();
    let centre = wide.iter().map(|p| p.0 * p.1).sum::<f64>() / weight;
    let band = points(centre - half, centre + half);
    // The contour's width by least squares with its height free: maximise (Σ y m)² / Σ m², first
    // on a 0.5 cm⁻¹ grid, then by golden section.
    let score = |w: f64| {
        let (mut ym, mut mm) = (0.0, 0.0);
        for &(nu, y) in &band {
            let m = windowed_contour(nu - centre, w, resolution);
            ym += y * m;
            mm += m * m;
        }
        ym * ym / mm
    };
    let mut best = 4.0;
    for i in 0..=150 {
        let w = 4.0 + 0.5 * i as f64;
        if score(w) > score(best) {
            best = w;
        }
    }
    let (mut a, mut b) = (best - 0.5, best + 0.5);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..40 {
        let (c, d) = (b - g * (b - a), a + g * (b - a));
        if score(c) > score(d) {
            b = d;
        } else {
            a = c;
        }
    }
    let fitted = 0.5 * (a + b);
    let vertex = |lo: f64, hi: f64| {
        let branch = points(lo, hi);
        let top = branch.iter().copied().max_by(|x, y| x.1.total_cmp(&y.1)).unwrap().0;
        let near: Vec<(f64, f64)> = branch.iter().copied().filter(|p| (p.0 - top).abs() <= resolution).collect();
        // y = c0 + c1 u + c2 u², u = ν − top, by the normal equations.
        let mut m = Matrix3::zeros();
        let mut v = Vector3::zeros();
        for (nu, y) in near {
            let u = nu - top;
            let basis = Vector3::new(1.0, u, u * u);
            m += basis * basis.transpose();
            v += basis * y;
        }
        let c = m.try_inverse().unwrap() * v;
        top - c[1] / (2.0 * c[2])
    };
    Band { centre, fitted, p: vertex(centre - half, centre), r: vertex(centre, centre + half) }
}

const PR_KELVIN: f64 = 300.0;
const PR_BATCHES: u64 = 8;

fn pr_scene(seed: u64, trajectories: u64) -> String {
    format!(
        "molecule = \"hcn\"\n[ensemble]\ntrajectories = {trajectories}\nseed = {seed}\nmethod = \"thermal\"\n\
         temperature = {PR_KELVIN}\nregion = {{ energy_cap = 0.05 }}\n[statistics]\nmeans = [\"H\"]\n\
         correlations = [\"mu_x\", \"mu_y\", \"mu_z\"]\n[integrator]\nmethod = \"dop853\"\nrtol = 1e-8\natol = 1e-8\n\
         [run]\nend = {PR_END}\noutput_interval = 20.0\n"
    )
}

const PR_END: f64 = 200000.0;
const PR_TRAJECTORIES: u64 = 48;

/// The P–R contour of HCN's CN-stretching band (a parallel band) at 300 K from a thermal
/// ensemble through the spectrum pipeline (`rovib::ensemble`: thermal sampler, chart switch
/// at the near-linear geometries the bend visits, dipole correlation, spectrum.csv): the
/// maxima of its P and R branches are `2.3583·√(B·T)` cm⁻¹ apart, B from the masses and bond
/// lengths alone.
#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 8 x 48 thermal HCN trajectories, ~90 s in the test profile"]
fn the_p_r_maxima_of_a_linear_molecule_are_classically_separated() {
    use rovib::ensemble::run_with_sampler;
    use rovib::runtime::sample::{Region, Thermal};
    let b = hcn_rotational_constant();
    let expected = classical_pr_separation(b, PR_KELVIN);
    let mut bands = Vec::new();
    for batch in 0..PR_BATCHES {
        let dir = temp_dir(&format!("pr{batch}"));
        let scene = parse_scene("pr.toml", &pr_scene(200 + batch, PR_TRAJECTORIES)).unwrap();
        let region = Region { energy_cap: Some(0.05), limits: [None; 3] };
        let sampler = Thermal::new(&ChargedHcn, PR_KELVIN, &region, 200 + batch).unwrap();
        let report = run_with_sampler(&ChargedHcn, &scene, &sampler, "thermal", &options(dir.clone(), 2)).unwrap();
        assert_eq!(report.outcome.completed, report.requested, "{:?}", report.outcome.first_failures);
        let (s, _, _) = read_spectrum(&dir);
        let band = pr_band(&s, PR_BAND_GUESS, 100.0);
        println!(
            "batch {batch}: band centre {:.2} cm-1, fitted contour maxima {:.2} apart, direct maxima {:.2} and {:.2} \
             ({:.2} apart), resolution {:.2} cm-1, {} switches in {} trajectories",
            band.centre,
            2.0 * band.fitted,
            band.p,
            band.r,
            band.r - band.p,
            s.resolution(),
            report.outcome.charts.switches,
            report.outcome.charts.trajectories_switched
        );
        bands.push((band, s.resolution()));
        let _ = std::fs::remove_dir_all(&dir);
    }
    let mean_se = |v: &[f64]| {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        (mean, (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt())
    };
    let (fitted, fitted_se) = mean_se(&bands.iter().map(|(b, _)| 2.0 * b.fitted).collect::<Vec<_>>());
    let (direct, direct_se) = mean_se(&bands.iter().map(|(b, _)| b.r - b.p).collect::<Vec<_>>());
    let resolution = bands[0].1;
    println!(
        "B = {b:.4} cm-1, T = {PR_KELVIN} K: classical P-R separation {expected:.2} cm-1; fitted {fitted:.2} ± \
         {fitted_se:.2}, direct {direct:.2} ± {direct_se:.2} cm-1 (resolution {resolution:.2} cm-1)"
    );
    // Tolerance: 3.5 standard errors of the mean of 8 batches (Student's t with 7 degrees of
    // freedom exceeds 3.5 with probability 1 %), plus 2 % of the prediction for what the
    // classical rigid-rotor contour leaves out (vibration–rotation interaction and centrifugal
    // distortion, ~1 %; the fit of the windowed contour removes the resolution's broadening).
    let tolerance = 3.5 * fitted_se + 0.02 * expected;
    assert!(
        (fitted - expected).abs() < tolerance,
        "P-R maxima {fitted} cm-1 apart, classical {expected} cm-1 (tolerance {tolerance})"
    );
    // The check discriminates: the prediction with B twice as large (separation × √2) is
    // rejected. (Half as large, × 0.71, is not resolved by this ensemble: the batches scatter by
    // about 15 % each, and a standard error of 1 cm⁻¹ would take some 2700 trajectories.)
    let wrong = classical_pr_separation(2.0 * b, PR_KELVIN);
    println!(
        "with B x 2: predicted {wrong:.2} cm-1, {:.2} from the spectrum (tolerance {tolerance:.2})",
        (fitted - wrong).abs()
    );
    assert!((fitted - wrong).abs() > tolerance, "B x 2 ({wrong} cm-1) is not rejected");
    let half = classical_pr_separation(0.5 * b, PR_KELVIN);
    println!("with B x 0.5: predicted {half:.2} cm-1, {:.2} from the spectrum (not asserted)", (fitted - half).abs());
}

/// A first look at where the band is, cm⁻¹.
const PR_BAND_GUESS: f64 = 2100.0;
