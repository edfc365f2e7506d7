//! Random and mutated molecule definitions, expressions and scene files never make rovib panic:
//! every input either works or gives a located error with a message and a fix.
//!
//! The case counts are fixed (and the seed too, so CI is reproducible); `ROVIB_FUZZ_CASES`
//! raises them for a long run (`STABILITY.md` records the figures).

use std::collections::HashMap;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use rovib::cli::run::initial_state;
use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::hamiltonian;
use rovib::scene::parse_scene;
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
/// (Definition and scene errors are the same struct compiled into two crates, hence a macro.)
macro_rules! well_formed {
    ($e:expr, $text:expr) => {{
        let (e, text) = (&$e, &$text);
        assert!(!e.message.is_empty() && !e.help.is_empty(), "{e:?}");
        assert!(e.line <= text.lines().count() + 1, "line {} beyond the file: {e:?}", e.line);
        let _ = e.to_string();
    }};
}

proptest! {
    #![proptest_config(config(cases(1500), 7))]

    /// Up to four mutations of a shipped definition.
    #[test]
    fn mutated_definitions_never_panic(file in 0usize..64, mutations in prop::collection::vec(mutation(), 1..5)) {
        let corpus = shipped();
        let (path, original) = &corpus[file % corpus.len()];
        let mut text = original.clone();
        for m in &mutations {
            text = apply(&text, m);
        }
        match generate_molecule(path, &text) {
            Ok(m) => prop_assert!(m.source.starts_with("// @generated")),
            Err(e) => well_formed!(e, text),
        }
    }
}

proptest! {
    #![proptest_config(config(cases(4000), 11))]

    /// Random strings over the expression alphabet.
    #[test]
    fn random_expressions_never_panic(text in "[a-z0-9_+*/^().,\\- ]{0,48}|(sin|cos|pow|atan2|sqrt|ln|exp)\\([a-z0-9+*/(),. -]{0,24}\\)?") {
        let mut g = Graph::new();
        let x = g.var("x");
        let y = g.var("y");
        let names = HashMap::from([("x".to_owned(), x), ("y".to_owned(), y)]);
        let scope = Scope { names: &names, context: "the fuzz test" };
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
                        Err(e) => well_formed!(e, text),
                    }
                }
            }
            Err(e) => well_formed!(e, text),
        }
    }
}
