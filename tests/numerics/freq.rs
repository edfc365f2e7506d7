//! `rovib freq`: the stationary point, harmonic wavenumbers and rotational constants of water,
//! against the modes tests/sampling.rs checks with an independent Cartesian Hessian and against
//! the inertia tensor built here from the Cartesian positions and masses.

use rovib::freq::{HARTREE_IN_MHZ, freq, frequencies};
use rovib::molecules::H2o;
use rovib::runtime::modes::NormalModes;
use rovib::runtime::nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rovib::runtime::units::HARTREE_IN_WAVENUMBERS;
use rovib::runtime::{Kinematics, Molecule};

#[test]
fn water_wavenumbers_and_rotational_constants() {
    let f = frequencies("h2o").unwrap();
    assert!(f.not_minimum.is_none());
    // The stationary point: the gradient vanishes there.
    let q0 = SVector::<f64, 3>::from_column_slice(&f.q0);
    let mut g = SVector::zeros();
    H2o.potential_gradient(&q0, &mut g);
    assert!(g.amax() < 1e-8, "gradient {g:?}");
    // Wavenumbers: those of the modes at the reference (a minimum), which tests/sampling.rs
    // checks against the mass-weighted Cartesian Hessian.
    let modes = NormalModes::at(&H2o, &H2o.reference_geometry().unwrap()).unwrap();
    for (a, b) in f.wavenumbers.iter().zip(modes.wavenumbers().iter()) {
        assert!((a - b).abs() < 1e-3, "{a} vs {b} cm-1");
    }
    assert_eq!(f.wavenumbers.len(), 3);
    // Rotational constants from the inertia tensor of the Cartesian positions (about the centre
    // of mass), diagonalised here.
    let mut r = SMatrix::<f64, 3, 3>::zeros();
    H2o.positions(&q0, &mut r);
    let masses = H2o.masses();
    let total: f64 = masses.iter().sum();
    let com: Vector3<f64> = (0..3).map(|a| r.column(a) * masses[a]).sum::<Vector3<f64>>() / total;
    let mut inertia = Matrix3::zeros();
    for a in 0..3 {
        let x: Vector3<f64> = r.column(a) - com;
        inertia += masses[a] * (Matrix3::identity() * x.norm_squared() - x * x.transpose());
    }
    let mut moments: Vec<f64> = inertia.symmetric_eigen().eigenvalues.iter().copied().collect();
    moments.sort_by(f64::total_cmp);
    for k in 0..3 {
        let b = 0.5 / moments[k];
        assert!((f.rotational_cm[k] / (b * HARTREE_IN_WAVENUMBERS) - 1.0).abs() < 1e-10, "{k}: {:?}", f.rotational_cm);
        assert!((f.rotational_mhz[k] / (b * HARTREE_IN_MHZ) - 1.0).abs() < 1e-10);
    }
    // The values examples/rotational_constants.rs prints for this model (4 decimals).
    for (b, known) in f.rotational_cm.iter().zip([27.3855, 14.5806, 9.5147]) {
        assert!((b - known).abs() < 1e-4, "{b} vs {known} cm-1");
    }
    // A ≥ B ≥ C.
    assert!(f.rotational_cm[0] >= f.rotational_cm[1] && f.rotational_cm[1] >= f.rotational_cm[2]);
}

#[test]
fn json_and_text_agree_and_an_unknown_molecule_is_an_error() {
    let j: serde_json::Value = serde_json::from_str(&freq("h2o", true).unwrap()).unwrap();
    let f = frequencies("h2o").unwrap();
    assert_eq!(j["minimum"], true);
    let w: Vec<f64> = serde_json::from_value(j["wavenumbers_cm-1"].clone()).unwrap();
    assert_eq!(w, f.wavenumbers);
    let text = freq("h2o", false).unwrap();
    assert!(text.contains("a minimum") && text.contains(&format!("{:.3}", f.wavenumbers[0])), "{text}");
    assert!(freq("h2q", false).unwrap_err().to_string().contains("unknown molecule `h2q`"));
}

// ---- Linear molecules: 3N − 5 modes from the Cartesian Hessian, B of a linear rotor ----

use rovib::molecules::{Co2, Hcn};
use rovib::runtime::cartesian_modes::CartesianModes;
use rovib::runtime::nalgebra::DMatrix;
use rovib::runtime::units::BOHR_IN_ANGSTROM;

/// A force constant in cm⁻¹/Å² (as the definition files write them) in hartree/bohr².
fn per_angstrom2(f: f64) -> f64 {
    f / HARTREE_IN_WAVENUMBERS * BOHR_IN_ANGSTROM * BOHR_IN_ANGSTROM
}

/// The curvature 2 D a² of a Morse curve (D in cm⁻¹, a in 1/Å), hartree/bohr².
fn morse_curvature(d: f64, a: f64) -> f64 {
    2.0 * per_angstrom2(d * a * a)
}

/// λ (hartree²) in cm⁻¹.
fn wavenumber(lambda: f64) -> f64 {
    lambda.sqrt() * HARTREE_IN_WAVENUMBERS
}

/// The harmonic wavenumbers of a linear triatomic X1–X2–X3 (bonds r1 = X1–X2, r2 = X2–X3, the
/// bend ρ = π − angle) with the valence force field F_r1 = f1, F_r2 = f2, F_r1r2 = f12, F_ρρ = fb,
/// by Wilson's GF method in closed form (Wilson, Decius & Cross, Molecular Vibrations, §4-2 and
/// appendix VI): the stretches from the 2×2 G = [[μ1 + μ2, −μ2], [−μ2, μ2 + μ3]] (the bonds are
/// antiparallel, cos 180° = −1), the bend from
/// G_ρρ = μ1/r1² + μ3/r2² + μ2 (1/r1 + 1/r2)², the same for both of its components. Ascending:
/// [bend, bend, stretch, stretch].
fn linear_triatomic(m: [f64; 3], r: [f64; 2], f1: f64, f2: f64, f12: f64, fb: f64) -> [f64; 4] {
    let mu = m.map(|x| 1.0 / x);
    let g = Matrix3::new(mu[0] + mu[1], -mu[1], 0.0, -mu[1], mu[1] + mu[2], 0.0, 0.0, 0.0, 0.0);
    let f = Matrix3::new(f1, f12, 0.0, f12, f2, 0.0, 0.0, 0.0, 0.0);
    let gf = (g * f).fixed_view::<2, 2>(0, 0).into_owned();
    let (tr, det) = (gf.trace(), gf.determinant());
    let disc = (tr * tr / 4.0 - det).sqrt();
    let g_bend = mu[0] / (r[0] * r[0]) + mu[2] / (r[1] * r[1]) + mu[1] * (1.0 / r[0] + 1.0 / r[1]).powi(2);
    let bend = wavenumber(fb * g_bend);
    [bend, bend, wavenumber(tr / 2.0 - disc), wavenumber(tr / 2.0 + disc)]
}

/// The mass-weighted Cartesian Hessian computed here, independently of `rovib freq` (which takes
/// second differences of U(x)): fourth-order central differences of the generated gradient
/// ∂U/∂x, which is not finite at an exactly linear geometry (the angle's closed form is not
/// differentiable there), so at such a displaced point it is the mean over two points moved
/// ±1e-6 bohr off the line (exact to O(1e-12) for a smooth U). Not projected: all 3N
/// eigenvalues, ascending by magnitude.
fn cartesian_hessian_eigenvalues<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    q: &SVector<f64, N>,
) -> Vec<f64> {
    let mut x0 = SMatrix::<f64, 3, NA>::zeros();
    m.positions(q, &mut x0);
    let off = SMatrix::<f64, 3, NA>::from_fn(|a, i| {
        if a == 0 {
            1e-6 * (i as f64 + 1.0)
        } else if a == 1 {
            1e-6 * (1.0 - i as f64)
        } else {
            0.0
        }
    });
    let gradient = |x: &SMatrix<f64, 3, NA>| {
        let mut g = SMatrix::<f64, 3, NA>::zeros();
        m.cartesian_potential_gradient(x, &mut g).expect("coordinates by kind");
        if g.iter().all(|v| v.is_finite()) {
            return g;
        }
        let (mut a, mut b) = (SMatrix::<f64, 3, NA>::zeros(), SMatrix::<f64, 3, NA>::zeros());
        m.cartesian_potential_gradient(&(x + off), &mut a);
        m.cartesian_potential_gradient(&(x - off), &mut b);
        (a + b) * 0.5
    };
    let masses = m.masses();
    let dim = 3 * NA;
    let h = 1e-4;
    let mut hess = DMatrix::<f64>::zeros(dim, dim);
    for j in 0..dim {
        let at = |t: f64| {
            let mut x = x0;
            x[(j % 3, j / 3)] += t;
            gradient(&x)
        };
        let col = (at(-2.0 * h) - at(-h) * 8.0 + at(h) * 8.0 - at(2.0 * h)) / (12.0 * h);
        for i in 0..dim {
            hess[(i, j)] = col[(i % 3, i / 3)] / (masses[i / 3] * masses[j / 3]).sqrt();
        }
    }
    let hess = (&hess + hess.transpose()) * 0.5;
    let mut lambda: Vec<f64> = hess.symmetric_eigenvalues().iter().copied().collect();
    lambda.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    lambda
}

/// What every linear molecule's `rovib freq` must give: a linear stationary point, 3N − 5 = 4
/// modes, the bend a degenerate pair (perpendicular to the axis, mass-orthogonal), the stretches
/// along the axis; the 4 equal to the non-zero eigenvalues of the unprojected Cartesian Hessian
/// computed here, whose other 5 (3 translations, 2 rotations) vanish; B = 1/(2I) of the linear
/// rotor from the positions, A infinite.
fn check_linear(name: &str, closed_form: [f64; 4]) -> Frequencies {
    let f = frequencies(name).unwrap();
    eprintln!("{name}: {:?} cm-1 (closed form {closed_form:?}), B = {} cm-1", f.wavenumbers, f.rotational_cm[1]);
    assert!(f.linear, "{name}: the stationary point is linear");
    assert!(f.not_minimum.is_none(), "{name}: {:?}", f.not_minimum);
    assert_eq!(f.wavenumbers.len(), 4, "{name}: 3N − 5 modes, got {:?}", f.wavenumbers);
    for (w, c) in f.wavenumbers.iter().zip(closed_form) {
        assert!((w - c).abs() < 1e-6 * c, "{name}: {w} vs closed form {c} cm-1 ({:e})", (w - c) / c);
    }
    assert!(
        (f.wavenumbers[0] - f.wavenumbers[1]).abs() < 1e-7 * f.wavenumbers[0],
        "{name}: bend pair {:?}",
        f.wavenumbers
    );
    f
}

use rovib::freq::Frequencies;

fn check_linear_against_cartesian_hessian<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, f: &Frequencies) {
    let name = m.name();
    let q0 = SVector::<f64, N>::from_column_slice(&f.q0);
    let lambda = cartesian_hessian_eigenvalues(m, &q0);
    let top = lambda[lambda.len() - 1].abs();
    for l in &lambda[..5] {
        assert!(l.abs() < 1e-8 * top, "{name}: translations and the two rotations should vanish: {lambda:?}");
    }
    let mut cart: Vec<f64> = lambda[5..].iter().map(|&l| wavenumber(l)).collect();
    cart.sort_by(f64::total_cmp);
    for (w, c) in f.wavenumbers.iter().zip(&cart) {
        assert!((w - c).abs() < 1e-6 * c, "{name}: rovib freq {w} vs Cartesian Hessian {c} cm-1");
    }
    // The modes' geometry: the axis from the positions; bends perpendicular, stretches along it.
    let mut x = SMatrix::<f64, 3, NA>::zeros();
    m.positions(&q0, &mut x);
    let axis = (x.column(NA - 1) - x.column(0)).normalize();
    let masses = m.masses();
    let vectors: Vec<SMatrix<f64, 3, NA>> = f.vectors.iter().map(|v| SMatrix::from_column_slice(v)).collect();
    for (k, l) in vectors.iter().enumerate() {
        let along: f64 = (0..NA).map(|i| l.column(i).dot(&axis).powi(2)).sum::<f64>().sqrt();
        let total = l.norm();
        if k < 2 {
            assert!(along < 1e-6 * total, "{name}: bend mode {k} has a component {along:e} along the axis");
        } else {
            assert!((along - total).abs() < 1e-6 * total, "{name}: stretch mode {k} leaves the axis");
        }
        let norm: f64 = (0..NA).map(|i| masses[i] * l.column(i).norm_squared()).sum();
        assert!((norm - 1.0).abs() < 1e-9, "{name}: mode {k} is not mass-normalised: {norm}");
    }
    let overlap: f64 = (0..NA).map(|i| masses[i] * vectors[0].column(i).dot(&vectors[1].column(i))).sum();
    assert!(overlap.abs() < 1e-9, "{name}: the two bend components are not orthogonal: {overlap}");
    // B of the linear rotor, I = Σ m (z − Z)² along the axis.
    let total: f64 = masses.iter().sum();
    let z: Vec<f64> = (0..NA).map(|i| x.column(i).dot(&axis)).collect();
    let centre: f64 = z.iter().zip(&masses).map(|(z, m)| z * m).sum::<f64>() / total;
    let inertia: f64 = z.iter().zip(&masses).map(|(z, m)| m * (z - centre).powi(2)).sum();
    let b = 0.5 / inertia * HARTREE_IN_WAVENUMBERS;
    assert!(f.rotational_cm[0].is_infinite(), "{name}: a linear rotor has no A: {:?}", f.rotational_cm);
    for k in [1, 2] {
        assert!((f.rotational_cm[k] / b - 1.0).abs() < 1e-10, "{name}: B = {:?} vs {b} cm-1", f.rotational_cm);
    }
}

/// CO2: the linear symmetric XY2 closed forms with this model's valence force field (co2.toml):
/// λ_sym = (f_r + f_rr)/m_O, λ_asym = (f_r − f_rr)(1/m_O + 2/m_C), λ_bend = 2 f_αα (1/m_O + 2/m_C)/r_e²
/// (Herzberg, Infrared and Raman Spectra, 1945, ch. II.4; with f_rr = 0 these are √(k/m_Y) and
/// √(k(1 + 2m_Y/m_X)/m_Y)), f_r = 2 D_e a² the Morse curvature. The general linear-triatomic
/// GF gives the same. Tolerance 1e-6 relative: the second differences of U(x) are good to
/// about 1e-9 (measured below), the closed forms exact.
#[test]
fn co2_has_four_modes_a_degenerate_bend_and_b() {
    let masses = Co2.masses();
    let (m_c, m_o) = (masses[0], masses[1]);
    let re = 1.161288 / BOHR_IN_ANGSTROM;
    let f_r = morse_curvature(45441.0, 2.979220);
    let f_rr = per_angstrom2(63499.57);
    let f_aa = 39506.67 / HARTREE_IN_WAVENUMBERS;
    let sym = wavenumber((f_r + f_rr) / m_o);
    let asym = wavenumber((f_r - f_rr) * (1.0 / m_o + 2.0 / m_c));
    let bend = wavenumber(2.0 * f_aa * (1.0 / m_o + 2.0 / m_c) / (re * re));
    let general = linear_triatomic([m_o, m_c, m_o], [re, re], f_r, f_r, f_rr, f_aa);
    for (a, b) in [bend, bend, sym, asym].iter().zip(general) {
        assert!((a - b).abs() < 1e-9 * b, "the two closed forms: {a} vs {b}");
    }
    let f = check_linear("co2", [bend, bend, sym, asym]);
    check_linear_against_cartesian_hessian(&Co2, &f);
    // The model's wavenumbers are those its constants were fitted to (co2.toml).
    for (w, known) in f.wavenumbers.iter().zip([672.85, 672.85, 1354.31, 2396.32]) {
        assert!((w - known).abs() < 0.1, "{w} vs {known} cm-1");
    }
}

/// HCN: the general linear-triatomic closed forms with hcn.toml's force field (Morse curvatures
/// of the two bonds, the stretch–stretch coupling, the harmonic bend in α − π).
#[test]
fn hcn_has_four_modes_a_degenerate_bend_and_b() {
    let masses = Hcn.masses();
    let r = [1.0655 / BOHR_IN_ANGSTROM, 1.1532 / BOHR_IN_ANGSTROM];
    let closed = linear_triatomic(
        [masses[0], masses[1], masses[2]],
        r,
        morse_curvature(45000.0, 1.869737),
        morse_curvature(78000.0, 2.461768),
        per_angstrom2(-10068.23),
        12937.68 / HARTREE_IN_WAVENUMBERS,
    );
    let f = check_linear("hcn", closed);
    check_linear_against_cartesian_hessian(&Hcn, &f);
    let text = freq("hcn", false).unwrap();
    assert!(
        text.contains("3N - 5 = 4") && text.contains("doubly degenerate") && text.contains("linear rotor"),
        "{text}"
    );
    let j: serde_json::Value = serde_json::from_str(&freq("hcn", true).unwrap()).unwrap();
    assert_eq!(j["linear"], true);
    assert_eq!(j["wavenumbers_cm-1"].as_array().unwrap().len(), 4);
    assert!(j["rotational_constants_cm-1"][0].is_null(), "A of a linear rotor: {}", j["rotational_constants_cm-1"]);
}

/// The Cartesian-Hessian modes of a bent molecule (water, 3N − 6 = 3) equal its GF modes: two
/// independent methods on one minimum.
#[test]
fn cartesian_modes_of_water_equal_its_gf_modes() {
    let f = frequencies("h2o").unwrap();
    assert!(!f.linear);
    let q0 = SVector::<f64, 3>::from_column_slice(&f.q0);
    let modes = CartesianModes::at(&H2o, &q0).unwrap();
    assert!(!modes.linear);
    let w = modes.wavenumbers();
    assert_eq!(w.len(), 3);
    for (a, b) in w.iter().zip(&f.wavenumbers) {
        assert!((a - b).abs() < 1e-6 * b, "Cartesian {w:?} vs GF {:?} cm-1", f.wavenumbers);
    }
}

/// Normal-mode sampling of a linear minimum is refused with a message that says why and what
/// to use (it works in the 3N − 6 internal coordinates, singular there).
#[test]
fn normal_mode_sampling_of_a_linear_molecule_says_what_to_use() {
    use rovib::runtime::sample::{ModeEnergies, NormalModeSampler, RotationSampling};
    for name in ["co2", "hcn"] {
        struct Try;
        impl rovib::runtime::MoleculeVisitor for Try {
            type Output = String;
            fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> String {
                let energies = ModeEnergies::Quantum(vec![0; N]);
                let rotation = RotationSampling::Fixed(Vector3::zeros());
                match NormalModeSampler::new(&m, &energies, &rotation, 1) {
                    Ok(_) => panic!("{}: sampled about a linear minimum", m.name()),
                    Err(e) => e.to_string(),
                }
            }
        }
        let message = rovib::molecules::visit(name, Try).unwrap();
        for promise in ["linear", "3N - 5", "rovib freq", "thermal or microcanonical"] {
            assert!(message.contains(promise), "{name}: `{promise}` missing from: {message}");
        }
    }
}

/// A rigid molecule (no internal coordinates) has no vibrational modes: `rovib freq` gives its
/// rotational constants and no wavenumbers, and normal-mode sampling draws rotation only.
#[test]
fn rigid_water_has_rotational_constants_and_no_modes() {
    let f = frequencies("h2o_rigid").unwrap();
    assert!(f.wavenumbers.is_empty() && f.vectors.is_empty() && f.not_minimum.is_none(), "{f:?}");
    let water = frequencies("h2o").unwrap();
    for k in 0..3 {
        assert!((f.rotational_cm[k] / water.rotational_cm[k] - 1.0).abs() < 1e-3, "{f:?}");
    }
    assert!(freq("h2o_rigid", true).is_ok());
    use rovib::runtime::sample::{ModeEnergies, NormalModeSampler, RotationSampling, Sampler};
    let s = NormalModeSampler::new(
        &rovib::molecules::H2oRigid,
        &ModeEnergies::Quantum(vec![]),
        &RotationSampling::Thermal { temperature: 300.0 },
        1,
    )
    .unwrap();
    let state = s.draw(0).unwrap();
    assert!(state.j.norm() > 0.0 && state.j.iter().all(|x| x.is_finite()));
}
