//! Piecewise definitions and special functions in a generated molecule: the emitted potential
//! and gradient (interpreted from the printed code) agree with central differences away from
//! the branch boundaries, and the lane form selects lane-wise.

mod common;

use common::method;

use rovib_codegen::generate_molecule;

/// A CO2–Ar-like surface in Jacobi coordinates: a short-range exponential inside R < 6, a
/// dispersion tail outside, each times Legendre polynomials of cos θ; min, max and abs in it.
const DEFINITION: &str = r#"name = "pw"

[expressions]
c = "cos(theta)"
short = "exp(-1.2 * (R - 6)) * (1 + 0.3 * legendre(2, c) + 0.05 * assoc_legendre(3, 1, c))"
long = "-(2 + 0.5 * legendre(2, c)) * pow(6 / R, 6)"

[[coordinates]]
name = "r"
unit = "bohr"
reference = 2.2

[[coordinates]]
name = "R"
unit = "bohr"
reference = 7

[[coordinates]]
name = "theta"
unit = "rad"
reference = 1.2

[[atoms]]
label = "O1"
position = [0, 0, "r"]

[[atoms]]
label = "O2"
position = [0, 0, "-r"]

[[atoms]]
label = "Ar"
position = ["R * sin(theta)", 0, "R * cos(theta)"]

[potential]
energy_unit = "hartree"
expression = """
1e-3 * if(R < 6, short, long) + 0.4 * pow(r - 2.2, 2)
+ 1e-4 * (min(R, 6.5) + max(R * c, 0) + abs(r - 2.3)) + 1e-4 * erf(R - 7)
"""
"#;

#[test]
fn piecewise_potential_gradient_matches_central_differences() {
    let m = generate_molecule("tests/pw.toml", DEFINITION).expect("valid");
    let (potential, gradient) = (method(&m.source, "potential"), method(&m.source, "potential_gradient"));
    let u = |q: &[f64]| common::interpret(&potential, q, 0).1.expect("U");
    let (mut checked, mut inside) = (0, 0);
    for i in 0..40 {
        let t = f64::from(i) / 40.0;
        let q = [2.0 + 0.5 * t, 4.0 + 4.0 * ((7.0 * t) % 1.0), 0.2 + 2.7 * ((3.0 * t) % 1.0)];
        // Away from every boundary (R = 6, R = 6.5, R cos θ = 0, r = 2.3) by more than the step.
        let h = 1e-5;
        if (q[1] - 6.0).abs() < 1e-3
            || (q[1] - 6.5).abs() < 1e-3
            || (q[1] * q[2].cos()).abs() < 1e-3
            || (q[0] - 2.3).abs() < 1e-3
        {
            continue;
        }
        let (grad, ret) = common::interpret(&gradient, &q, 3);
        assert_eq!(ret.expect("U"), u(&q));
        for k in 0..3 {
            let (mut plus, mut minus) = (q, q);
            plus[k] += h;
            minus[k] -= h;
            let fd = (u(&plus) - u(&minus)) / (2.0 * h);
            assert!((grad[k] - fd).abs() <= 1e-7 * (1.0 + fd.abs()), "∂U/∂q{k} at {q:?}: {} vs {fd}", grad[k]);
        }
        checked += 1;
        inside += usize::from(q[1] < 6.0);
    }
    assert!(checked > 30, "only {checked} points away from the boundaries");
    assert!(inside > 5 && checked - inside > 5, "both branches of R < 6 are checked ({inside} of {checked} inside)");
    let lanes_start = m.source.find("fn potential_gradient_lanes").expect("lane form");
    let lanes = &m.source[lanes_start..];
    assert!(lanes.contains("T::select_lt("), "the lane form selects lane-wise");
    assert!(lanes.contains("T::select_le("), "min and max select with <=");
    assert!(m.source.contains("if "), "the f64 form is an if expression");
    assert!(m.source.contains("::rovib_runtime::special::erf("), "erf in the f64 form");
    assert!(lanes.contains(".erf()"), "erf in the lane form");
}

/// The build warnings name every condition at whose boundary the potential or its gradient jumps,
/// and none where the branches meet smoothly.
#[test]
fn jumps_at_branch_boundaries_are_reported() {
    let m = generate_molecule("tests/pw.toml", DEFINITION).expect("valid");
    let notes = m.warnings.join("\n");
    assert_eq!(m.warnings.len(), 4, "{notes}");
    let note = |condition: &str| m.warnings.iter().find(|n| n.contains(condition)).unwrap_or_else(|| panic!("{notes}"));
    // The value jumps at R = 6 by the difference of the two branches there, 1e-3 (short − long)
    // = 1e-3 (3 + 0.8 P2(c) + 0.05 P3^1(c)), closed forms at the θ the note reports.
    let at_r6 = note("`R < 6.0`");
    let reported = |key: &str| -> f64 {
        let tail = &at_r6[at_r6.find(key).unwrap_or_else(|| panic!("{key} in {at_r6}")) + key.len()..];
        tail.split([' ', ',']).next().unwrap().parse().unwrap()
    };
    let c = reported("theta = ").cos();
    let p2 = 1.5 * c * c - 0.5;
    let p31 = 1.5 * (5.0 * c * c - 1.0) * (1.0 - c * c).sqrt();
    let jump = 1e-3 * (3.0 + 0.8 * p2 + 0.05 * p31);
    assert!(at_r6.contains(&format!("value jumps by {jump:.3e} hartree")), "expected {jump:.3e}: {notes}");
    // min, max and abs have kinks: the gradient jumps by twice the slope of |x| (1e-4 · 2), the
    // slope of min(R, 6.5) (1e-4) and of max(R cos θ, 0) (1e-4 · |∇(R cos θ)|).
    assert!(note("`(r - 2.3) < 0.0`").contains("gradient by 2.000e-4"), "{notes}");
    assert!(note("`R <= 6.5`").contains("gradient by 1.000e-4"), "{notes}");
    assert!(note("`0.0 <= (R * cos(theta))`").contains("near r = "), "{notes}");
    // Branches that meet with value and gradient: no note.
    let smooth = DEFINITION
        .replace("if(R < 6, short, long)", "if(R < 6, pow(R - 6, 2), 0)")
        .replace("+ 1e-4 * (min(R, 6.5) + max(R * c, 0) + abs(r - 2.3))", "+ 1e-4 * if(r > 2.3, pow(r - 2.3, 3), 0)");
    let m = generate_molecule("tests/pw.toml", &smooth).expect("valid");
    assert!(m.warnings.is_empty(), "{:?}", m.warnings);
    assert!(m.notes.is_empty(), "a jump is a warning for the build, not a note for `rovib list`: {:?}", m.notes);
}
