//! Large potentials, as real published surfaces are: thousands of terms must generate without
//! exhausting the stack of a build script, and the generated potential must equal the
//! polynomial evaluated directly.
//!
//! Every generation here runs in a thread with a 2 MiB stack, the size of an unoptimised build
//! script's main thread on Linux, so a recursion as deep as the input would overflow here too.

mod common;

use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use rovib_codegen::{GeneratedMolecule, generate_molecule};

/// The stack of a build script's main thread.
const STACK: usize = 2 << 20;

/// Runs `generate_molecule` on a small stack; the thread is joined, so a stack overflow aborts
/// the test binary (which fails the test run).
fn generate_on_small_stack(path: &str, text: String) -> Result<GeneratedMolecule, Vec<rovib_codegen::DefinitionError>> {
    let path = path.to_owned();
    std::thread::Builder::new()
        .stack_size(STACK)
        .spawn(move || generate_molecule(&path, &text))
        .expect("spawn")
        .join()
        .expect("generation does not panic")
}

/// A bent triatomic with coordinates r1, r2 (bohr) and alpha (rad) and the given potential
/// (hartree). Constants and parameters are written as given.
fn triatomic(name: &str, potential: &str, parameters: &str) -> String {
    format!(
        r#"name = "{name}"

[[coordinates]]
name = "r1"
unit = "bohr"
reference = 1.81

[[coordinates]]
name = "r2"
unit = "bohr"
reference = 1.81

[[coordinates]]
name = "alpha"
unit = "rad"
reference = 1.82

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
expression = """
{potential}
"""
parameters = {{ {parameters} }}
"#
    )
}

/// Interprets the generated `potential` function at `q` (bohr, bohr, rad).
fn generated_potential(source: &str, q: &[f64; 3]) -> f64 {
    let file = syn::parse_file(source).expect("generated source parses");
    let f = file
        .items
        .iter()
        .find_map(|item| match item {
            syn::Item::Impl(i) => i.items.iter().find_map(|it| match it {
                syn::ImplItem::Fn(f) if f.sig.ident == "potential" => Some(&f.block),
                _ => None,
            }),
            _ => None,
        })
        .expect("a potential function");
    common::interpret(f, q, 0).1.expect("potential returns a value")
}

/// A polynomial surface in the displacements from the reference, 10⁴ terms, every exponent
/// triple (i, j, k) by increasing total degree: generated on a 2 MiB stack, and the generated
/// potential equals the polynomial evaluated directly at random points.
#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): ~60 s in the test profile on a loaded 2-core machine"]
fn ten_thousand_term_polynomial_generates_and_evaluates_correctly() {
    const TERMS: usize = 10_000;
    let mut exponents: Vec<(i32, i32, i32)> =
        (0..22).flat_map(|i| (0..22).flat_map(move |j| (0..22).map(move |k| (i, j, k)))).collect();
    exponents.sort_by_key(|&(i, j, k)| (i + j + k, i, j, k));
    exponents.truncate(TERMS);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    // Coefficients fall off with the degree, as fitted surfaces' do.
    let coefficients: Vec<f64> =
        exponents.iter().map(|&(i, j, k)| rng.random_range(-1.0f64..1.0) * 0.5f64.powi(i + j + k)).collect();
    let terms: Vec<String> = exponents
        .iter()
        .zip(&coefficients)
        .map(|(&(i, j, k), c)| format!("{c:e} * pow(r1 - 1.81, {i}) * pow(r2 - 1.81, {j}) * pow(alpha - 1.82, {k})"))
        .collect();
    let text = triatomic("big", &terms.join("\n + "), "");
    let m = generate_on_small_stack("molecules/big.toml", text).expect("a valid definition");
    assert_short_scope_chains(&m);
    for _ in 0..20 {
        let q = [
            1.81 + 0.4 * rng.random_range(-1.0f64..1.0),
            1.81 + 0.4 * rng.random_range(-1.0f64..1.0),
            1.82 + 0.4 * rng.random_range(-1.0f64..1.0),
        ];
        let d = [q[0] - 1.81, q[1] - 1.81, q[2] - 1.82];
        let (mut direct, mut scale) = (0.0, 0.0);
        for (&(i, j, k), c) in exponents.iter().zip(&coefficients) {
            let t = c * d[0].powi(i) * d[1].powi(j) * d[2].powi(k);
            direct += t;
            scale += t.abs();
        }
        let generated = generated_potential(&m.source, &q);
        // Summation order differs (the generator collects and reorders terms): rounding only.
        assert!((generated - direct).abs() <= 1e-13 * scale, "at {q:?}: generated {generated}, direct {direct}");
    }
}

/// A flat sum of 10⁴ Morse terms, one of the shapes that overflowed the stack.
#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): ~25 s in the test profile on a loaded 2-core machine"]
fn ten_thousand_morse_terms_generate() {
    let terms: Vec<String> = (0..10_000)
        .map(|i| format!("{}e-5 * pow(1 - exp(-1.1 * (r1 - {})), 2)", i % 97 + 1, 1.0 + i as f64 * 1e-4))
        .collect();
    let text = triatomic("morse", &terms.join(" + "), "");
    let m = generate_on_small_stack("molecules/morse.toml", text).expect("a valid definition");
    let q = [1.9, 1.7, 1.8];
    let direct: f64 = (0..10_000)
        .map(|i| (i % 97 + 1) as f64 * 1e-5 * (1.0 - (-1.1 * (q[0] - (1.0 + i as f64 * 1e-4))).exp()).powi(2))
        .sum();
    let generated = generated_potential(&m.source, &q);
    assert!((generated - direct).abs() <= 1e-12 * direct.abs(), "generated {generated}, direct {direct}");
}

/// Parentheses nested 2,000 deep: a located error naming the limit (absurd input), never a
/// stack overflow; nesting within the limit works.
#[test]
fn deep_nesting_is_a_located_error() {
    let depth = 2_000;
    let deep = format!("{}r1{}", "(".repeat(depth), ")".repeat(depth));
    let text = triatomic("deep", &deep, "");
    let errors = generate_on_small_stack("molecules/deep.toml", text).expect_err("too deep");
    let [e] = errors.as_slice() else { panic!("one error expected: {errors:#?}") };
    assert!(e.message.contains("nested"), "{e}");
    assert!(e.line > 0, "{e}");
    // At the limit: 64 parentheses, each after a unary minus, nest 128 deep.
    let half = rovib_codegen::parse::MAX_NESTING / 2;
    let ok = format!("{}r1{}", "-(".repeat(half), ")".repeat(half));
    generate_on_small_stack("molecules/deep.toml", triatomic("deep", &ok, "")).expect("nesting at the limit works");
}

/// The deepest chain of nested `let` scopes in `m`'s generated code stays within
/// `scopes::MAX_LET_DEPTH` (rustc with debug information overflows its stack at about 2 500,
/// `rovib_codegen::scopes`), and the largest function is long enough that the grouping was
/// needed (so this checks the grouping, not a small file).
fn assert_short_scope_chains(m: &GeneratedMolecule) {
    use rovib_codegen::scopes::{FLAT_LETS, MAX_LET_DEPTH, max_let_depth};
    let largest = m.stats.iter().max_by_key(|s| s.temporaries).expect("functions");
    assert!(largest.temporaries > FLAT_LETS, "{}: {} has only {} lets", m.name, largest.name, largest.temporaries);
    let depth = max_let_depth(&syn::parse_file(&m.source).expect("generated source parses"));
    assert!(depth <= MAX_LET_DEPTH, "{}: a chain of {depth} nested let scopes (at most {MAX_LET_DEPTH})", m.name);
}

/// Hexane (20 atoms, 54 coordinates, the largest test molecule): its production function
/// has 4 244 temporaries, which in one flat chain crash rustc in the test profile; grouped, the
/// deepest chain is a few hundred.
#[test]
fn hexane_keeps_its_scope_chains_short() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/alkanes/hexane.toml");
    let text = std::fs::read_to_string(path).expect("the hexane fixture");
    let m = generate_on_small_stack("codegen/tests/fixtures/alkanes/hexane.toml", text).expect("a valid definition");
    assert_short_scope_chains(&m);
}
