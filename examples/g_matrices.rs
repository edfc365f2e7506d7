//! The kinetic matrices of water at a geometry of your choice: `a`, `A`, `I` (generated code)
//! and the blocks `G11`, `G12`, `G22` of the inverse kinetic metric (runtime), printed with
//! their units, and `G22` checked against Wilson's closed-form G matrix of a bent XY₂ molecule.
//!
//! Run it with the geometry in ångström and degrees (default: r1 = 0.96 Å, r2 = 1.00 Å,
//! α = 104.5°, slightly asymmetric so that no element vanishes by symmetry):
//!
//! ```sh
//! cargo run --release --features examples --example g_matrices
//! cargo run --release --features examples --example g_matrices -- 0.9578 0.9578 104.5    # r1/Å r2/Å alpha/deg
//! ```
//!
//! Running it is a check: it stops with a message (and exit status 101) unless `G22` equals
//! Wilson's G matrix to 1e-12 (relative, element by element).
//!
//! Conventions (README, "Units and conventions"): the generated code takes q in atomic units
//! (bohr, rad) and returns everything in atomic units (bohr, electron masses m_e); the kinetic
//! energy is `T = ½ (ω, q̇)ᵀ [[I, A], [Aᵀ, a]] (ω, q̇)` and `[[G11, G12], [G12ᵀ, G22]]` is the
//! inverse of that metric.

use std::process::ExitCode;

use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::InverseMetric;
use rovib::runtime::nalgebra::{Matrix3, SMatrix, SVector};
use rovib::runtime::units::{AngleUnit, BOHR_IN_ANGSTROM, CoordinateUnit, LengthUnit};
use rovib::runtime::{Kinematics, KineticMatrices};

/// The default geometry: r1, r2 in Å, α in degrees.
const DEFAULT_GEOMETRY: [f64; 3] = [0.96, 1.00, 104.5];

/// How closely `G22` must match Wilson's G matrix (relative, element by element).
const WILSON_TOLERANCE: f64 = 1e-12;

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
    let [r1_angstrom, r2_angstrom, alpha_deg] = geometry_from_args()?;
    let water = H2o;

    // The generated code works in atomic units: convert Å → bohr and degrees → rad once, here.
    let q = SVector::<f64, 3>::new(
        r1_angstrom * LengthUnit::Angstrom.in_bohr(),
        r2_angstrom * LengthUnit::Angstrom.in_bohr(),
        alpha_deg * AngleUnit::Deg.in_rad(),
    );
    // Coordinate names and units, in the order of q, from the molecule itself.
    let coordinates = water.coordinates();
    let names = coordinates.map(|c| c.name);
    // The unit of each q_k in the atomic system: "bohr" or "rad".
    let q_units = coordinates.map(|c| match c.unit {
        CoordinateUnit::Length(_) => "bohr",
        CoordinateUnit::Angle(_) => "rad",
    });

    println!("{} ({}), {} atoms", water.name(), water.source(), water.atoms().len());
    println!(
        "geometry: r1 = {r1_angstrom} Å, r2 = {r2_angstrom} Å, alpha = {alpha_deg}°  \
         → q = ({:.10} bohr, {:.10} bohr, {:.10} rad)\n",
        q[0], q[1], q[2]
    );

    // Body-frame positions (centre of mass at the origin), printed in Å.
    let mut positions = SMatrix::<f64, 3, 3>::zeros();
    water.positions(&q, &mut positions);
    println!("body-frame positions / Å (molecule in the xz plane, bisector along z):");
    for (i, atom) in water.atoms().iter().enumerate() {
        let r = positions.column(i) * BOHR_IN_ANGSTROM;
        println!("  {:<3} {:>13.8} {:>13.8} {:>13.8}   mass {} Da", atom.label, r[0], r[1], r[2], atom.mass_da);
    }
    println!();

    // The generated kinetic matrices a, A, I at q (value entry point; `kinetic_jacobian` gives
    // their q-derivatives).
    let mut k = KineticMatrices::<3>::default();
    water.kinetic(&q, &mut k);

    // Units: with [q_j] the unit of q_j (bohr or rad), the metric element for a pair of
    // velocities (x, y) has the unit m_e·bohr²/([x][y]), and ω is in rad per time, so
    //   a_jk: m_e·bohr²/([q_j][q_k]),  A_jk: m_e·bohr²/[q_k],  I: m_e·bohr²,
    // and the inverse blocks have the inverse units:
    //   G11: 1/(m_e·bohr²),  G12_jk: [q_k]/(m_e·bohr²),  G22_jk: [q_j][q_k]/(m_e·bohr²).
    let xyz = ["x", "y", "z"];
    print_matrix("a (vibrational kinetic matrix)", "m_e·bohr²/([q_j][q_k])", &names, &names, &k.a);
    print_matrix("A (Coriolis matrix, rows x y z)", "m_e·bohr²/[q_k]", &xyz, &names, &k.coriolis);
    print_matrix("I (inertia tensor)", "m_e·bohr²", &xyz, &xyz, &k.inertia);

    // G11, G12, G22 from a, A, I (the seed path's InverseMetric; it fails, with the block named,
    // where the metric is singular, e.g. for a linear geometry).
    let g = InverseMetric::new(&k, &q).map_err(|e| format!("cannot compute the G matrices: {e}"))?.g;
    print_matrix("G11 (rotational block)", "1/(m_e·bohr²)", &xyz, &xyz, &g.g11);
    print_matrix("G12 (rotation-vibration block)", "[q_k]/(m_e·bohr²)", &xyz, &names, &g.g12);
    print_matrix("G22 (vibrational block)", "[q_j][q_k]/(m_e·bohr²)", &names, &names, &g.g22);
    println!("  with [q] = {} for {}\n", q_units.join(", "), names.join(", "));

    // The sanity check: G22 is Wilson's G matrix, known in closed form for a bent XY2.
    let masses = water.masses();
    let wilson = wilson_g(&q, masses[0], masses[1]);
    print_matrix("Wilson's G matrix, closed form", "[q_j][q_k]/(m_e·bohr²)", &names, &names, &wilson);
    let mut worst = 0.0_f64;
    for i in 0..3 {
        for j in 0..3 {
            // Each element relative to its own scale √(G_ii G_jj) (the diagonal is positive).
            let scale = (wilson[(i, i)] * wilson[(j, j)]).sqrt();
            worst = worst.max((g.g22[(i, j)] - wilson[(i, j)]).abs() / scale);
        }
    }
    assert!(
        worst <= WILSON_TOLERANCE,
        "G22 differs from Wilson's G matrix by {worst:e} (relative), more than {WILSON_TOLERANCE:e}: \
         the generated kinetic matrices or the G-matrix code are wrong"
    );
    println!("G22 = Wilson's G: largest relative difference {worst:.1e} (≤ {WILSON_TOLERANCE:e}) ✓");
    Ok(())
}

/// r1 and r2 in Å and α in degrees from the command line, or the defaults.
fn geometry_from_args() -> Result<[f64; 3], String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.is_empty() {
        return Ok(DEFAULT_GEOMETRY);
    }
    if args.len() != 3 {
        return Err(format!(
            "expected three numbers, r1/Å r2/Å alpha/deg (e.g. `-- 0.9578 0.9578 104.5`), got {} argument(s)",
            args.len()
        ));
    }
    let mut values = [0.0; 3];
    for (value, (arg, name)) in values.iter_mut().zip(args.iter().zip(["r1", "r2", "alpha"])) {
        *value = arg.parse::<f64>().map_err(|e| format!("{name} = {arg:?} is not a number: {e}"))?;
    }
    let [r1, r2, alpha] = values;
    if !(r1 > 0.0 && r1.is_finite() && r2 > 0.0 && r2.is_finite()) {
        return Err(format!("bond lengths must be positive and finite, got r1 = {r1} Å, r2 = {r2} Å"));
    }
    if !(alpha > 0.0 && alpha < 180.0) {
        return Err(format!("alpha must lie strictly between 0° and 180° (water is bent), got {alpha}°"));
    }
    Ok(values)
}

/// Wilson's G matrix of a bent XY₂ molecule in valence coordinates (r1, r2, α), X central
/// (Wilson, Decius & Cross, *Molecular Vibrations*, 1955, Appendix VI), with μ = 1/m:
///
/// ```text
/// G_r1r1 = G_r2r2 = μ_X + μ_Y          G_r1r2 = μ_X cos α
/// G_r1α = −μ_X sin α / r2              G_r2α  = −μ_X sin α / r1
/// G_αα  = μ_Y (1/r1² + 1/r2²) + μ_X (1/r1² + 1/r2² − 2 cos α / (r1 r2))
/// ```
fn wilson_g(q: &SVector<f64, 3>, m_x: f64, m_y: f64) -> Matrix3<f64> {
    let (r1, r2, alpha) = (q[0], q[1], q[2]);
    let (mu_x, mu_y) = (1.0 / m_x, 1.0 / m_y);
    let (sin, cos) = alpha.sin_cos();
    let g11 = mu_x + mu_y;
    let g12 = mu_x * cos;
    let g13 = -mu_x * sin / r2;
    let g23 = -mu_x * sin / r1;
    let inv_sq = 1.0 / (r1 * r1) + 1.0 / (r2 * r2);
    let g33 = mu_y * inv_sq + mu_x * (inv_sq - 2.0 * cos / (r1 * r2));
    #[rustfmt::skip]
    let g = Matrix3::new(
        g11, g12, g13,
        g12, g11, g23,
        g13, g23, g33,
    );
    g
}

/// Prints a matrix with row and column labels and its unit.
fn print_matrix<const R: usize, const C: usize>(
    title: &str,
    unit: &str,
    rows: &[&str],
    columns: &[&str],
    m: &SMatrix<f64, R, C>,
) {
    println!("{title}, unit {unit}:");
    print!("{:>8}", "");
    for c in columns {
        print!("{c:>16}");
    }
    println!();
    for (i, r) in rows.iter().enumerate() {
        print!("{r:>8}");
        for j in 0..C {
            // `+ 0.0` turns a negative zero (e.g. from −0.0 · x) into 0, which reads better.
            print!("{:>16.8e}", m[(i, j)] + 0.0);
        }
        println!();
    }
    println!();
}
