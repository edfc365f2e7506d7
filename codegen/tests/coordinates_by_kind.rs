//! Coordinates declared by kind: the Z-matrix construction is checked against an independent
//! plain-f64 computation of distances, angles and dihedrals (and the documented body frame), the
//! closed forms q(x) against the coordinates they came from, and every bad declaration against
//! its located message.

use rovib_codegen::expr::ExprId;
use rovib_codegen::{DefinitionError, generate_molecule, parse_definition};

/// A four-atom Z-matrix (HOOH-like): every kind, positions built by the generator.
const ZMAT: &str = r#"name = "xy4"

[[coordinates]]
name = "roo"
unit = "bohr"
reference = 2.75
kind = "distance(O1, O2)"

[[coordinates]]
name = "r1"
unit = "bohr"
reference = 1.82
kind = "distance(H1, O1)"

[[coordinates]]
name = "r2"
unit = "bohr"
reference = 1.84
kind = "distance(O2, H2)"

[[coordinates]]
name = "t1"
unit = "deg"
reference = 100.0
kind = "angle(H1, O1, O2)"

[[coordinates]]
name = "t2"
unit = "rad"
reference = 1.8
kind = "angle(O1, O2, H2)"

[[coordinates]]
name = "tau"
unit = "rad"
reference = 1.9
kind = "dihedral(H1, O1, O2, H2)"

[[atoms]]
label = "O1"

[[atoms]]
label = "O2"

[[atoms]]
label = "H1"

[[atoms]]
label = "H2"

[potential]
energy_unit = "hartree"
expression = "k * (pow(roo - 2.7, 2) + pow(r1 - 1.8, 2) + pow(r2 - 1.8, 2)) + c * cos(tau) + k * t2 * t1"
parameters = { k = 0.2, c = 0.01 }
"#;

fn error(text: &str) -> DefinitionError {
    match generate_molecule("molecules/xy4.toml", text) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        // The first error is the one each test provokes (the collector may add consequences).
        Err(mut e) => e.remove(0),
    }
}

fn with(from: &str, to: &str) -> String {
    assert_eq!(ZMAT.matches(from).count(), 1, "`{from}` must occur once");
    ZMAT.replace(from, to)
}

fn assert_error(e: &DefinitionError, line: usize, message: &str, help: &str) {
    assert_eq!(e.path, "molecules/xy4.toml");
    assert!(e.message.contains(message), "message `{}` should contain `{message}`", e.message);
    assert_eq!(e.line, line, "line of {e:#?}");
    assert!(e.help.contains(help), "help `{}` should contain `{help}`", e.help);
}

type V = [f64; 3];
fn sub(a: V, b: V) -> V {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: V, b: V) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross(a: V, b: V) -> V {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
fn norm(a: V) -> f64 {
    dot(a, a).sqrt()
}
/// The angle at b, by acos (a different formula from the generator's atan2).
fn angle(a: V, b: V, c: V) -> f64 {
    let (u, v) = (sub(a, b), sub(c, b));
    (dot(u, v) / (norm(u) * norm(v))).acos()
}
/// The IUPAC dihedral, from the two plane normals and the sign of the triple product.
fn dihedral(a: V, b: V, c: V, d: V) -> f64 {
    let (n1, n2) = (cross(sub(b, a), sub(c, b)), cross(sub(c, b), sub(d, c)));
    let cosine = (dot(n1, n2) / (norm(n1) * norm(n2))).clamp(-1.0, 1.0);
    cosine.acos() * dot(sub(b, a), n2).signum()
}

fn positions(def: &rovib_codegen::Definition, q: &[f64]) -> Vec<V> {
    let roots: Vec<ExprId> = def.positions.iter().flatten().copied().collect();
    let mut vars = vec![0.0; def.graph.var_count()];
    vars[..q.len()].copy_from_slice(q);
    let x = def.graph.eval(&roots, &vars);
    x.chunks(3).map(|c| [c[0], c[1], c[2]]).collect()
}

#[test]
fn the_z_matrix_places_atoms_at_their_coordinates_in_the_documented_frame() {
    let def = parse_definition("molecules/xy4.toml", ZMAT).expect("valid");
    for q in [
        [2.75, 1.82, 1.84, 100f64.to_radians(), 1.8, 1.9],
        [2.6, 1.7, 2.0, 2.9, 0.4, -2.7],
        [3.1, 1.9, 1.6, 0.3, 3.0, 0.05],
    ] {
        let x = positions(&def, &q);
        let [o1, o2, h1, h2] = [x[0], x[1], x[2], x[3]];
        let got = [
            norm(sub(o2, o1)),
            norm(sub(h1, o1)),
            norm(sub(h2, o2)),
            angle(h1, o1, o2),
            angle(o1, o2, h2),
            dihedral(h1, o1, o2, h2),
        ];
        for (k, (g, want)) in got.iter().zip(q).enumerate() {
            assert!((g - want).abs() < 1e-12, "coordinate {k}: {g} vs {want} at {q:?}");
        }
        // Body frame: first atom at the origin, second on +z, third in the xz plane, x ≥ 0.
        assert_eq!(o1, [0.0; 3]);
        assert!(o2[0] == 0.0 && o2[1] == 0.0 && o2[2] > 0.0, "{o2:?}");
        assert!(h1[1] == 0.0 && h1[0] >= 0.0, "{h1:?}");
    }
}

#[test]
fn the_closed_forms_give_the_coordinates_back() {
    // The generated q(x) is emitted from the same expressions as these; evaluate them on the
    // Z-matrix positions of random geometries (angles in (0, π), dihedrals in (−π, π)).
    let m = generate_molecule("molecules/xy4.toml", ZMAT).expect("valid");
    for f in ["fn internal_coordinates", "fn cartesian_potential", "fn cartesian_potential_gradient"] {
        assert!(m.source.contains(f), "{f} is generated");
    }
    let mut def = parse_definition("molecules/xy4.toml", ZMAT).expect("valid");
    let n = def.coordinates.len();
    let kinds = def.kinds.clone().expect("kinds");
    let mut rng = 12345u64;
    let mut uniform = || {
        rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    let q_of_x: Vec<ExprId> = {
        let g = &mut def.graph;
        let first = g.var_count();
        let x: Vec<[ExprId; 3]> = (0..4).map(|i| [0, 1, 2].map(|a| g.var(&format!("x{i}{a}")))).collect();
        let q: Vec<ExprId> = kinds.iter().map(|&k| rovib_codegen::zmatrix::coordinate_of_positions(g, k, &x)).collect();
        assert_eq!(first, n);
        q
    };
    for _ in 0..50 {
        let q = [
            2.0 + uniform(),
            1.5 + uniform(),
            1.5 + uniform(),
            0.2 + 2.7 * uniform(),
            0.2 + 2.7 * uniform(),
            -3.0 + 6.0 * uniform(),
        ];
        let x = positions(&def, &q);
        let mut vars = vec![0.0; def.graph.var_count()];
        for (i, xi) in x.iter().enumerate() {
            vars[n + 3 * i..n + 3 * i + 3].copy_from_slice(xi);
        }
        let back = def.graph.eval(&q_of_x, &vars);
        for k in 0..n {
            assert!((back[k] - q[k]).abs() < 1e-11, "coordinate {k}: {} vs {} at {q:?}", back[k], q[k]);
        }
    }
}

#[test]
fn explicit_positions_with_kinds_are_checked_against_them() {
    let water = r#"name = "xy2"
[[coordinates]]
name = "r1"
unit = "bohr"
reference = 1.8
kind = "distance(O, H1)"
[[coordinates]]
name = "r2"
unit = "bohr"
reference = 1.8
kind = "distance(O, H2)"
[[coordinates]]
name = "alpha"
unit = "rad"
reference = 1.8
kind = "angle(H1, O, H2)"
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
expression = "r1 + r2 + alpha"
"#;
    generate_molecule("molecules/xy2.toml", water).expect("consistent kinds and positions");
    // The angle at H1 is not alpha: located at that kind.
    let bad = water.replace("angle(H1, O, H2)", "angle(O, H1, H2)");
    let e = generate_molecule("molecules/xy2.toml", &bad).unwrap_err().remove(0);
    assert_eq!(e.line, 16, "{e}");
    assert!(e.message.contains("the positions give `angle(O, H1, H2)`"), "{e}");
    // A wrong position (H2's x with a quarter of the angle): the first kind it breaks is named.
    let bad = water.replace("sin(alpha / 2)\", 0, \"r2", "sin(alpha / 4)\", 0, \"r2");
    let e = generate_molecule("molecules/xy2.toml", &bad).unwrap_err().remove(0);
    assert!(e.message.starts_with("the positions give `distance(O, H2)`"), "{e}");
    assert_eq!(e.line, 11, "{e}");
}

#[test]
fn bad_declarations_are_located_errors() {
    assert_error(
        &error(&with("distance(O1, O2)", "distanse(O1, O2)")),
        7,
        "unknown coordinate kind `distanse`",
        "did you mean `distance`?",
    );
    assert_error(&error(&with("distance(O1, O2)", "distance(O1, O3)")), 7, "unknown atom `O3`", "did you mean `O1`?");
    assert_error(&error(&with("distance(O1, O2)", "distance(O1)")), 7, "`distance` takes 2 atoms", "angle(A, B, C)");
    assert_error(&error(&with("distance(O1, O2)", "distance(O1, O1)")), 7, "atom `O1` appears twice", "distinct");
    assert_error(&error(&with("distance(O1, O2)", "distance O1 O2")), 7, "is not a coordinate kind", "distance(A, B)");
    // A length unit for an angle.
    assert_error(
        &error(&with("unit = \"deg\"", "unit = \"bohr\"")),
        23,
        "coordinate `t1` is declared `angle` but its unit `bohr` is a length",
        "rad",
    );
    // Atom O2 (the second) has no distance to O1.
    assert_error(
        &error(&with("distance(O1, O2)", "distance(H1, H2)")),
        43,
        "atom `O2` is not placed",
        "distance(O2, X)",
    );
    // H2's angle has the wrong middle atom.
    assert_error(
        &error(&with("angle(O1, O2, H2)", "angle(O2, O1, H2)")),
        49,
        "no coordinate is `angle(H2, O2, X)`",
        "angle(H2, O2, X)",
    );
    // H2 has no dihedral (a second angle instead).
    assert_error(
        &error(&with("dihedral(H1, O1, O2, H2)", "angle(H1, O1, H2)")),
        49,
        "no coordinate is `dihedral(H2, O2, O1, X)`",
        "dihedral(H2, O2, O1, X)",
    );
    // Mixed declarations.
    let e = error(&with("kind = \"distance(O2, H2)\"\n", ""));
    assert_error(&e, 16, "coordinate `r2` has no kind", "every coordinate");
    // A position with kinds for only some atoms.
    assert_error(
        &error(&with("label = \"H1\"\n", "label = \"H1\"\nposition = [0, 0, 1]\n")),
        47,
        "atom `H1` has a position",
        "remove every `position`",
    );
    // The dihedral's axis atoms collinear at the reference.
    assert_error(
        &error(&with("reference = 100.0", "reference = 180.0")),
        37,
        "the dihedral about `O1`–`O2` is undefined",
        "linear chain",
    );
}

#[test]
fn a_redundant_declaration_is_located() {
    let extra = ZMAT.replace(
        "[[atoms]]\nlabel = \"O1\"",
        "[[coordinates]]\nname = \"rhh\"\nunit = \"bohr\"\nreference = 3.0\nkind = \"distance(H1, H2)\"\n\n[[atoms]]\nlabel = \"O1\"",
    );
    let e = generate_molecule("molecules/xy4.toml", &extra).unwrap_err().remove(0);
    assert_eq!(e.line, 43, "{e}");
    assert!(e.message.contains("`distance(H1, H2)` is not needed to place the atoms"), "{e}");
}

#[test]
fn a_linear_reference_gets_a_note_not_an_error() {
    let hcn = |alpha: &str| {
        format!(
            r#"name = "hcn"
[[coordinates]]
name = "rch"
unit = "bohr"
reference = 2.0
kind = "distance(H, C)"
[[coordinates]]
name = "rcn"
unit = "bohr"
reference = 2.2
kind = "distance(C, N)"
[[coordinates]]
name = "alpha"
unit = "rad"
reference = {alpha}
range = [0, "pi"]
kind = "angle(H, C, N)"
[[atoms]]
label = "H"
[[atoms]]
label = "C"
[[atoms]]
label = "N"
[potential]
energy_unit = "hartree"
expression = "pow(rch - 2, 2) + pow(rcn - 2.2, 2) + 0.1 * pow(alpha - pi, 2)"
"#
        )
    };
    let linear = generate_molecule("molecules/hcn.toml", &hcn("3.141592653589793")).expect("a note, not an error");
    assert_eq!(linear.notes.len(), 1, "{:?}", linear.notes);
    let note = &linear.notes[0];
    assert!(
        note.starts_with("note: the reference geometry of molecule `hcn` (molecules/hcn.toml) is linear"),
        "{note}"
    );
    // What rovib will do there, for a definition with kinds: the Cartesian chart, eval, freq.
    for promise in ["not an error", "rovib run", "lab-frame Cartesian coordinates", "rovib eval", "3N - 5"] {
        assert!(note.contains(promise), "the note does not say `{promise}`: {note}");
    }
    let bent = generate_molecule("molecules/hcn.toml", &hcn("3.1")).expect("valid");
    assert!(bent.notes.is_empty(), "{:?}", bent.notes);
    // The same linear molecule with explicit positions and no kinds: the note says a run stops
    // there and how to get the Cartesian chart.
    let explicit = hcn("3.141592653589793")
        .replace("kind = \"distance(H, C)\"\n", "")
        .replace("kind = \"distance(C, N)\"\n", "")
        .replace("kind = \"angle(H, C, N)\"\n", "")
        .replace(
            "label = \"H\"",
            "label = \"H\"\nposition = [\"rch * sin(pi - alpha)\", 0, \"-rch * cos(pi - alpha)\"]",
        )
        .replace("label = \"C\"", "label = \"C\"\nposition = [0, 0, 0]")
        .replace("label = \"N\"", "label = \"N\"\nposition = [0, 0, \"rcn\"]");
    let m = generate_molecule("molecules/hcn.toml", &explicit).expect("a note, not an error");
    assert_eq!(m.notes.len(), 1, "{:?}", m.notes);
    for promise in
        ["is linear", "no coordinate kinds", "stops with a singular-metric error", "declare each coordinate's kind"]
    {
        assert!(m.notes[0].contains(promise), "the note does not say `{promise}`: {}", m.notes[0]);
    }
}

/// A bond angle lies in [0, π]: a declared range reaching beyond is refused at the range, and
/// an angle kind without a range gets [0, π] (in its unit).
#[test]
fn bond_angle_ranges_stay_within_zero_and_pi() {
    let e = error(&with(
        "reference = 1.8\nkind = \"angle(O1, O2, H2)\"",
        "reference = 1.8\nrange = [0, \"2 * pi\"]\nkind = \"angle(O1, O2, H2)\"",
    ));
    assert!(e.message.contains("reaches outside [0, π]"), "{e}");
    assert_eq!(e.line, 31, "{e}");
    let def = parse_definition("molecules/xy4.toml", ZMAT).expect("valid");
    let t1 = def.coordinates.iter().find(|c| c.name == "t1").unwrap();
    assert_eq!(t1.range, (0.0, 180.0), "degrees");
    let t2 = def.coordinates.iter().find(|c| c.name == "t2").unwrap();
    assert_eq!(t2.range, (0.0, std::f64::consts::PI));
}
