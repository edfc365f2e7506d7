//! `rovib freq`: the stationary point, harmonic wavenumbers and rotational constants of water,
//! against the modes tests/sampling.rs checks with an independent Cartesian Hessian and against
//! the inertia tensor built here from the Cartesian positions and masses.

use rovib::cli::freq::{HARTREE_IN_MHZ, freq, frequencies};
use rovib::molecules::H2o;
use rovib::runtime::Molecule;
use rovib::runtime::modes::NormalModes;
use rovib::runtime::nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rovib::runtime::units::HARTREE_IN_WAVENUMBERS;

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
