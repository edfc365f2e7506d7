//! Random and mutated molecule definitions, expressions and scene files never make rovib panic:
//! every input either works or gives a located error with a message and a fix.
//!
//! The case counts are fixed (and the seed too, so CI is reproducible); `ROVIB_FUZZ_CASES`
//! raises them for a long run (`STABILITY.md` records the figures).

use std::collections::HashMap;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use rovib::molecules::H2o;
use rovib::runtime::diagnostic::FileError;
use rovib::runtime::hamiltonian::hamiltonian;
use rovib::scene::parse_scene;
use rovib::start::initial_state;
use rovib_codegen::definition::parse_definition;
use rovib_codegen::expr::Graph;
use rovib_codegen::generate_molecule;
use rovib_codegen::parse::{Scope, parse_expression};

fn cases(default: u32) -> u32 {
    std::env::var("ROVIB_FUZZ_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(default)
}

fn config(cases: u32, seed: u64) -> Config {
    Config { cases, rng_seed: RngSeed::Fixed(seed), failure_persistence: None, ..Config::default() }
}

/// The shipped definitions with at most three coordinates: the parser sees the same syntax in
/// every file, and generating the large molecules for every valid mutation would only add time.
fn shipped() -> Vec<(String, String)> {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/molecules");
    let mut files: Vec<(String, String)> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| {
            (format!("molecules/{}", p.file_name().unwrap().to_str().unwrap()), std::fs::read_to_string(&p).unwrap())
        })
        .filter(|(_, text)| text.matches("[[coordinates]]").count() <= 3)
        .collect();
    files.sort();
    files
}

/// Pieces a mutation inserts: TOML and expression syntax, edge-case numbers, other keys.
const PIECES: &[&str] = &[
    "\"",
    "'",
    "\"\"\"",
    "[",
    "]",
    "{",
    "}",
    "=",
    ",",
    "\n",
    "#",
    "(",
    ")",
    "pow(",
    "sin(",
    "^",
    "**",
    "-",
    "+",
    "*",
    "/",
    "0",
    "1e999",
    "nan",
    "inf",
    "-0.0",
    "1e-320",
    "pi",
    "alpha",
    "r1",
    "x",
    "é",
    "\\",
    "[[atoms]]",
    "[[coordinates]]",
    "label = \"H1\"",
    "unit = \"deg\"",
    "mass = 0",
    "position = [0, 0]",
    "name = \"q\"",
    "expression = \"\"",
    "atan2(",
    "ln(0)",
    "sqrt(-1)",
    "/ 0",
    "pow(0, -1)",
    // Hostile names and edge numbers.
    "None",
    "Some",
    "Ok",
    "fn",
    "self",
    "gen",
    "R1",
    "omega_x",
    "1e308",
    "5e-324",
    "name = \"fn\"",
    "name = \"None\"",
    "reference = 1e308",
    "mass = 1e306",
    "range = [0, 1]",
    "range = [1, 0]",
    "range = [0, \"pi\"]",
    "((((((((((",
];

#[derive(Clone, Debug)]
enum Mutation {
    Delete(usize, usize),
    Insert(usize, usize),
    Duplicate(usize, usize),
    SwapLines(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 1usize..40).prop_map(|(a, n)| Mutation::Delete(a, n)),
        (any::<usize>(), 0..PIECES.len()).prop_map(|(a, p)| Mutation::Insert(a, p)),
        (any::<usize>(), 1usize..60).prop_map(|(a, n)| Mutation::Duplicate(a, n)),
        (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Mutation::SwapLines(a, b)),
    ]
}

/// Applies a mutation at character positions (never splitting a UTF-8 character).
fn apply(text: &str, m: &Mutation) -> String {
    let chars: Vec<char> = text.chars().collect();
    let at = |i: usize| if chars.is_empty() { 0 } else { i % (chars.len() + 1) };
    match *m {
        Mutation::Delete(a, n) => {
            let a = at(a);
            let b = (a + n).min(chars.len());
            chars[..a].iter().chain(&chars[b..]).collect()
        }
        Mutation::Insert(a, p) => {
            let a = at(a);
            let mut s: String = chars[..a].iter().collect();
            s.push_str(PIECES[p]);
            s.extend(&chars[a..]);
            s
        }
        Mutation::Duplicate(a, n) => {
            let a = at(a);
            let b = (a + n).min(chars.len());
            let mut s: String = chars[..b].iter().collect();
            s.extend(&chars[a..]);
            s
        }
        Mutation::SwapLines(a, b) => {
            let mut lines: Vec<&str> = text.lines().collect();
            if !lines.is_empty() {
                let (a, b) = (a % lines.len(), b % lines.len());
                lines.swap(a, b);
            }
            lines.join("\n")
        }
    }
}

/// A usable error: a message, a fix and a line inside the file, and a display that works.
/// (Definition and scene errors are one type, `rovib_base::diagnostic::FileError`.)
fn well_formed(e: &FileError, text: &str) {
    assert!(!e.message.is_empty() && !e.help.is_empty(), "{e:?}");
    assert!(e.line <= text.lines().count() + 1, "line {} beyond the file: {e:?}", e.line);
    let _ = e.to_string();
}

/// Every error of a definition is usable, there is at least one, and they come in file order.
fn all_well_formed(errors: &[FileError], text: &str) {
    assert!(!errors.is_empty(), "a refused definition has at least one error");
    for e in errors {
        well_formed(e, text);
    }
    assert!(errors.windows(2).all(|w| (w[0].line, w[0].column) <= (w[1].line, w[1].column)), "{errors:#?}");
}

proptest! {
    #![proptest_config(config(cases(1500), 7))]

    /// Up to four mutations of a shipped definition.
    #[test]
    #[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 99 s unoptimised on a loaded 2-core machine"]
    fn mutated_definitions_never_panic(file in 0usize..64, mutations in prop::collection::vec(mutation(), 1..5)) {
        let corpus = shipped();
        let (path, original) = &corpus[file % corpus.len()];
        let mut text = original.clone();
        for m in &mutations {
            text = apply(&text, m);
        }
        match generate_molecule(path, &text) {
            Ok(m) => prop_assert!(m.source.starts_with("// @generated")),
            Err(e) => all_well_formed(&e, &text),
        }
    }
}

proptest! {
    #![proptest_config(config(cases(4000), 11))]

    /// Random strings over the expression alphabet.
    #[test]
    fn random_expressions_never_panic(text in "[a-z0-9_+*/^().,\\- ]{0,48}|(sin|cos|pow|atan2|sqrt|ln|exp|if|select|abs|min|max|erf|legendre|assoc_legendre|sum)\\([a-z0-9+*/(),.<>=\\[\\] -]{0,24}\\)?") {
        let mut g = Graph::new();
        let x = g.var("x");
        let y = g.var("y");
        let names = HashMap::from([("x".to_owned(), x), ("y".to_owned(), y)]);
        let library = rovib_codegen::parse::Library::default();
        let scope = Scope { names: &names, context: "the fuzz test", library: &library, named: true };
        match parse_expression(&mut g, &text, &scope) {
            Ok(e) => {
                let _ = g.eval(&[e], &[0.3, -1.2]);
            }
            Err(e) => prop_assert!(!e.message.is_empty() && e.line >= 1),
        }
    }
}

fn scenes() -> Vec<(String, String)> {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");
    let mut files: Vec<(String, String)> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| (format!("scenes/{}", p.file_name().unwrap().to_str().unwrap()), std::fs::read_to_string(&p).unwrap()))
        .collect();
    files.sort();
    files
}

proptest! {
    #![proptest_config(config(cases(3000), 13))]

    /// Up to four mutations of a shipped scene, parsed and, for water, bound to the molecule.
    #[test]
    fn mutated_scenes_never_panic(file in 0usize..64, mutations in prop::collection::vec(mutation(), 1..5)) {
        let corpus = scenes();
        let (path, original) = &corpus[file % corpus.len()];
        let mut text = original.clone();
        for m in &mutations {
            text = apply(&text, m);
        }
        match parse_scene(path, &text) {
            Ok(scene) => {
                if scene.molecule.get_ref() == "h2o" {
                    match initial_state(&H2o, &scene) {
                        Ok(start) => {
                            let _ = hamiltonian(&H2o, &start.state);
                        }
                        Err(e) => well_formed(&e, &text),
                    }
                }
            }
            Err(e) => well_formed(&e, &text),
        }
    }
}

/// A small deterministic generator (SplitMix64) for [`hostile_definition`].
struct Pick(u64);
impl Pick {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn of<'a>(&mut self, items: &[&'a str]) -> &'a str {
        items[self.below(items.len())]
    }
}

/// Names that Rust, the prelude, the template or the output columns use, uppercase names and
/// names that mangle alike.
const HOSTILE_NAMES: &[&str] = &[
    "None",
    "Some",
    "Ok",
    "Err",
    "velocities",
    "gen",
    "self",
    "Self",
    "fn",
    "q",
    "k",
    "t0",
    "omega_x",
    "qdot_r1",
    "r1",
    "R1",
    "a_b",
    "A_B",
    "a__b",
    "H",
    "theta",
    "pi",
    "sin",
    "x",
    "E",
    "Result",
    "grad",
];

/// Numbers at the edges of f64: huge, tiny, signed zero, non-finite.
const EDGE_NUMBERS: &[&str] =
    &["1.0", "1e308", "5e-324", "-0.0", "0", "1e-300", "2.5", "-1.0", "1e20", "nan", "inf", "1.8", "0.5", "180"];

/// A random definition built from hostile names, edge numbers and a potential of up to 1,000
/// terms; the name of its file.
fn hostile_definition(seed: u64) -> (String, String) {
    let mut p = Pick(seed);
    // Mostly an ordinary molecule name, so that most definitions get as far as generation.
    let name = if p.below(4) == 0 {
        p.of(&["fn", "self", "gen", "result", "atom", "x_y", "a__b", "molecules", "e", "none"])
    } else {
        "h"
    };
    let mut text = format!("name = \"{name}\"\nlength_unit = \"{}\"\n", p.of(&["bohr", "angstrom"]));
    let n = 1 + p.below(3);
    let mut coords: Vec<&str> = (0..n).map(|_| p.of(HOSTILE_NAMES)).collect();
    if p.below(4) > 0 {
        coords.dedup();
    }
    for c in &coords {
        text +=
            &format!("\n[[coordinates]]\nname = \"{c}\"\nunit = \"{}\"\n", p.of(&["bohr", "angstrom", "rad", "deg"]));
        match p.below(4) {
            0 => {}
            1 => text += &format!("reference = {}\n", p.of(EDGE_NUMBERS)),
            _ => text += &format!("reference = {}\n", p.of(&["0.5", "1.0", "1.8", "2.5"])),
        }
        if p.below(3) == 0 {
            text += &format!(
                "range = {}\n",
                p.of(&[
                    "[0, 1]",
                    "[1, 0]",
                    "[-inf, inf]",
                    "[0, \"pi\"]",
                    "[0, 1e308]",
                    "[5e-324, 1]",
                    "[-1e308, 1e308]"
                ])
            );
        }
    }
    // Numbers inside expressions: finite, but at the edges of f64 as often as not.
    const IN_EXPRESSIONS: &[&str] = &["1e308", "5e-324", "-0.0", "0", "1e-300", "2.5", "1e20", "0.5", "1.0", "3.0"];
    let term = |p: &mut Pick| -> String {
        let c = coords[p.below(coords.len())];
        match p.below(5) {
            0 => format!("{} * {c}", p.of(IN_EXPRESSIONS)),
            1 => format!("sin({c} * {})", p.of(IN_EXPRESSIONS)),
            2 => format!("pow({c} - {}, {})", p.of(IN_EXPRESSIONS), 1 + p.below(6)),
            3 => format!("exp(-{} * {c})", p.of(IN_EXPRESSIONS)),
            _ => p.of(IN_EXPRESSIONS).to_owned(),
        }
    };
    for (i, label) in ["O", "H1", "H2", "C"].iter().take(2 + p.below(3)).enumerate() {
        let xyz: Vec<String> = (0..3)
            .map(|axis| if axis == i % 3 || p.below(3) == 0 { format!("\"{}\"", term(&mut p)) } else { "0".into() })
            .collect();
        text += &format!("\n[[atoms]]\nlabel = \"{label}\"\nposition = [{}]\n", xyz.join(", "));
        if p.below(8) == 0 {
            text += &format!("mass = {}\n", p.of(EDGE_NUMBERS));
        }
    }
    let terms = if p.below(10) == 0 { 1000 } else { 1 + p.below(40) };
    let potential: Vec<String> = (0..terms).map(|_| term(&mut p)).collect();
    text += &format!(
        "\n[potential]\nenergy_unit = \"{}\"\nexpression = \"{}\"\n",
        p.of(&["hartree", "cm-1", "eV", "kcal/mol"]),
        potential.join(" + ")
    );
    (format!("molecules/{name}.toml"), text)
}

proptest! {
    #![proptest_config(config(cases(300), 17))]

    /// Definitions built from hostile names, edge numbers and large potentials: no panic; every
    /// accepted one prints source that parses, and its positions and potential are finite at
    /// the reference geometry when it has one.
    #[test]
    #[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 7 s unoptimised on a loaded 2-core machine"]
    fn hostile_definitions_never_panic_and_accepted_ones_parse(seed in any::<u64>()) {
        let (path, text) = hostile_definition(seed);
        match generate_molecule(&path, &text) {
            Ok(m) => {
                prop_assert!(syn::parse_file(&m.source).is_ok(), "generated source does not parse:\n{}", m.source);
                let def = parse_definition(&path, &text).expect("generated above");
                let reference: Option<Vec<f64>> =
                    def.coordinates.iter().map(|c| c.reference.map(|r| r * c.unit.in_atomic_units())).collect();
                if let Some(q) = reference {
                    let mut roots: Vec<_> = def.positions.iter().flatten().copied().collect();
                    roots.push(def.potential);
                    for v in def.graph.eval(&roots, &q) {
                        prop_assert!(v.is_finite(), "{v} at the reference of\n{text}");
                    }
                }
            }
            Err(e) => all_well_formed(&e, &text),
        }
    }
}

/// Numbers for scene keys: huge, tiny, subnormal, signed zero, non-finite, ordinary.
const SCENE_NUMBERS: &[&str] = &[
    "1.0", "1e308", "1e307", "5e-324", "1e-300", "1e-16", "2.3e-15", "-0.0", "0", "-1.0", "nan", "inf", "-inf",
    "1e-10", "0.5", "20.0", "1e20", "1e-7", "137.0", "3000.0",
];

/// A random scene for water built from edge numbers in every time, tolerance and limit key,
/// hostile names in its tables, and either form of `[initial]`.
fn hostile_scene(seed: u64) -> String {
    let mut p = Pick(seed);
    let n = |p: &mut Pick| p.of(SCENE_NUMBERS).to_owned();
    let mut text = format!("molecule = \"{}\"\n[units]\n", p.of(&["h2o", "h2o", "h2o", "", "fn", "h2o\\n", "H2O"]));
    text += &format!("time = \"{}\"\nlength = \"{}\"\n", p.of(&["au", "fs", "ps"]), p.of(&["bohr", "angstrom"]));
    text += "[initial]\n";
    if p.below(3) == 0 {
        let v = n(&mut p);
        let x = n(&mut p);
        text += &format!(
            "positions = {{ O = [{x}, 0, 0.12], H1 = [0.76, 0, -0.47], H2 = [-0.76, 0, -0.47] }}\n\
             velocities = {{ {} = [{v}, 0, 0] }}\n",
            p.of(&["O", "H1", "H2", "None", "r1", "\"H\\n1\""])
        );
    } else {
        let name = p.of(&["r1", "r2", "alpha", "theta", "None", "self", "\"r 1\"", "\"\""]);
        text += &format!("q = {{ {name} = {} }}\n", n(&mut p));
        text += &format!("{} = {{ {} = {} }}\n", p.of(&["p", "qdot"]), p.of(&["r1", "alpha", "x"]), n(&mut p));
        text += &format!("euler = [{}, {}, 0]\n", n(&mut p), p.of(&["0", "90", "180", "1e-9", "3.14159"]));
        text += &format!("{} = [{}, {}, {}]\n", p.of(&["j", "pe"]), n(&mut p), n(&mut p), p.of(&["0", "1.0"]));
    }
    let method = p.of(&["dop853", "gauss-legendre", "rk4"]);
    text += &format!("[integrator]\nmethod = \"{method}\"\n");
    for key in ["rtol", "atol", "step", "min_step"] {
        if p.below(2) == 0 {
            text += &format!("{key} = {}\n", n(&mut p));
        }
    }
    if p.below(3) == 0 {
        text += &format!("max_steps = {}\n", p.of(&["0", "1", "100", "18446744073709551615"]));
    }
    text += &format!("[run]\nend = {}\n", n(&mut p));
    if p.below(4) > 0 {
        text += &format!("output_interval = {}\n", n(&mut p));
    }
    if p.below(3) == 0 {
        text += &format!("max_outputs = {}\n", p.of(&["0", "10", "18446744073709551615"]));
    }
    if p.below(3) == 0 {
        text += &format!("min_metric_pivot = {}\n", n(&mut p));
    }
    if p.below(3) == 0 {
        text += &format!("frozen = [\"{}\"]\n", p.of(&["r1", "alpha", "theta", ""]));
    }
    if p.below(3) == 0 {
        text += &format!("outputs = [{}]\n", p.of(&["\"summary\"", "", "\"lab\", \"trajectory\"", "\"xyz\""]));
    }
    text
}

proptest! {
    #![proptest_config(config(cases(2000), 19))]

    /// Scenes built from edge numbers and hostile names: no panic; every
    /// scene the parser accepts has integrator settings the solver accepts, finite non-zero
    /// times in atomic units, an output count within its limit and, for fixed steps, a step
    /// count within max_steps; bound to water, it starts a run or gives a located error.
    #[test]
    fn hostile_scenes_are_refused_where_written_or_run(seed in any::<u64>()) {
        use rovib::runtime::integrate::{Method, fixed_step_count};
        let text = hostile_scene(seed);
        match parse_scene("scenes/fuzz.toml", &text) {
            Ok(scene) => {
                prop_assert!(scene.method.validate().is_ok(), "{:?} accepted from\n{text}", scene.method);
                prop_assert!(scene.t_end.is_finite() && scene.t_end > 0.0, "{text}");
                prop_assert!(scene.output_interval.is_finite() && scene.output_interval > 0.0, "{text}");
                let h = match scene.method {
                    Method::GaussLegendre(o) => Some((o.step, o.max_steps)),
                    Method::Rk4(o) => Some((o.step, o.max_steps)),
                    Method::Dop853(_) => None,
                };
                if let Some((h, max_steps)) = h {
                    prop_assert!(fixed_step_count(0.0, scene.t_end, scene.output_interval, h) <= max_steps, "{text}");
                }
                if scene.molecule.get_ref() == "h2o" {
                    match initial_state(&H2o, &scene) {
                        Ok(start) => {
                            prop_assert!(start.com_velocity.norm() < 137.1, "{text}");
                            if let Err(e) = rovib::start::production_system(&H2o, &scene, &start.body) {
                                prop_assert!(!e.to_string().is_empty());
                            }
                        }
                        Err(e) => well_formed(&e, &text),
                    }
                }
            }
            Err(e) => well_formed(&e, &text),
        }
    }
}
