//! A generated fuzz of ensemble scenes: 12 000 scenes from a fixed seed, each a valid thermal
//! water ensemble with one to four keys set to a value from that key's own pool or a hostile
//! one (negative, zero, huge, non-finite, NaN-like strings, wrong types, wrong tables), removed,
//! or an unknown key added. Each is parsed, checked and bound to water (no trajectory runs):
//! none may panic, and each is accepted or refused with an error located in the file.
//!
//! Then "no key ignored": for every key a single-run or ensemble scene accepts, one valid change
//! of only that key must be refused (the keys an ensemble does not use) or change the bound
//! plan (the scene, the ensemble and the binding, with file positions left out).

use std::panic::{AssertUnwindSafe, catch_unwind};

use rovib::ensemble::output_times;
use rovib::ensemble::scene::parse_ensemble;
use rovib::molecules::H2o;
use rovib::runtime::diagnostic::FileError;
use rovib::scene::parse_scene;

/// The base scene: one `key = value` per line, by table (an empty key opens the table).
const BASE: &[(&str, &str, &str)] = &[
    ("", "molecule", "\"h2o\""),
    ("", "description", "\"fuzz\""),
    ("units", "", ""),
    ("units", "time", "\"au\""),
    ("ensemble", "", ""),
    ("ensemble", "trajectories", "100"),
    ("ensemble", "seed", "7"),
    ("ensemble", "method", "\"thermal\""),
    ("ensemble", "temperature", "300"),
    ("ensemble", "region", "{ energy_cap = 0.1 }"),
    ("ensemble", "threads", "2"),
    ("statistics", "", ""),
    ("statistics", "means", "[\"r1\", \"H\"]"),
    ("statistics", "histograms", "[{ quantity = \"alpha\", bins = 20, range = [1.0, 2.5], times = [0, 50] }]"),
    ("statistics", "correlations", "[\"r2\"]"),
    ("integrator", "", ""),
    ("integrator", "method", "\"dop853\""),
    ("integrator", "rtol", "1e-10"),
    ("run", "", ""),
    ("run", "end", "100"),
    ("run", "output_interval", "10"),
];

/// Keys and values to try (table, key, values), beyond the hostile ones.
const POOL: &[(&str, &str, &[&str])] = &[
    ("", "molecule", &["\"co2\"", "\"nope\"", "\"\""]),
    ("units", "length", &["\"bohr\"", "\"angstrom\"", "\"parsec\""]),
    ("units", "angle", &["\"deg\"", "\"rad\"", "\"grad\""]),
    ("units", "time", &["\"fs\"", "\"ps\"", "\"year\""]),
    ("ensemble", "trajectories", &["1", "64", "65", "1000000000000", "9223372036854775807"]),
    ("ensemble", "seed", &["0", "9223372036854775807"]),
    ("ensemble", "method", &["\"microcanonical\"", "\"normal-modes\"", "\"file\"", "\"thermla\""]),
    ("ensemble", "temperature", &["1e-300", "1e300", "5000"]),
    ("ensemble", "energy", &["0.01", "-0.01", "1e300"]),
    ("ensemble", "energy_unit", &["\"eV\"", "\"cm-1\"", "\"kcal\""]),
    ("ensemble", "angular_momentum", &["0", "10", "-1"]),
    ("ensemble", "region", &["{ limits = { r1 = [1.0, 3.0] } }", "{ limits = { r9 = [1, 2] } }", "{ energy_cap = 0 }"]),
    ("ensemble", "quanta", &["[0, 0, 0]", "[1, 0]", "[4294967296, 0, 0]"]),
    ("ensemble", "mode_energies", &["[0.001, 0.001, 0.001]", "[-1, 0, 0]"]),
    ("ensemble", "j", &["[0, 0, 5]", "[1, 2]"]),
    ("ensemble", "file", &["\"missing.csv\"", "\"\"", "\"/dev/null\""]),
    ("ensemble", "threads", &["1", "100000"]),
    ("ensemble", "keep_trajectories", &["1", "10", "1000000000"]),
    ("ensemble", "max_memory_gb", &["0.000001", "1e9"]),
    ("ensemble", "max_disk_gb", &["0.000001", "1e9"]),
    ("statistics", "means", &["[]", "[\"T\", \"U\", \"Jx\", \"Lz\", \"p_r1\"]", "[\"mu_x\"]", "[\"bogus\"]"]),
    (
        "statistics",
        "histograms",
        &[
            "[{ quantity = \"r1\", bins = 1000000, range = [0, 10] }]",
            "[{ quantity = \"r1\", bins = 10, range = [-1e308, 1e308] }]",
            "[{ quantity = \"H\", bins = 3, range = [0, 1], times = [100] }]",
            "[{ quantity = \"r1\", bins = 3, range = [0, 1], times = [1000] }]",
            "[{ quantity = \"r1\", bins = 3 }]",
        ],
    ),
    ("statistics", "correlations", &["[\"alpha\", \"Lz\"]", "[\"nope\"]"]),
    ("integrator", "method", &["\"rk4\"", "\"gauss-legendre\"", "\"euler\""]),
    ("integrator", "rtol", &["1e-20", "0.5", "2"]),
    ("integrator", "atol", &["1e-12", "1e-320"]),
    ("integrator", "step", &["0.1", "1e-30"]),
    ("integrator", "stages", &["2", "3", "7"]),
    ("integrator", "compensated", &["true"]),
    ("integrator", "max_steps", &["1", "0", "18446744073709551615"]),
    ("integrator", "min_step", &["1e-6", "1000"]),
    ("run", "end", &["1", "1e-300", "1e300"]),
    ("run", "output_interval", &["1e-6", "100", "0.3"]),
    ("run", "outputs", &["[\"trajectory\"]"]),
    ("run", "frozen", &["[\"alpha\"]", "[\"r1\", \"r2\", \"alpha\"]", "[\"zz\"]"]),
    ("run", "min_metric_pivot", &["0.001", "2"]),
    ("run", "max_energy_error", &["1e-6", "0"]),
    ("run", "max_outputs", &["5", "1000000000"]),
    ("run", "euler_unwrapped", &["true"]),
    ("run", "cartesian_fallback", &["false"]),
    ("run", "stop_outside", &["{ r1 = [0.5, 5.0] }", "{ r1 = [5.0, 0.5] }"]),
    ("initial", "q", &["{ r1 = 1.0 }"]),
    ("potential.parameters", "re", &["1.0", "-1e300"]),
    ("potential.parameters", "bogus", &["1"]),
];

const HOSTILE: &[&str] = &[
    "-1",
    "0",
    "-0.0",
    "1e308",
    "-1e308",
    "inf",
    "-inf",
    "nan",
    "9223372036854775807",
    "-9223372036854775808",
    "\"nan\"",
    "\"NaN\"",
    "\"inf\"",
    "\"\"",
    "\"1\"",
    "true",
    "[]",
    "[1, 2, 3]",
    "[\"a\", 1]",
    "{}",
    "{ x = 1 }",
    "[[1], [2]]",
    "1979-05-27",
    "\"\u{0}\"",
];

/// A small deterministic generator (xorshift64*), so that every run fuzzes the same scenes.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// The scene text of `entries` (table, key, value), tables in order of first appearance.
fn render(entries: &[(String, String, String)]) -> String {
    let mut tables: Vec<&str> = Vec::new();
    for (t, _, _) in entries {
        if !tables.contains(&t.as_str()) {
            tables.push(t);
        }
    }
    let mut text = String::new();
    for table in tables {
        if !table.is_empty() {
            text.push_str(&format!("[{table}]\n"));
        }
        for (t, k, v) in entries {
            if t == table && !k.is_empty() {
                text.push_str(&format!("{k} = {v}\n"));
            }
        }
    }
    text
}

fn base() -> Vec<(String, String, String)> {
    BASE.iter().map(|(t, k, v)| ((*t).to_owned(), (*k).to_owned(), (*v).to_owned())).collect()
}

/// Sets `table.key = value` (replacing it, or adding it).
fn set(entries: &mut Vec<(String, String, String)>, table: &str, key: &str, value: &str) {
    match entries.iter_mut().find(|(t, k, _)| t == table && k == key) {
        Some(e) => e.2 = value.to_owned(),
        None => entries.push((table.to_owned(), key.to_owned(), value.to_owned())),
    }
}

/// Parses, checks and binds `text` to water: the bound plan with file positions left out, or
/// the error.
fn plan(text: &str) -> Result<String, FileError> {
    let scene = parse_scene("fuzz.toml", text)?;
    let ensemble = parse_ensemble(&scene)?;
    let parameters = rovib::parameters::scene_parameters(&H2o, &scene)?;
    let bound = ensemble.bind(&H2o, &scene, &output_times(scene.t_end, scene.output_interval))?;
    let mut s = scene.clone();
    s.text = String::new();
    let raw = format!(
        "{s:?} {ensemble:?} {parameters:?} {:?} {} {:?} {} {:?} {:?}",
        bound.spec, bound.description, bound.quantities, bound.n_means, bound.histograms, bound.correlations
    );
    Ok(without_positions(&raw))
}

/// `raw` with every `a..b` (a file position) removed.
fn without_positions(raw: &str) -> String {
    let b = raw.as_bytes();
    let mut out = String::with_capacity(raw.len());
    let mut i = 0;
    while i < b.len() {
        if b[i].is_ascii_digit() && (i == 0 || !b[i - 1].is_ascii_alphanumeric() && b[i - 1] != b'.') {
            let mut j = i;
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            if raw[j..].starts_with("..") && b.get(j + 2).is_some_and(u8::is_ascii_digit) {
                let mut k = j + 2;
                while k < b.len() && b[k].is_ascii_digit() {
                    k += 1;
                }
                out.push('@');
                i = k;
                continue;
            }
        }
        out.push(b[i] as char);
        i += 1;
    }
    out
}

fn located(e: &FileError, text: &str) {
    assert_eq!(e.path, "fuzz.toml", "{e}\n{text}");
    assert!(!e.message.is_empty() && !e.help.is_empty(), "{e}\n{text}");
    let whole_file =
        e.message.contains("[ensemble]") || e.message.contains("missing field") || e.message.contains("output times");
    assert!(e.line >= 1 || whole_file, "not located: {e}\n{text}");
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 5 s unoptimised on a loaded 2-core machine"]
fn generated_ensemble_scenes_never_panic_and_are_accepted_or_refused_at_a_place() {
    let begin = std::time::Instant::now();
    let mut rng = Rng(0x5EED_2026_0025);
    let (mut accepted, mut refused) = (0, 0);
    let scenes = 12_000;
    for _ in 0..scenes {
        let mut entries = base();
        for _ in 0..1 + rng.below(4) {
            match rng.below(10) {
                0 => {
                    let i = rng.below(entries.len());
                    if !entries[i].1.is_empty() {
                        entries.remove(i);
                    }
                }
                1 => {
                    let (t, _, _) = POOL[rng.below(POOL.len())];
                    set(&mut entries, t, &format!("unknown_{}", rng.below(3)), "1");
                }
                2 => {
                    // A key in the wrong table.
                    let (_, k, v) = POOL[rng.below(POOL.len())];
                    let (t, _, _) = POOL[rng.below(POOL.len())];
                    set(&mut entries, t, k, v[0]);
                }
                3..=5 => {
                    let (t, k, _) = POOL[rng.below(POOL.len())];
                    set(&mut entries, t, k, HOSTILE[rng.below(HOSTILE.len())]);
                }
                _ => {
                    let (t, k, v) = POOL[rng.below(POOL.len())];
                    set(&mut entries, t, k, v[rng.below(v.len())]);
                }
            }
        }
        let text = render(&entries);
        match catch_unwind(AssertUnwindSafe(|| plan(&text))) {
            Ok(Ok(_)) => accepted += 1,
            Ok(Err(e)) => {
                located(&e, &text);
                refused += 1;
            }
            Err(_) => panic!("panicked on the scene:\n{text}"),
        }
    }
    assert_eq!(accepted + refused, scenes);
    // Both outcomes are exercised, and the whole fuzz stays cheap (no hang).
    assert!(accepted > 500 && refused > 5000, "accepted {accepted}, refused {refused}");
    assert!(begin.elapsed().as_secs() < 60, "{:?}", begin.elapsed());
}

/// What one valid change of a key must do in an ensemble.
#[derive(Debug, PartialEq)]
enum Expect {
    /// Change the bound plan.
    Changes,
    /// Be refused (the key does not apply to ensembles, or this value is below its cap).
    Refused,
}

/// Every key a scene accepts (single-run keys included), with a valid change of it alone.
const KEYS: &[(&str, &str, &str, Expect)] = &[
    ("", "molecule", "\"co2\"", Expect::Changes),
    ("", "description", "\"other\"", Expect::Changes),
    ("units", "length", "\"angstrom\"", Expect::Changes),
    ("units", "angle", "\"deg\"", Expect::Changes),
    ("units", "time", "\"fs\"", Expect::Changes),
    ("ensemble", "trajectories", "101", Expect::Changes),
    ("ensemble", "seed", "8", Expect::Changes),
    ("ensemble", "method", "\"file\"", Expect::Refused),
    ("ensemble", "temperature", "301", Expect::Changes),
    ("ensemble", "energy_unit", "\"eV\"", Expect::Changes),
    ("ensemble", "region", "{ energy_cap = 0.2 }", Expect::Changes),
    ("ensemble", "threads", "1", Expect::Changes),
    ("ensemble", "keep_trajectories", "10", Expect::Changes),
    ("ensemble", "max_memory_gb", "0.000001", Expect::Refused),
    ("ensemble", "max_disk_gb", "0.000001", Expect::Refused),
    ("statistics", "means", "[\"r1\"]", Expect::Changes),
    (
        "statistics",
        "histograms",
        "[{ quantity = \"alpha\", bins = 21, range = [1.0, 2.5], times = [0, 50] }]",
        Expect::Changes,
    ),
    ("statistics", "correlations", "[\"r1\"]", Expect::Changes),
    ("integrator", "rtol", "1e-9", Expect::Changes),
    ("integrator", "atol", "1e-9", Expect::Changes),
    ("integrator", "max_steps", "1000", Expect::Changes),
    ("integrator", "min_step", "1e-6", Expect::Changes),
    ("run", "end", "110", Expect::Changes),
    ("run", "output_interval", "5", Expect::Changes),
    ("run", "outputs", "[\"summary\"]", Expect::Refused),
    ("run", "frozen", "[\"alpha\"]", Expect::Changes),
    ("run", "min_metric_pivot", "0.001", Expect::Changes),
    ("run", "max_energy_error", "1e-6", Expect::Changes),
    ("run", "max_outputs", "5", Expect::Refused),
    ("run", "euler_unwrapped", "false", Expect::Refused),
    ("run", "cartesian_fallback", "false", Expect::Changes),
    ("run", "stop_outside", "{ r1 = [0.5, 5.0] }", Expect::Changes),
    ("initial", "q", "{ r1 = 1.0 }", Expect::Refused),
    ("potential.parameters", "re", "1.0", Expect::Changes),
];

/// Keys whose valid change applies to other methods or integrators, checked from a base that
/// uses them: (base changes, table, key, value, expectation).
/// A key checked from a base scene changed by some `(table, key, value)` (an empty value removes
/// the key).
type Elsewhere =
    (&'static [(&'static str, &'static str, &'static str)], &'static str, &'static str, &'static str, Expect);

const KEYS_ELSEWHERE: &[Elsewhere] = &[
    (
        &[
            ("ensemble", "method", "\"microcanonical\""),
            ("ensemble", "temperature", ""),
            ("ensemble", "energy", "0.01"),
        ],
        "ensemble",
        "energy",
        "0.02",
        Expect::Changes,
    ),
    (
        &[
            ("ensemble", "method", "\"microcanonical\""),
            ("ensemble", "temperature", ""),
            ("ensemble", "energy", "0.01"),
        ],
        "ensemble",
        "angular_momentum",
        "3",
        Expect::Changes,
    ),
    (
        &[("ensemble", "method", "\"normal-modes\""), ("ensemble", "region", ""), ("ensemble", "quanta", "[0, 0, 0]")],
        "ensemble",
        "quanta",
        "[1, 0, 0]",
        Expect::Changes,
    ),
    (
        &[
            ("ensemble", "method", "\"normal-modes\""),
            ("ensemble", "region", ""),
            ("ensemble", "temperature", ""),
            ("ensemble", "mode_energies", "[0.001, 0, 0]"),
        ],
        "ensemble",
        "mode_energies",
        "[0.002, 0, 0]",
        Expect::Changes,
    ),
    (
        &[
            ("ensemble", "method", "\"normal-modes\""),
            ("ensemble", "region", ""),
            ("ensemble", "temperature", ""),
            ("ensemble", "quanta", "[0, 0, 0]"),
        ],
        "ensemble",
        "j",
        "[0, 0, 3]",
        Expect::Changes,
    ),
    (&[("integrator", "rtol", "")], "integrator", "method", "\"rk4\"\nstep = 0.5", Expect::Changes),
    (
        &[("integrator", "method", "\"gauss-legendre\""), ("integrator", "rtol", ""), ("integrator", "step", "0.5")],
        "integrator",
        "step",
        "0.25",
        Expect::Changes,
    ),
    (
        &[("integrator", "method", "\"gauss-legendre\""), ("integrator", "rtol", ""), ("integrator", "step", "0.5")],
        "integrator",
        "stages",
        "2",
        Expect::Changes,
    ),
    (
        &[("integrator", "method", "\"gauss-legendre\""), ("integrator", "rtol", ""), ("integrator", "step", "0.5")],
        "integrator",
        "compensated",
        "false",
        Expect::Changes,
    ),
];

fn outcome(entries: &[(String, String, String)]) -> Result<String, FileError> {
    plan(&render(entries))
}

fn check_key(mut entries: Vec<(String, String, String)>, table: &str, key: &str, value: &str, expect: &Expect) {
    let before = outcome(&entries).unwrap_or_else(|e| panic!("the base scene for {table}.{key} is refused: {e}"));
    set(&mut entries, table, key, value);
    let text = render(&entries);
    match (plan(&text), expect) {
        (Ok(after), Expect::Changes) => {
            assert_ne!(before, after, "changing only {table}.{key} to {value} changes nothing: ignored\n{text}")
        }
        (Err(e), Expect::Refused) => located(&e, &text),
        (other, _) => panic!("{table}.{key} = {value}: expected {expect:?}, got {other:?}\n{text}"),
    }
}

#[test]
fn no_key_is_silently_ignored() {
    for (table, key, value, expect) in KEYS {
        check_key(base(), table, key, value, expect);
    }
    for (changes, table, key, value, expect) in KEYS_ELSEWHERE {
        let mut entries = base();
        for (t, k, v) in *changes {
            if v.is_empty() {
                entries.retain(|(et, ek, _)| !(et == t && ek == k));
            } else {
                set(&mut entries, t, k, v);
            }
        }
        check_key(entries, table, key, value, expect);
    }
    // `file`: two states files that differ in one state.
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-ensemble-fuzz");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let rows = "1.8,1.8,1.82\n".repeat(100);
    std::fs::write(dir.join("a.csv"), format!("r1,r2,alpha\n{rows}")).unwrap();
    std::fs::write(dir.join("b.csv"), format!("r1,r2,alpha\n1.9,1.8,1.82\n{rows}")).unwrap();
    let mut entries = base();
    entries.retain(|(t, k, _)| !(t == "ensemble" && (k == "region" || k == "temperature")));
    set(&mut entries, "ensemble", "method", "\"file\"");
    set(&mut entries, "ensemble", "file", &format!("{:?}", dir.join("a.csv").to_str().unwrap()));
    check_key(entries, "ensemble", "file", &format!("{:?}", dir.join("b.csv").to_str().unwrap()), &Expect::Changes);
    let _ = std::fs::remove_dir_all(&dir);
}
