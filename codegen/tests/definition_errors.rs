//! Every kind of bad molecule definition stops generation with a message that names the file,
//! the place, what is wrong and what to change.

use rovib_codegen::{DefinitionError, generate_molecule};

/// A valid triatomic; each test breaks one thing in it.
const GOOD: &str = r#"name = "xy2"
length_unit = "bohr"

[[coordinates]]
name = "r1"
unit = "bohr"

[[coordinates]]
name = "r2"
unit = "bohr"

[[coordinates]]
name = "alpha"
unit = "rad"

[[atoms]]
label = "O"
position = [0, 0, 0]

[[atoms]]
label = "H1"
position = ["r1 * sin(alpha / 2)", 0, "r1 * cos(alpha / 2)"]

[[atoms]]
label = "H2"
position = ["-r2 * sin(alpha / 2)", 0, "r2 * cos(alpha / 2)"]

[potential]
energy_unit = "hartree"
expression = "k * (pow(r1 - 1.8, 2) + pow(r2 - 1.8, 2))"
parameters = { k = 0.2 }
"#;

/// Every error of a definition, in file order.
fn errors(text: &str) -> Vec<DefinitionError> {
    match generate_molecule("molecules/xy2.toml", text) {
        Ok(_) => panic!("expected errors for:\n{text}"),
        Err(errors) => errors,
    }
}

fn messages(errors: &[DefinitionError]) -> Vec<&str> {
    errors.iter().map(|e| e.message.as_str()).collect()
}

/// The one error of a definition with one mistake (a mistake must not be reported again as its
/// consequences).
fn error(text: &str) -> DefinitionError {
    match generate_molecule("molecules/xy2.toml", text) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(mut errors) if errors.len() == 1 => errors.remove(0),
        Err(errors) => panic!("expected one error, got {}: {errors:#?}\nfor:\n{text}", errors.len()),
    }
}

/// Replaces `from` (which must occur exactly once) in the good definition.
fn with(from: &str, to: &str) -> String {
    assert_eq!(GOOD.matches(from).count(), 1, "`{from}` must occur once");
    GOOD.replace(from, to)
}

fn assert_error(e: &DefinitionError, line: usize, column: usize, message: &str, help: &str) {
    assert_eq!(e.path, "molecules/xy2.toml");
    assert_eq!(e.message, message, "message of {e:#?}");
    assert_eq!((e.line, e.column), (line, column), "place of {e:#?}");
    assert!(e.help.contains(help), "help `{}` should contain `{help}`", e.help);
    let shown = e.to_string();
    assert!(shown.contains(&format!("--> molecules/xy2.toml:{line}:{column}")), "{shown}");
    assert!(shown.starts_with(&format!("error: {message}")), "{shown}");
}

#[test]
fn the_good_definition_generates() {
    let m = generate_molecule("molecules/xy2.toml", GOOD).expect("valid");
    assert_eq!((m.atoms, m.coordinates), (3, 3));
    assert!(m.source.starts_with("// @generated from molecules/xy2.toml"));
}

#[test]
fn toml_syntax_error() {
    let e = error(&with("label = \"O\"", "label = \"O"));
    assert_eq!((e.line, e.column), (17, 11), "{e}");
    assert!(e.message.contains("string"), "{e}");
    assert!(e.help.contains("TOML"));
}

#[test]
fn expression_syntax_error_is_located_in_the_file() {
    let e = error(&with("\"r1 * sin(alpha / 2)\"", "\"r1 * sin(alpha / )\""));
    assert_eq!(e.line, 22, "{e}");
    assert!(e.message.starts_with("syntax error in the position of atom H1"), "{e}");
    // The column points into the string, past `position = ["`.
    assert!(e.column > 14, "{e}");
}

#[test]
fn unknown_name() {
    let e = error(&with("\"r1 * sin(alpha / 2)\"", "\"r1 * sin(alph / 2)\""));
    assert_error(&e, 22, 23, "unknown name `alph` in the position of atom H1", "did you mean `alpha`?");
    assert!(e.to_string().contains("22 | position = [\"r1 * sin(alph / 2)\""), "{e}");
}

#[test]
fn unknown_function() {
    let e = error(&with("\"r1 * sin(alpha / 2)\"", "\"r1 * sine(alpha / 2)\""));
    assert_error(&e, 22, 19, "unknown function `sine` in the position of atom H1", "the functions are sin, cos");
}

#[test]
fn wrong_argument_count() {
    let e = error(&with("pow(r1 - 1.8, 2)", "pow(r1 - 1.8)"));
    assert_error(&e, 30, 20, "`pow` takes 2 arguments but 1 was given in the potential", "pow(base, exponent)");
}

#[test]
fn caret_is_not_a_power() {
    let e = error(&with("pow(r1 - 1.8, 2)", "(r1 - 1.8)^2"));
    assert_error(&e, 30, 30, "`^` is not a power in the potential", "pow(base, exponent)");
}

#[test]
fn duplicate_atom() {
    let e = error(&with("label = \"H2\"", "label = \"H1\""));
    assert_error(&e, 25, 9, "duplicate atom `H1`: another atom on line 21 has the same label", "own label");
}

#[test]
fn duplicate_coordinate() {
    // The uses of the old name `r2` are reported too: nothing declares it any more.
    let all = errors(&with("name = \"r2\"", "name = \"r1\""));
    assert_error(&all[0], 9, 8, "duplicate name `r1`: already declared as a coordinate on line 5", "rename");
    assert_eq!(
        messages(&all[1..]),
        [
            "unknown name `r2` in the position of atom H2",
            "unknown name `r2` in the position of atom H2",
            "unknown name `r2` in the potential"
        ]
    );
    assert_eq!(all.iter().map(|e| e.line).collect::<Vec<_>>(), [9, 26, 26, 30]);
}

#[test]
fn parameter_clashing_with_a_coordinate() {
    let all = errors(&with("parameters = { k = 0.2 }", "parameters = { r1 = 0.2 }"));
    // The potential's `k` is no longer declared (line 30), and the clash is on line 31.
    assert_eq!(messages(&all[..1]), ["unknown name `k` in the potential"]);
    assert_eq!(all.len(), 2, "{all:#?}");
    assert_error(
        &all[1],
        31,
        16,
        "duplicate name `r1`: already declared as a coordinate on line 5",
        "rename this parameter",
    );
}

/// Independent mistakes in one file are all reported, each where it is, in file order, with the
/// same text as when it is the only one.
#[test]
fn every_error_of_a_definition_is_reported() {
    let text = with("length_unit = \"bohr\"", "length_unit = \"nm\"")
        .replace("\"r1 * sin(alpha / 2)\"", "\"r1 * sine(alpha / 2)\"")
        .replace("energy_unit = \"hartree\"", "energy_unit = \"kJ/mol\"");
    let all = errors(&text);
    assert_eq!(all.len(), 3, "{all:#?}");
    assert_error(&all[0], 2, 15, "unknown length unit `nm`", "\"bohr\", \"angstrom\"");
    assert_error(&all[1], 22, 19, "unknown function `sine` in the position of atom H1", "the functions are sin, cos");
    assert_error(&all[2], 29, 15, "unknown energy unit `kJ/mol`", "\"cm-1\", \"eV\"");

    // Mistakes in a coordinate, an atom's label, another atom's position and the potential.
    let text = with("unit = \"rad\"", "unit = \"radian\"")
        .replace("label = \"O\"", "label = \"Q1\"")
        .replace("position = [\"-r2 * sin(alpha / 2)\", 0, \"r2 * cos(alpha / 2)\"]", "position = [0, 0]")
        .replace("pow(r1 - 1.8, 2)", "(r1 - 1.8)^2");
    let all = errors(&text);
    assert_eq!(all.len(), 4, "{all:#?}");
    assert_error(&all[0], 14, 8, "unknown unit `radian` for coordinate `alpha`", "\"rad\", \"deg\"");
    assert_error(&all[1], 17, 9, "cannot tell the element of atom `Q1` from its label", "element = \"X\"");
    assert_error(&all[2], 26, 12, "the position of atom `H2` has 2 components instead of 3", "[x, y, z]");
    assert_error(&all[3], 30, 30, "`^` is not a power in the potential", "pow(base, exponent)");
}

/// A constant with a problem is reported once: the positions using it are not reported as using
/// an unknown name, nor as non-finite.
#[test]
fn a_broken_constant_is_reported_once() {
    let text = with("length_unit = \"bohr\"", "length_unit = \"bohr\"\n[constants]\nc = \"1 / 0\"")
        .replace("\"r1 * sin(alpha / 2)\"", "\"c * r1 * sin(alpha / 2)\"");
    let e = error(&text);
    assert_error(&e, 4, 5, "constant `c` is not a finite number", "finite number");
    // A cycle, used in a position and in the potential.
    let text = with("length_unit = \"bohr\"", "length_unit = \"bohr\"\n[constants]\na = \"b\"\nb = \"a\"")
        .replace("\"r1 * sin(alpha / 2)\"", "\"a * r1 * sin(alpha / 2)\"")
        .replace("k * (", "b * k * (");
    let e = error(&text);
    assert!(e.message.contains("defined in terms of itself"), "{e}");
}

#[test]
fn missing_position() {
    let e = error(&with("position = [0, 0, 0]\n", ""));
    assert_error(&e, 17, 9, "missing position for atom `O`", "position = [x, y, z]");
}

#[test]
fn position_with_two_components() {
    let e = error(&with("position = [0, 0, 0]", "position = [0, 0]"));
    assert_error(&e, 18, 12, "the position of atom `O` has 2 components instead of 3", "[x, y, z]");
}

#[test]
fn coordinate_that_moves_no_atom() {
    let text =
        with("[[atoms]]\nlabel = \"O\"", "[[coordinates]]\nname = \"d\"\nunit = \"bohr\"\n\n[[atoms]]\nlabel = \"O\"");
    let e = error(&text);
    assert_error(&e, 17, 8, "no atom position depends on coordinate `d`", "use the coordinate in some atom's position");
}

#[test]
fn non_positive_mass() {
    let e = error(&with("label = \"O\"", "label = \"O\"\nmass = -16.0"));
    assert_error(&e, 18, 8, "the mass of atom `O` must be positive and finite, got -16", "daltons");
    let e = error(&with("label = \"O\"", "label = \"O\"\nmass = 0"));
    assert_eq!(e.message, "the mass of atom `O` must be positive and finite, got 0");
}

#[test]
fn non_finite_mass() {
    let e = error(&with("label = \"O\"", "label = \"O\"\nmass = inf"));
    assert_error(&e, 18, 8, "the mass of atom `O` must be positive and finite, got inf", "daltons");
    let e = error(&with("label = \"O\"", "label = \"O\"\nmass = nan"));
    assert_eq!(e.message, "the mass of atom `O` must be positive and finite, got NaN");
}

#[test]
fn unknown_units() {
    let e = error(&with("unit = \"rad\"", "unit = \"radian\""));
    assert_error(&e, 14, 8, "unknown unit `radian` for coordinate `alpha`", "\"rad\", \"deg\"");
    let e = error(&with("length_unit = \"bohr\"", "length_unit = \"nm\""));
    assert_error(&e, 2, 15, "unknown length unit `nm`", "\"bohr\", \"angstrom\"");
    let e = error(&with("energy_unit = \"hartree\"", "energy_unit = \"kJ/mol\""));
    assert_error(&e, 29, 15, "unknown energy unit `kJ/mol`", "\"cm-1\", \"eV\"");
}

#[test]
fn misspelt_key() {
    let e = error(&with("position = [0, 0, 0]", "postion = [0, 0, 0]"));
    assert_eq!(e.line, 18, "{e}");
    assert!(e.message.starts_with("unknown field `postion`"), "{e}");
    assert!(e.help.contains("check the spelling"));
}

#[test]
fn unknown_element() {
    let e = error(&with("label = \"O\"", "label = \"Q1\""));
    assert_error(&e, 17, 9, "cannot tell the element of atom `Q1` from its label", "element = \"X\"");
    let e = error(&with("label = \"O\"", "label = \"O\"\nelement = \"Oo\""));
    assert_error(&e, 18, 11, "unknown element `Oo`", "chemical symbol");
}

#[test]
fn name_must_match_the_file() {
    let e = error(&with("name = \"xy2\"", "name = \"water\""));
    assert_error(&e, 1, 8, "molecule name `water` does not match the file name `xy2.toml`", "rename the file");
}

#[test]
fn reserved_and_invalid_names() {
    let all = errors(&with("name = \"alpha\"", "name = \"sin\""));
    assert_error(&all[0], 13, 8, "the coordinate name `sin` is reserved", "cannot be redefined");
    assert!(all[1..].iter().all(|e| e.message.starts_with("unknown name `alpha`")), "{all:#?}");
    let all = errors(&with("name = \"alpha\"", "name = \"2a\""));
    assert_error(&all[0], 13, 8, "`2a` is not a valid coordinate name", "start with a letter");
    assert!(all[1..].iter().all(|e| e.message.starts_with("unknown name `alpha`")), "{all:#?}");
}

/// A coordinate named like an ensemble quantity would shadow it in `[statistics]` (two `H_mean`
/// columns, `mu_x` correlating the coordinate): refused where it is declared.
#[test]
fn coordinate_names_of_ensemble_quantities_are_refused() {
    for name in ["H", "T", "U", "J", "Jz", "Lx", "mu_x", "p_r1"] {
        let all = errors(&with("name = \"alpha\"", &format!("name = \"{name}\"")));
        assert_error(
            &all[0],
            13,
            8,
            &format!("the coordinate name `{name}` is the name of an ensemble quantity"),
            "T, U, H, J, Jx, Jy, Jz, Lx, Ly, Lz, mu_x, mu_y, mu_z and p_NAME",
        );
    }
}

#[test]
fn constants_resolve_in_any_order_but_not_in_cycles() {
    let text = with("length_unit = \"bohr\"", "length_unit = \"bohr\"\n[constants]\nb = \"2 * a\"\na = 0.5");
    generate_molecule("molecules/xy2.toml", &text).expect("b uses a, defined later");
    let text = with("length_unit = \"bohr\"", "length_unit = \"bohr\"\n[constants]\nb = \"2 * a\"\na = \"b\"");
    let e = error(&text);
    assert!(e.message.contains("defined in terms of itself"), "{e}");
}

#[test]
fn too_few_atoms() {
    let start = GOOD.find("[[atoms]]\nlabel = \"H1\"").unwrap();
    let end = GOOD.find("[potential]").unwrap();
    let text = format!("{}{}", &GOOD[..start], &GOOD[end..]);
    let e = error(&text.replace("r1 - 1.8", "0").replace("r2 - 1.8", "0"));
    assert_eq!(e.message, "a molecule needs at least 2 atoms, this one has 1");
}

#[test]
fn every_error_of_a_directory_is_reported() {
    let dir = std::env::temp_dir().join(format!("rovib-codegen-errors-{}", std::process::id()));
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(dir.join("xy2.toml"), with("\"r1 * sin(alpha / 2)\"", "\"r1 * sin(alph / 2)\"")).unwrap();
    std::fs::write(dir.join("zz.toml"), GOOD.replace("xy2", "zz").replace("\"hartree\"", "\"joule\"")).unwrap();
    let errors = rovib_codegen::generate(&dir, "molecules", &out).unwrap_err();
    let messages: Vec<&str> = errors.iter().map(|e| e.message.as_str()).collect();
    assert_eq!(messages, ["unknown name `alph` in the position of atom H1", "unknown energy unit `joule`"]);
    assert_eq!(errors[1].path, "molecules/zz.toml");
    assert!(std::fs::read_dir(&out).unwrap().next().is_none(), "nothing is written when a definition is bad");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A second directory adds its molecules to the first; a molecule defined in both is an error
/// naming both files.
#[test]
fn two_directories_add_up_and_a_molecule_defined_in_both_is_an_error_naming_both_files() {
    let dir = std::env::temp_dir().join(format!("rovib-codegen-dirs-{}", std::process::id()));
    let (shipped, user, out) = (dir.join("shipped"), dir.join("user"), dir.join("out"));
    for d in [&shipped, &user, &out] {
        std::fs::create_dir_all(d).unwrap();
    }
    std::fs::write(shipped.join("xy2.toml"), GOOD).unwrap();
    std::fs::write(user.join("aa.toml"), GOOD.replace("xy2", "aa")).unwrap();
    let dirs = [(shipped.as_path(), "molecules"), (user.as_path(), "/home/me/mine")];
    let report = rovib_codegen::generate_dirs(&dirs, &out, &Default::default()).expect("both directories build");
    let names: Vec<(&str, &str)> = report.molecules.iter().map(|m| (m.name.as_str(), m.path.as_str())).collect();
    assert_eq!(names, [("aa", "/home/me/mine/aa.toml"), ("xy2", "molecules/xy2.toml")], "in name order");
    let registry = std::fs::read_to_string(out.join("molecules.rs")).unwrap();
    assert!(registry.contains("Generated from `/home/me/mine/aa.toml`"), "{registry}");
    assert!(registry.contains("pub const NAMES: [&str; 2usize] = [\"aa\", \"xy2\"]"), "{registry}");

    std::fs::write(user.join("xy2.toml"), GOOD).unwrap();
    let errors = rovib_codegen::generate_dirs(&dirs, &out, &Default::default()).unwrap_err();
    assert_eq!(errors.len(), 1, "{errors:?}");
    assert_eq!(errors[0].path, "/home/me/mine/xy2.toml");
    assert_eq!(errors[0].message, "`molecules/xy2.toml` and `/home/me/mine/xy2.toml` both define the molecule `xy2`");
    assert!(errors[0].help.contains("ROVIB_MOLECULES_ONLY=1"), "{}", errors[0].help);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Values that are finite as written but overflow in atomic units: located errors, not a
/// panic while printing an infinite literal.
#[test]
fn values_that_overflow_in_atomic_units() {
    let e = error(&with("label = \"O\"", "label = \"O\"\nmass = 1e306"));
    assert_error(&e, 18, 8, "the mass of atom `O` (1e306 Da) overflows in electron masses", "daltons");
    let e = error(&with(
        "unit = \"bohr\"\n\n[[coordinates]]\nname = \"r2\"",
        "unit = \"angstrom\"\nreference = 1e308\n\n[[coordinates]]\nname = \"r2\"",
    ));
    assert_error(&e, 7, 13, "reference value 1e308 angstrom overflows in atomic units", "reference geometry");
    // Each mass fits, their sum does not.
    let huge = "mass = 9e304";
    let text = with("label = \"O\"", &format!("label = \"O\"\n{huge}"))
        .replace("label = \"H1\"", &format!("label = \"H1\"\n{huge}"))
        .replace("label = \"H2\"", &format!("label = \"H2\"\n{huge}"));
    let e = error(&text);
    assert_eq!(e.message, "the total mass overflows in electron masses (3 atoms)");
}

/// A molecule name becomes a module and a type: keywords and names the generated code uses are
/// refused where the name is written.
#[test]
fn molecule_names_that_cannot_be_rust() {
    for name in ["fn", "type", "self", "gen", "async"] {
        let text = with("name = \"xy2\"", &format!("name = \"{name}\""));
        let e = generate_molecule(&format!("molecules/{name}.toml"), &text).unwrap_err().remove(0);
        assert_eq!(e.message, format!("molecule name `{name}` is a Rust keyword"), "{e}");
        assert_eq!((e.line, e.column), (1, 8));
    }
    for (name, ty) in [("result", "Result"), ("atom", "Atom"), ("kinetic_matrices", "KineticMatrices"), ("e", "E")] {
        let text = with("name = \"xy2\"", &format!("name = \"{name}\""));
        let e = generate_molecule(&format!("molecules/{name}.toml"), &text).unwrap_err().remove(0);
        assert_eq!(
            e.message,
            format!("molecule name `{name}` gives the type name `{ty}`, which generated code already uses")
        );
    }
}

/// A coordinate named like a velocity variable (`omega_x`, `qdot_r1`) is a coordinate of its
/// own: the kinetic energy has one term per coordinate and ω component.
#[test]
fn coordinates_named_like_velocities_stay_coordinates() {
    let text = GOOD
        .replace("\"r1", "\"omega_x")
        .replace("r1 ", "omega_x ")
        .replace("(r1", "(omega_x")
        .replace("\"alpha\"", "\"qdot_r2\"")
        .replace("alpha /", "qdot_r2 /");
    let m = generate_molecule("molecules/xy2.toml", &text).expect("valid");
    let lets: Vec<&str> = m.source.lines().filter(|l| l.trim_start().starts_with("let q")).collect();
    // Coordinates and velocities load from different inputs.
    assert!(lets.iter().any(|l| l.contains("let q0_omega_x = q[0];")), "{lets:#?}");
    assert!(m.source.contains("let omega_x = omega[0];"), "{}", m.source);
    assert!(lets.iter().any(|l| l.contains("let qdot1_r2 = qdot[1];")), "{lets:#?}");
    assert!(lets.iter().any(|l| l.contains("let q2_qdot_r2 = q[2];")), "{lets:#?}");
}

/// Non-finite positions and potentials are build errors where they can be known: constants
/// always, everything else at the reference geometry when the file gives one.
#[test]
fn non_finite_positions_and_potentials() {
    let e = error(&with("position = [0, 0, 0]", "position = [\"1 / 0\", 0, 0]"));
    assert_error(&e, 18, 13, "the x coordinate of atom `O` is inf (a constant)", "division by zero");
    let e = error(&with("position = [0, 0, 0]", "position = [0, \"sqrt(-1)\", 0]"));
    assert_error(&e, 18, 16, "the y coordinate of atom `O` is NaN (a constant)", "square root");
    // Finite in ångström, infinite in bohr.
    let e = error(
        &with("position = [0, 0, 0]", "position = [0, 0, 1e308]")
            .replace("length_unit = \"bohr\"", "length_unit = \"angstrom\""),
    );
    assert_eq!(e.message, "the z coordinate of atom `O` is inf (a constant)");
    let e = error(&with("position = [0, 0, 0]", "position = [0, 0, \"1e300 * 1e300\"]"));
    assert_eq!(e.message, "the z coordinate of atom `O` is inf (a constant)");
    let with_references = GOOD
        .replace("\nunit = \"bohr\"", "\nunit = \"bohr\"\nreference = 1.8")
        .replace("\nunit = \"rad\"", "\nunit = \"rad\"\nreference = 1.8");
    let e = error(&with_references.replace("k * (pow(r1 - 1.8, 2) + pow(r2 - 1.8, 2))", "k * ln(r1 - 1.8)"));
    assert_eq!(e.message, "the potential is -inf hartree at the reference geometry");
    assert_eq!(e.line, 33);
    let e = error(&with_references.replace("\"r1 * sin(alpha / 2)\"", "\"sqrt(1.7 - r1)\""));
    assert_eq!(e.message, "the x coordinate of atom `H1` is NaN at the reference geometry");
    let e = error(&with("k * (pow(r1 - 1.8, 2) + pow(r2 - 1.8, 2))", "1e200 * 1e200 + 0 * r1"));
    assert_eq!(e.message, "the potential is inf hartree (a constant)");
    // Like terms whose summed coefficient overflows are left uncollected: no reference, so no
    // check, and generation must not fail on an infinite constant.
    generate_molecule(
        "molecules/xy2.toml",
        &with("k * (pow(r1 - 1.8, 2) + pow(r2 - 1.8, 2))", "1e308 * r1 + 1e308 * r1"),
    )
    .expect("generates; the value overflows only at run time");
}

/// Coordinates carry valid ranges: declared ones are checked and emitted in atomic units, the
/// defaults keep lengths positive, and a reference outside the range is an error.
#[test]
fn coordinate_ranges() {
    let angle = |range: &str| with("unit = \"rad\"", &format!("unit = \"deg\"\nreference = 100\nrange = {range}"));
    let m = generate_molecule("molecules/xy2.toml", &angle("[0, 180]")).expect("valid");
    assert!(m.source.contains("range: (0.0, 3.141592653589793)"), "{}", m.source);
    assert!(m.source.contains("range: (0.0, f64::INFINITY)"), "lengths default to positive");
    let m = generate_molecule("molecules/xy2.toml", &angle("[-inf, \"inf\"]")).expect("valid");
    assert!(m.source.contains("range: (f64::NEG_INFINITY, f64::INFINITY)"));
    let m = generate_molecule("molecules/xy2.toml", &angle("[\"-pi\", \"180 * 2\"]")).expect("valid");
    assert!(m.source.contains("range: (-0.05483113556160755, 6.283185307179586)"), "{}", m.source);

    let e = error(&angle("[0, 90]"));
    assert_error(
        &e,
        15,
        13,
        "reference value 100.0 of `alpha` is outside its range [0.0, 90.0] deg",
        "range = [low, high]",
    );
    let e = error(&angle("[90, 0]"));
    assert_eq!(e.message, "the range of `alpha` is empty: 90.0 is not below 0.0");
    let e = error(&angle("[0, 90, 180]"));
    assert_eq!(e.message, "the range of `alpha` has 3 values instead of 2");
    let e = error(&angle("[0, nan]"));
    assert_eq!(e.message, "invalid bound NaN in the range of `alpha`");
    let e = error(&angle("[0, \"pi(\"]"));
    assert!(e.message.starts_with("syntax error in a range"), "{e}");
    // The default range of a length: positive.
    let e = error(&with("name = \"r2\"\nunit = \"bohr\"", "name = \"r2\"\nunit = \"bohr\"\nreference = -2.05"));
    assert_eq!(e.message, "reference value -2.05 of `r2` is outside its range [0.0, inf] bohr");
}

/// A label with a newline (or a comma, a space, a quote) would break `rovib list` and the
/// comma-separated lists of messages: labels are one short word.
#[test]
fn atom_labels_are_one_short_word() {
    for (label, shown) in [("H\\n1", "'\\n'"), ("H 1", "' '"), ("H,1", "','"), ("H\\t1", "'\\t'"), ("H\\\"1", "'\"'")] {
        let e = error(&with("label = \"H1\"", &format!("label = \"{label}\"")));
        assert_eq!((e.line, e.column), (21, 9), "{e}");
        assert!(e.message.starts_with("atom label ") && e.message.ends_with(&format!("contains {shown}")), "{e}");
    }
    let long = "H".repeat(33);
    let e = error(&with("label = \"H1\"", &format!("label = \"{long}\"")));
    assert!(e.message.contains("has 33 characters, more than 32"), "{e}");
    // Letters of any script, digits and a little punctuation are fine.
    for label in ["H1'", "H(a)", "H-3", "H.2", "H_b"] {
        let text = with("label = \"H1\"", &format!("label = \"{label}\""));
        assert!(generate_molecule("molecules/xy2.toml", &text).is_ok(), "{label}");
    }
}

/// The good definition with `tables` (e.g. `[expressions]` and `[functions]`) after line 2.
fn with_tables(tables: &str) -> String {
    with("length_unit = \"bohr\"\n", &format!("length_unit = \"bohr\"\n{tables}\n"))
}

#[test]
fn named_expressions_and_functions_generate() {
    let text =
        with_tables("[functions]\n\"sq(x)\" = \"x * x\"\n[expressions]\nhalf = \"alpha / 2\"\nd1 = \"r1 - 1.8\"")
            .replace("pow(r1 - 1.8, 2)", "sq(d1)")
            .replace("\"r1 * sin(alpha / 2)\"", "\"r1 * sin(half)\"");
    generate_molecule("molecules/xy2.toml", &text).expect("valid");
}

#[test]
fn unknown_names_in_named_expressions_and_functions() {
    let e = error(&with_tables("[expressions]\nhalf = \"alfa / 2\""));
    assert_error(&e, 4, 9, "unknown name `alfa` in the named expression `half`", "did you mean `alpha`?");
    // A function sees its parameters and the constants, not the coordinates.
    let e = error(&with_tables("[functions]\n\"f(x)\" = \"x * r1\""));
    assert_error(&e, 4, 15, "unknown name `r1` in the function `f`", "the names available here are: pi, x");
}

#[test]
fn cycles_and_recursion_are_located_errors() {
    let e = error(&with_tables("[expressions]\na = \"b + 1\"\nb = \"2 * a\""));
    assert_error(
        &e,
        4,
        6,
        "the named expression `a` uses `b`, which is defined below it (line 5)",
        "move `b` above `a`",
    );
    let e = error(&with_tables("[expressions]\na = \"r1 + a\""));
    assert_error(&e, 4, 11, "the named expression `a` refers to itself", "no recursion");
    let e = error(&with_tables("[functions]\n\"f(x)\" = \"1 + f(x - 1)\""));
    assert_error(&e, 4, 15, "the function `f` refers to itself", "no recursion");
    let e = error(&with_tables("[functions]\n\"f(x)\" = \"g(x)\"\n\"g(x)\" = \"f(x)\""));
    assert_error(&e, 4, 11, "the function `f` uses `g`, which is defined below it (line 5)", "move `g` above `f`");
}

#[test]
fn wrong_arity_of_a_function_is_located_at_the_call() {
    let text =
        with_tables("[functions]\n\"lj(r, eps, sigma)\" = \"4 * eps * (pow(sigma / r, 12) - pow(sigma / r, 6))\"")
            .replace("k * (pow(r1", "lj(r1, 1) + k * (pow(r1");
    let e = error(&text);
    assert_eq!(e.message, "`lj` takes 3 arguments but 2 were given in the potential");
    assert!(e.help.contains("write `lj(r, eps, sigma)`"), "{e}");
    assert_eq!((e.line, e.column), (32, 15), "{e}");
}

#[test]
fn a_named_expression_is_usable_only_where_its_names_are() {
    // `k` is a potential parameter: fine in the potential, an error in a position.
    let text =
        with_tables("[expressions]\nkr = \"k * r1\"").replace("\"r1 * cos(alpha / 2)\"", "\"kr * cos(alpha / 2)\"");
    let e = error(&text);
    assert_eq!(e.message, "unknown name `k` in the position of atom H1 (inside `kr`)");
    assert_eq!((e.line, e.column), (24, 40), "{e}");
    let text = with_tables("[expressions]\nkr = \"k * r1\"").replace("k * (pow", "kr / r1 * (pow");
    generate_molecule("molecules/xy2.toml", &text).expect("a parameter is known in the potential");
}

#[test]
fn bad_library_entries_are_reported_once() {
    // A broken named expression used in a position and in the potential: one error.
    let text = with_tables("[expressions]\nh = \"alpha / \"")
        .replace("\"r1 * sin(alpha / 2)\"", "\"r1 * sin(h)\"")
        .replace("k * (", "h * k * (");
    let e = error(&text);
    assert!(e.message.starts_with("syntax error in the named expression `h`"), "{e}");
    let e = error(&with_tables("[expressions]\nr1 = \"2\""));
    assert!(e.message.starts_with("duplicate name `r1`"), "{e}");
    let e = error(&with_tables("[functions]\nsq = \"x * x\""));
    assert_error(&e, 4, 1, "function `sq` has no parameter list", "\"lj(r, eps, sigma)\"");
    let e = error(&with_tables("[functions]\n\"sin(x)\" = \"x\""));
    assert!(e.message.contains("the function name `sin` is reserved"), "{e}");
    let e = error(&with_tables("[functions]\n\"f(x, x)\" = \"x\""));
    assert_eq!(e.message, "function `f` has two parameters named `x`");
    let e = error(&with_tables("[functions]\n\"f()\" = \"1\""));
    assert!(e.help.contains("[expressions]"), "{e}");
}

#[test]
fn nesting_of_named_expressions_is_bounded() {
    let mut tables = String::from("[expressions]\ne0 = \"r1\"\n");
    for i in 1..=70 {
        tables.push_str(&format!("e{i} = \"e{} + 1\"\n", i - 1));
    }
    let all = errors(&with_tables(&tables));
    assert!(all[0].message.contains("nested more than 64 deep"), "{all:#?}");
}
