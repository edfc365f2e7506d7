//! Code that works for ANY compiled-in molecule: a [`MoleculeVisitor`] is called, through
//! `rovib::molecules::visit(name, visitor)`, with the generated type of the molecule named at run
//! time, so one generic function serves every molecule with its own fixed-size, monomorphised
//! code.
//!
//! For each molecule it prints, at the reference geometry of its definition file:
//!
//! * the principal moments of inertia (eigenvalues of the generated `I`) and the rotational
//!   constants `B = ħ²/(2I)`, which in atomic units is `1/(2I)` hartree, in cm⁻¹, with the kind of
//!   rotor (linear, spherical, symmetric or asymmetric top with Ray's κ);
//! * if the reference geometry is a minimum of the potential, the harmonic wavenumbers by
//!   Wilson's GF method: F the Hessian of `U` (central differences of the generated gradient),
//!   G = `G22` from the runtime, ω² the eigenvalues of G·F.
//!
//! ```sh
//! cargo run --release --features examples --example rotational_constants             # every molecule
//! cargo run --release --features examples --example rotational_constants -- h2o nh3  # some of them
//! ```
//!
//! Not every reference geometry is an equilibrium (ch4.toml's has one angle of 96°; see the
//! comment in that file): the rotational constants are those of the reference geometry, and the
//! harmonic wavenumbers are skipped where it is not a minimum or, as for the linear references of
//! hcn.toml and co2.toml, where the GF method's chart is singular (`rovib freq` gives those
//! molecules' 3N − 5 modes from the Cartesian Hessian).

use std::process::ExitCode;

use rovib::molecules;
use rovib::runtime::hamiltonian::InverseMetric;
use rovib::runtime::nalgebra::{DMatrix, SMatrix, SVector};
use rovib::runtime::units::{BOHR_IN_ANGSTROM, DALTON_IN_ELECTRON_MASSES, HARTREE_IN_WAVENUMBERS};
use rovib::runtime::{KineticMatrices, Molecule, MoleculeVisitor};

/// A reference geometry counts as stationary if the Newton step to the nearest stationary point,
/// `F⁻¹ ∂U/∂q`, is shorter than this in every coordinate (bohr or rad).
const STATIONARY_TOLERANCE: f64 = 1e-6;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    // The rotational constant of a moment of 1 u·Å² in cm⁻¹, from the CODATA constants of
    // `units` (B = 1/(2I) hartree with I in m_e·bohr²): the textbook h/(8π²c) = 16.857 63 u·Å²·cm⁻¹.
    let b_of_unit_moment = HARTREE_IN_WAVENUMBERS / (2.0 * DALTON_IN_ELECTRON_MASSES / BOHR_IN_ANGSTROM.powi(2));
    assert!(
        (b_of_unit_moment / 16.857_629_206 - 1.0).abs() < 1e-8,
        "unit conversion: B(1 u·Å²) = {b_of_unit_moment} cm⁻¹, expected 16.857 629 206 cm⁻¹"
    );

    let requested: Vec<String> = std::env::args().skip(1).collect();
    let names: Vec<&str> =
        if requested.is_empty() { molecules::NAMES.to_vec() } else { requested.iter().map(String::as_str).collect() };
    for name in names {
        // `visit` returns None for a name that is not compiled in.
        molecules::visit(name, Summary).ok_or_else(|| {
            format!("no molecule called {name:?}; the compiled-in molecules are: {}", molecules::NAMES.join(", "))
        })?;
    }
    Ok(())
}

/// The visitor: what to do with a molecule, whatever its `N` (coordinates) and `NA` (atoms).
#[derive(Copy, Clone)]
struct Summary;

impl MoleculeVisitor for Summary {
    type Output = ();

    fn visit<M, const N: usize, const NA: usize>(self, molecule: M)
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let atoms = molecule.atoms().map(|a| a.label).join(" ");
        let coordinates = molecule.coordinates().map(|c| c.name).join(" ");
        println!(
            "{} ({}): {NA} atoms ({atoms}), {N} internal coordinates ({coordinates})",
            molecule.name(),
            molecule.source()
        );
        let Some(q) = molecule.reference_geometry() else {
            println!("  no reference geometry in the definition file: nothing to evaluate\n");
            return;
        };

        // The inertia tensor from the generated kinetic matrices, and its principal moments.
        let mut k = KineticMatrices::<N>::default();
        molecule.kinetic(&q, &mut k);
        let mut moments: Vec<f64> = k.inertia.symmetric_eigenvalues().iter().copied().collect();
        moments.sort_by(f64::total_cmp);
        let in_u_angstrom2 = |i: f64| i / DALTON_IN_ELECTRON_MASSES * BOHR_IN_ANGSTROM.powi(2);
        println!(
            "  principal moments of inertia / (u·Å²): {}",
            moments.iter().map(|&i| format!("{:10.5}", in_u_angstrom2(i))).collect::<Vec<_>>().join(" ")
        );

        // B = ħ²/(2I): 1/(2I) hartree in atomic units (ħ = 1, I in m_e·bohr²), here in cm⁻¹;
        // ordered A ≥ B ≥ C. A vanishing moment (linear geometry) has no rotational constant.
        let negligible = 1e-10 * moments.iter().sum::<f64>();
        let constants: Vec<Option<f64>> =
            moments.iter().map(|&i| (i > negligible).then(|| HARTREE_IN_WAVENUMBERS / (2.0 * i))).collect();
        let shown: Vec<String> = ["A", "B", "C"]
            .iter()
            .zip(&constants)
            .map(|(label, b)| match b {
                Some(b) => format!("{label} = {b:.4}"),
                None => format!("{label} = –"),
            })
            .collect();
        println!("  rotational constants / cm⁻¹: {}   ({})", shown.join(", "), rotor_kind(&constants));

        harmonic_wavenumbers(&molecule, &q, &k);
        println!();
    }
}

/// Linear, spherical, symmetric (prolate or oblate) or asymmetric top, from A ≥ B ≥ C.
fn rotor_kind(constants: &[Option<f64>]) -> String {
    let same = |x: f64, y: f64| (x - y).abs() <= 1e-6 * x.abs().max(y.abs());
    match *constants {
        [None, Some(_), Some(_)] => "linear rotor".into(),
        [Some(a), Some(b), Some(c)] if same(a, b) && same(b, c) => "spherical top".into(),
        [Some(a), Some(b), Some(_)] if same(a, b) => "oblate symmetric top".into(),
        [Some(_), Some(b), Some(c)] if same(b, c) => "prolate symmetric top".into(),
        // Ray's asymmetry parameter: −1 prolate, +1 oblate limit.
        [Some(a), Some(b), Some(c)] => format!("asymmetric top, κ = {:.4}", (2.0 * b - a - c) / (a - c)),
        _ => "degenerate geometry".into(),
    }
}

/// Prints the harmonic wavenumbers (Wilson's GF method) if `q` is a minimum of the potential.
fn harmonic_wavenumbers<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    molecule: &M,
    q: &SVector<f64, N>,
    k: &KineticMatrices<N>,
) {
    if N == 0 {
        println!("  rigid: no internal coordinates, no vibrations");
        return;
    }
    let f = hessian(molecule, q);
    let mut gradient = SVector::<f64, N>::zeros();
    molecule.potential_gradient(q, &mut gradient);
    // A minimum has a positive definite F, and there the Newton step F⁻¹ ∂U/∂q is the distance
    // to the stationary point.
    let Some(chol_f) = f.cholesky() else {
        println!("  the Hessian of U is not positive definite here: not a minimum, no harmonic wavenumbers");
        return;
    };
    let newton = chol_f.solve(&gradient);
    if newton.amax() > STATIONARY_TOLERANCE {
        println!(
            "  not a stationary point of U (the minimum is up to {:.3} bohr or rad away): no harmonic wavenumbers",
            newton.amax()
        );
        return;
    }
    let g = match InverseMetric::new(k, q) {
        Ok(metric) => metric.g.g22,
        Err(e) => {
            println!("  {e}: no harmonic wavenumbers");
            return;
        }
    };
    // G·F is not symmetric, but with G = L Lᵀ it is similar to the symmetric Lᵀ F L; its
    // eigenvalues λ are ω² in atomic units, so ħω = √λ hartree.
    let l = g.cholesky().expect("G22 is positive definite where InverseMetric succeeds").l();
    let s: SMatrix<f64, N, N> = l.transpose() * f * l;
    let s = DMatrix::from_fn(N, N, |i, j| 0.5 * (s[(i, j)] + s[(j, i)]));
    let mut wavenumbers: Vec<f64> =
        s.symmetric_eigenvalues().iter().map(|&lambda| lambda.sqrt() * HARTREE_IN_WAVENUMBERS).collect();
    wavenumbers.sort_by(f64::total_cmp);
    println!(
        "  harmonic wavenumbers / cm⁻¹ (GF method): {}",
        wavenumbers.iter().map(|w| format!("{w:.1}")).collect::<Vec<_>>().join(", ")
    );
}

/// The Hessian of `U` at `q` by fourth-order central differences of the generated gradient,
/// symmetrized (hartree per (bohr or rad)²).
fn hessian<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    molecule: &M,
    q: &SVector<f64, N>,
) -> SMatrix<f64, N, N> {
    let step = 1e-4;
    let gradient_at = |k: usize, t: f64| {
        let mut x = *q;
        x[k] += t;
        let mut g = SVector::<f64, N>::zeros();
        molecule.potential_gradient(&x, &mut g);
        g
    };
    let mut f = SMatrix::<f64, N, N>::zeros();
    for k in 0..N {
        let column = (gradient_at(k, -2.0 * step) - 8.0 * gradient_at(k, -step) + 8.0 * gradient_at(k, step)
            - gradient_at(k, 2.0 * step))
            / (12.0 * step);
        f.set_column(k, &column);
    }
    (f + f.transpose()) * 0.5
}
