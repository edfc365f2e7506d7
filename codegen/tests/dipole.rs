//! The `[dipole]` table: the generated expressions against a dipole computed by hand from the
//! same geometry (charges depending on q included), their q-derivatives against finite
//! differences, generated code only where a definition has a dipole, and every bad table
//! stopping generation with its place and what to change.

use rovib_codegen::{DefinitionError, dipole, generate_molecule, kinetic, parse_definition};

/// A triatomic with q-dependent charges; tests break one thing in it.
const GOOD: &str = r#"name = "xy2"
length_unit = "angstrom"

[[coordinates]]
name = "r1"
unit = "angstrom"
reference = 0.96

[[coordinates]]
name = "r2"
unit = "angstrom"
reference = 0.96

[[coordinates]]
name = "alpha"
unit = "deg"
reference = 104.5

[[atoms]]
label = "O"
position = [0, 0, 0]

[[atoms]]
label = "H1"
position = ["r1 * sin(alpha * pi / 360)", 0, "r1 * cos(alpha * pi / 360)"]

[[atoms]]
label = "H2"
position = ["-r2 * sin(alpha * pi / 360)", 0, "r2 * cos(alpha * pi / 360)"]

[potential]
energy_unit = "hartree"
expression = "k * (pow(r1 - 0.96, 2) + pow(r2 - 0.96, 2))"
parameters = { k = 0.2 }

[dipole]
charges = { O = "-(q1 + q2)", H1 = "q1", H2 = "q2" }
parameters = { q1 = 0.33, q2 = 0.33 }
"#;

/// GOOD's charges with q1, q2 depending on the bond lengths and the angle (a charge-flux model).
fn flux_model() -> String {
    let flux = r#"charges = { O = "-(0.66 + 0.1 * (r1 + r2 - 1.92) + 0.02 * cos(alpha * pi / 180))", H1 = "0.33 + 0.1 * (r1 - 0.96) + 0.01 * cos(alpha * pi / 180)", H2 = "0.33 + 0.1 * (r2 - 0.96) + 0.01 * cos(alpha * pi / 180)" }"#;
    GOOD.replace("parameters = { q1 = 0.33, q2 = 0.33 }", "")
        .replace(r#"charges = { O = "-(q1 + q2)", H1 = "q1", H2 = "q2" }"#, flux)
}

const ANGSTROM: f64 = 1.0 / 0.529_177_210_903;
const DEBYE: f64 = 0.393_430_269_519_899_5;

/// μ in e·bohr computed by hand for the flux model at q = (r1, r2 in bohr, alpha in rad).
fn by_hand(q: [f64; 3]) -> [f64; 3] {
    let (r1, r2, a) = (q[0] / ANGSTROM, q[1] / ANGSTROM, q[2]);
    let q1 = 0.33 + 0.1 * (r1 - 0.96) + 0.01 * a.cos();
    let q2 = 0.33 + 0.1 * (r2 - 0.96) + 0.01 * a.cos();
    let qo = -(0.66 + 0.1 * (r1 + r2 - 1.92) + 0.02 * a.cos());
    assert!((q1 + q2 + qo).abs() < 1e-15, "neutral");
    let h = (a / 2.0).sin_cos();
    let pos = [[0.0, 0.0, 0.0], [q[0] * h.0, 0.0, q[0] * h.1], [-q[1] * h.0, 0.0, q[1] * h.1]];
    let charges = [qo, q1, q2];
    // A neutral molecule: the origin does not matter, so no centre-of-mass shift is needed.
    let mut mu = [0.0; 3];
    for (p, c) in pos.iter().zip(charges) {
        for axis in 0..3 {
            mu[axis] += c * p[axis];
        }
    }
    mu
}

#[test]
fn charges_depending_on_q_give_the_dipole_and_its_derivatives() {
    let mut def = parse_definition("molecules/xy2.toml", &flux_model()).expect("valid");
    let exprs = kinetic::build(&mut def, &rovib_codegen::Options::default());
    let d = dipole::build(&mut def, &exprs.positions).expect("the definition has a dipole");
    for q in [[1.81, 1.82, 1.82], [1.6, 2.1, 1.3], [2.4, 1.7, 2.6]] {
        let got = def.graph.eval(&d.mu, &q);
        let want = by_hand(q);
        for axis in 0..3 {
            assert!((got[axis] - want[axis]).abs() < 1e-14, "q = {q:?}, axis {axis}: {got:?} vs {want:?}");
        }
        for k in 0..3 {
            let h = 1e-5;
            let (mut qp, mut qm) = (q, q);
            qp[k] += h;
            qm[k] -= h;
            let (p, m) = (by_hand(qp), by_hand(qm));
            let got = def.graph.eval(&d.jacobian[k], &q);
            for axis in 0..3 {
                let fd = (p[axis] - m[axis]) / (2.0 * h);
                assert!((got[axis] - fd).abs() < 1e-9, "∂μ_{axis}/∂q_{k} at {q:?}: {} vs {fd}", got[axis]);
            }
        }
    }
}

#[test]
fn components_are_converted_from_their_unit() {
    for (unit, scale) in [("debye", DEBYE), ("e*bohr", 1.0), ("e*angstrom", ANGSTROM)] {
        let text = GOOD.replace(
            "charges = { O = \"-(q1 + q2)\", H1 = \"q1\", H2 = \"q2\" }",
            &format!("unit = \"{unit}\"\ncomponents = [\"q1 * (r1 - r2)\", 0, \"2 * q1 * cos(alpha * pi / 360)\"]"),
        );
        let mut def = parse_definition("molecules/xy2.toml", &text).expect("valid");
        let exprs = kinetic::build(&mut def, &rovib_codegen::Options::default());
        let d = dipole::build(&mut def, &exprs.positions).expect("a dipole");
        let q = [1.9, 1.7, 1.9];
        let got = def.graph.eval(&d.mu, &q);
        let want = [0.33 * (1.9 - 1.7) / ANGSTROM, 0.0, 2.0 * 0.33 * (0.95f64).cos()];
        for axis in 0..3 {
            assert!((got[axis] - want[axis] * scale).abs() < 1e-14, "{unit}: {got:?} vs {want:?}");
        }
    }
}

#[test]
fn dipole_functions_are_generated_only_for_a_dipole() {
    let with = generate_molecule("molecules/xy2.toml", GOOD).expect("valid");
    assert!(with.source.contains("fn dipole(&self) -> Option<impl Dipole<3>>"));
    assert!(with.source.contains("impl Dipole<3> for Xy2"));
    assert!(with.source.contains("fn moment(") && with.source.contains("fn moment_jacobian("));
    let without_text = GOOD.split("[dipole]").next().expect("a prefix").to_owned();
    let without = generate_molecule("molecules/xy2.toml", &without_text).expect("valid");
    assert!(
        !without.source.contains("dipole") && !without.source.contains("Dipole"),
        "no dipole code without a [dipole] table"
    );
    // Everything else is the same code: the dipole adds an import, the accessor at the end of
    // `impl Molecule` and `impl Dipole` after it.
    let accessor = with.source.find("    /// The dipole surface of the definition's").expect("the accessor");
    let accessor_end = accessor + with.source[accessor..].find("    }\n").expect("its end") + "    }\n".len();
    let dipole_impl = with.source.find("\nimpl Dipole<3>").expect("the dipole impl");
    let rest = format!("{}{}", &with.source[..accessor], &with.source[accessor_end..dipole_impl])
        .replace("use ::rovib_runtime::surface::Dipole;\n", "");
    let lines = |s: &str| s.lines().filter(|l| !l.trim().is_empty()).map(str::to_owned).collect::<Vec<_>>();
    assert_eq!(lines(&without.source), lines(&rest));
    assert_eq!(with.stats.len(), without.stats.len() + 2);
}

/// The one error of a definition with one mistake.
fn error(text: &str) -> DefinitionError {
    match generate_molecule("molecules/xy2.toml", text) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(mut e) => {
            assert_eq!(e.len(), 1, "one mistake, one error: {e:?}");
            e.remove(0)
        }
    }
}

/// Line and column (1-based) of the first occurrence of `needle` in `text`.
fn place(text: &str, needle: &str) -> (usize, usize) {
    let at = text.find(needle).unwrap_or_else(|| panic!("`{needle}` in the text"));
    let line = text[..at].matches('\n').count() + 1;
    let column = at - text[..at].rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, column)
}

fn check(text: &str, at: &str, message: &str, help: &str) {
    let e = error(text);
    assert_eq!(e.message, message, "{e}");
    assert_eq!((e.line, e.column), place(text, at), "place of {e}");
    assert!(e.help.contains(help), "help `{}` should contain `{help}`", e.help);
    assert!(e.to_string().contains("--> molecules/xy2.toml:"), "{e}");
}

#[test]
fn bad_dipole_tables_are_located_errors() {
    let charges = "charges = { O = \"-(q1 + q2)\", H1 = \"q1\", H2 = \"q2\" }";
    // Both forms, or neither.
    let both = GOOD.replace(charges, &format!("{charges}\ncomponents = [0, 0, 1]\nunit = \"debye\""));
    check(&both, "[dipole]", "the [dipole] table gives both `components` and `charges`", "write either");
    let neither = GOOD.replace(charges, "");
    check(&neither, "[dipole]", "the [dipole] table gives neither `components` nor `charges`", "charges = {");
    // Components: a unit, a known unit, three of them, known names, finite at the reference.
    let comps = |c: &str, unit: &str| GOOD.replace(charges, &format!("{unit}components = {c}"));
    check(&comps("[0, 0, 1]", ""), "[0, 0, 1]", "the dipole components have no unit", "unit = \"debye\"");
    check(&comps("[0, 0, 1]", "unit = \"D\"\n"), "\"D\"", "unknown dipole unit `D`", "\"e*bohr\"");
    check(&comps("[0, 1]", "unit = \"debye\"\n"), "[0, 1]", "the dipole has 2 components instead of 3", "mu_z");
    let typo = comps("[0, 0, \"q1 * cos(alpah)\"]", "unit = \"debye\"\n");
    let e = error(&typo);
    assert!(e.message.contains("unknown name `alpah`") && e.message.contains("dipole's z component"), "{e}");
    assert_eq!((e.line, e.column), place(&typo, "alpah)"));
    assert!(e.help.contains("did you mean `alpha`?"), "{e}");
    check(
        &comps("[0, 0, \"q1 * sqrt(-r1)\"]", "unit = \"debye\"\n"),
        "\"q1 * sqrt",
        "this part of the dipole is NaN at the reference geometry",
        "division by zero",
    );
    // Charges: atoms by label, every atom, no unit.
    let typo = GOOD.replace("H2 = \"q2\"", "H3 = \"q2\"");
    check(&typo, "H3 =", "`H3` in the dipole's charges is not an atom", "did you mean `H1`?");
    let missing = GOOD.replace(", H2 = \"q2\"", "");
    check(&missing, "[dipole]", "the dipole's charges leave out atom(s) H2", "give every atom a charge");
    let unit = GOOD.replace(charges, &format!("unit = \"debye\"\n{charges}"));
    check(&unit, "\"debye\"", "`unit` is not used with `charges`", "units of e");
    let unknown = GOOD.replace(charges, &format!("{charges}\nsign = 1"));
    let e = error(&unknown);
    assert!(e.message.starts_with("unknown field `sign`"), "{e}");
    // A dipole parameter is a name like any other.
    let clash = GOOD.replace("q2 = 0.33 }", "q2 = 0.33, k = 1 }");
    let e = error(&clash);
    assert!(e.message.starts_with("duplicate name `k`"), "{e}");
    let nan = GOOD.replace("q2 = 0.33 }", "q2 = nan }");
    check(&nan, "nan }", "non-finite value of dipole parameter `q2`", "finite");
}
