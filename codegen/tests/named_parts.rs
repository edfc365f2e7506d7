//! Named sub-expressions and functions: a site–site CO2–Ar model written with them generates the
//! same potential and gradient as the same model written out (the fixtures in
//! `tests/fixtures/co2ar/`), and the parts nest and inline as documented.

mod common;

use common::method;

use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;
use rovib_codegen::generate_molecule;

const NAMED: &str = include_str!("fixtures/co2ar/co2ar.toml");
const FLAT: &str = include_str!("fixtures/co2ar/co2ar_flat.toml");

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-13 * a.abs().max(b.abs()).max(1e-300)
}

/// The CO2–Ar model with named parts and functions equals the model written out: potential and
/// gradient at random points (bohr, rad) agree to round-off, and so do the positions.
#[test]
fn co2_ar_with_named_parts_equals_the_written_out_model() {
    let named = generate_molecule("tests/fixtures/co2ar/co2ar.toml", NAMED).expect("valid");
    let flat = generate_molecule("tests/fixtures/co2ar/co2ar_flat.toml", FLAT).expect("valid");
    let angstrom = 1.0 / 0.529_177_210_903;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..50 {
        let q = [
            (1.0 + 0.4 * rng.random::<f64>()) * angstrom,
            (1.0 + 0.4 * rng.random::<f64>()) * angstrom,
            (3.0 + 2.0 * rng.random::<f64>()) * angstrom,
            std::f64::consts::PI * (0.05 + 0.9 * rng.random::<f64>()),
        ];
        for (name, outputs) in [("potential", 0), ("potential_gradient", 4)] {
            let (out_n, ret_n) = common::interpret(&method(&named.source, name), &q, outputs);
            let (out_f, ret_f) = common::interpret(&method(&flat.source, name), &q, outputs);
            let (u_n, u_f) = (ret_n.expect("returns U"), ret_f.expect("returns U"));
            assert!(u_n.is_finite() && close(u_n, u_f), "{name} at {q:?}: {u_n} vs {u_f}");
            for (k, (a, b)) in out_n.iter().zip(&out_f).enumerate() {
                assert!(a.is_finite() && close(*a, *b), "{name}[{k}] at {q:?}: {a} vs {b}");
            }
        }
    }
    // Inlining gives the very same graph: the generated code differs only in the names.
    let strip = |s: &str, name: &str, ty: &str| s.replace(name, "M").replace(ty, "M");
    let a = strip(&named.source, "co2ar", "Co2ar");
    let b = strip(&flat.source, "co2ar_flat", "Co2arFlat");
    let differing = a.lines().zip(b.lines()).filter(|(x, y)| x != y).count();
    assert!(differing <= 4, "{differing} lines differ (expected only the header and description)");
}

/// A chain of functions each calling the previous twice with the same argument, 2^40 calls if
/// inlined naively, builds in linear time: a call with the same argument expressions is built
/// once per expression.
#[test]
fn repeated_calls_are_built_once() {
    let mut functions = String::from("[functions]\n\"f0(x)\" = \"1 + x / 8\"\n");
    for i in 1..=40 {
        functions.push_str(&format!("\"f{i}(x)\" = \"f{p}(x) * f{p}(x) / f{p}(x)\"\n", p = i - 1));
    }
    let text = FLAT.replace("length_unit = \"angstrom\"\n", &format!("length_unit = \"angstrom\"\n{functions}"));
    let text = text.replace("expression = \"\"\"\n", "expression = \"\"\"\nf40(r1) - (1 + r1 / 8) +\n");
    let start = std::time::Instant::now();
    let m = generate_molecule("tests/fixtures/co2ar/co2ar_flat.toml", &text).expect("valid");
    assert!(start.elapsed().as_secs_f64() < 20.0, "took {:?}", start.elapsed());
    let flat = generate_molecule("tests/fixtures/co2ar/co2ar_flat.toml", FLAT).expect("valid");
    let q = [2.2, 2.2, 6.6, 1.4];
    let u = |s: &str| common::interpret(&method(s, "potential"), &q, 0).1.expect("returns U");
    assert!(close(u(&m.source), u(&flat.source)), "{} vs {}", u(&m.source), u(&flat.source));
}

/// Generation is deterministic: the library's tables are hash maps (each with its own random
/// seed), and nothing in the output may depend on their order.
#[test]
fn generation_with_functions_is_deterministic() {
    let with_constants = NAMED
        .replace("deg = \"pi / 180\"", "deg = \"pi / 180\"\na1 = 1.5\na2 = 2.5\na3 = 3.5\na4 = 4.5")
        .replace("\"morse(r, d, a, re)\" = \"d * ", "\"morse(r, d, a, re)\" = \"(a1 + a2 + a3 + a4) / 12 * d * ");
    let first = generate_molecule("tests/fixtures/co2ar/co2ar.toml", &with_constants).expect("valid").source;
    for _ in 0..8 {
        assert_eq!(generate_molecule("tests/fixtures/co2ar/co2ar.toml", &with_constants).expect("valid").source, first);
    }
}
