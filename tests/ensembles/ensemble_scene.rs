//! Bad `[ensemble]` and `[statistics]` input: every error names the file, the line and what to
//! change (one test per message).

use rovib::Error;
use rovib::ensemble::scene::{DEFAULT_SEED, parse_ensemble};
use rovib::ensemble::{EnsembleOptions, run_ensemble};
use rovib::runtime::diagnostic::FileError;
use rovib::scene::parse_scene;

const RUN: &str = "[run]\nend = 100\noutput_interval = 10\n";

/// The error for a scene: from parsing, or from binding it to the molecule (run_ensemble stops
/// there, before any trajectory, when the method cannot be sampled).
fn error(ensemble: &str) -> FileError {
    let text = format!("molecule = \"h2o\"\n{ensemble}\n{RUN}");
    let scene = match parse_scene("bad.toml", &text) {
        Ok(s) => s,
        Err(e) => return e,
    };
    if let Err(e) = parse_ensemble(&scene) {
        return e;
    }
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-ensemble-scene");
    match run_ensemble(&scene, &EnsembleOptions::new(out)) {
        Err(Error::File(e)) => e,
        other => panic!("expected a located error, got {other:?}"),
    }
}

fn check(e: &FileError, line: usize, message: &str, help: &str) {
    assert_eq!(e.path, "bad.toml");
    assert_eq!(e.line, line, "{e}");
    assert!(e.message.contains(message), "message: {e}");
    assert!(e.help.contains(help), "help: {e}");
}

#[test]
fn unknown_method_suggests_the_closest() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"thermla\"\ntemperature = 300");
    check(&e, 4, "unknown ensemble method `thermla`", "did you mean \"thermal\"?");
}

#[test]
fn temperature_must_be_positive() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 0");
    check(&e, 5, "`ensemble.temperature` must be a positive finite number of kelvin, got 0", "above 0 K");
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = -3.0");
    check(&e, 5, "got -3", "above 0 K");
}

#[test]
fn thermal_needs_a_temperature() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"thermal\"");
    check(&e, 4, "the thermal method needs `temperature`", "add temperature = ... (kelvin)");
}

#[test]
fn zero_trajectories() {
    let e = error("[ensemble]\ntrajectories = 0\nmethod = \"thermal\"\ntemperature = 300");
    check(&e, 3, "`ensemble.trajectories` must be at least 1, got 0", "trajectories = 1000");
}

#[test]
fn energy_cap_below_the_energy() {
    // U at the reference geometry is 0 for h2o.toml's potential; E = 0.05, cap 0.01 hartree.
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"microcanonical\"\nenergy = 0.05\n\
         region = { energy_cap = 0.01 }",
    );
    check(&e, 6, "the energy cap 0.01 hartree is below the energy above the reference", "raise region.energy_cap");
}

#[test]
fn energy_below_the_minimum() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"microcanonical\"\nenergy = -1\nenergy_unit = \"eV\"");
    check(&e, 5, "is below the potential at the reference geometry", "above the minimum of the potential");
}

#[test]
fn missing_seed_takes_the_documented_default() {
    let text =
        format!("molecule = \"h2o\"\n[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n{RUN}");
    let e = parse_ensemble(&parse_scene("ok.toml", &text).unwrap()).unwrap();
    assert_eq!((e.seed, e.seed_given, DEFAULT_SEED), (0, false, 0));
    let text = text.replace("[ensemble]\n", "[ensemble]\nseed = 42\n");
    let e = parse_ensemble(&parse_scene("ok.toml", &text).unwrap()).unwrap();
    assert_eq!((e.seed, e.seed_given), (42, true));
}

#[test]
fn negative_seed() {
    let e = error("[ensemble]\ntrajectories = 10\nseed = -1\nmethod = \"thermal\"\ntemperature = 300");
    check(&e, 4, "`ensemble.seed` must be a non-negative integer", "from 0 to");
}

#[test]
fn a_key_of_another_method() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\nenergy = 0.1");
    check(&e, 6, "`energy` does not apply to the thermal method", "the thermal method takes temperature");
}

#[test]
fn unknown_key() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperture = 300");
    check(&e, 5, "unknown field `temperture`", "docs/src/reference/ensemble.md");
}

#[test]
fn unknown_energy_unit() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"microcanonical\"\nenergy = 1\nenergy_unit = \"kJ/mol\"");
    check(&e, 6, "unknown energy unit `kJ/mol`", "\"cm-1\"");
}

#[test]
fn zero_threads() {
    let e = error("[ensemble]\ntrajectories = 10\nthreads = 0\nmethod = \"thermal\"\ntemperature = 300");
    check(&e, 4, "`ensemble.threads` must be at least 1", "every core");
}

#[test]
fn region_limits_of_an_unknown_coordinate() {
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
         region = { limits = { r3 = [1.0, 2.0] } }",
    );
    check(&e, 6, "h2o has no coordinate `r3`", "did you mean `r1`?");
}

#[test]
fn region_limits_in_the_wrong_order() {
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
         region = { limits = { r1 = [2.0, 1.0] } }",
    );
    check(&e, 6, "the limits of `r1` must be two finite numbers [low, high] with low < high", "r1 = [low, high]");
}

#[test]
fn unknown_quantity_suggests_the_closest() {
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
         [statistics]\nmeans = [\"r1\", \"alpah\"]",
    );
    check(&e, 7, "no quantity is called `alpah`", "did you mean `alpha`?");
}

#[test]
fn histogram_with_an_empty_range() {
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
         [statistics]\nhistograms = [{ quantity = \"r1\", bins = 10, range = [2.0, 2.0] }]",
    );
    check(&e, 7, "a histogram's range must be two finite numbers [low, high] with low < high", "range = [low, high]");
}

#[test]
fn histogram_with_no_bins() {
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
         [statistics]\nhistograms = [{ quantity = \"r1\", bins = 0, range = [1.0, 2.0] }]",
    );
    check(&e, 7, "a histogram needs at least one bin, got 0", "bins = 50");
}

#[test]
fn histogram_with_too_many_bins() {
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
         [statistics]\nhistograms = [{ quantity = \"r1\", bins = 1000000000000, range = [1.0, 2.0] }]",
    );
    check(&e, 7, "a histogram of 1000000000000 bins is more than the 1000000 allowed", "fewer bins");
}

#[test]
fn too_many_output_times() {
    let text = "molecule = \"h2o\"\n[ensemble]\ntrajectories = 1\nmethod = \"thermal\"\ntemperature = 1\n\
                [run]\nend = 1e9\noutput_interval = 1\n";
    // Refused by the scene parser already (run.max_outputs, default 10^6), where it is written.
    let e = parse_scene("bad.toml", text).unwrap_err();
    assert!(e.message.contains("output times"), "{e}");
    assert!(e.message.contains("more than 1000000"), "{e}");
    assert_eq!(e.line, 8);
    // Raising run.max_outputs does not lift the ensemble's own limit.
    let raised = text.replace("[run]\n", "[run]\nmax_outputs = 2000000000\n");
    let e = parse_ensemble(&parse_scene("bad.toml", &raised).unwrap()).unwrap_err();
    assert!(e.message.contains("output times, more than the 1000000 an ensemble allows"), "{e}");
    assert!(e.help.contains("raise run.output_interval"), "{e}");
}

#[test]
fn histogram_time_outside_the_run() {
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
         [statistics]\nhistograms = [{ quantity = \"r1\", bins = 5, range = [1.0, 2.0], times = [0, 500] }]",
    );
    check(&e, 7, "histogram time 500 is outside the run, 0 to run.end = 100", "between 0 and run.end");
}

#[test]
fn normal_modes_need_the_mode_energies() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"normal-modes\"\ntemperature = 300");
    check(&e, 4, "the normal-modes method needs the mode energies", "quanta = [v1, v2, ...]");
}

#[test]
fn negative_quantum_number() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"normal-modes\"\nquanta = [0, -1, 0]");
    check(&e, 5, "quantum number -1 is not a non-negative integer", "v ≥ 0");
}

#[test]
fn states_file_that_does_not_exist() {
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"file\"\nfile = \"no-such-states.csv\"");
    check(&e, 5, "cannot read the states file", "readable CSV or extended XYZ file");
}

#[test]
fn statistics_without_an_ensemble() {
    let text = format!("molecule = \"h2o\"\n[initial]\n[statistics]\nmeans = [\"r1\"]\n{RUN}");
    let e = parse_scene("bad.toml", &text).unwrap_err();
    assert!(e.message.contains("a [statistics] table without an [ensemble] table"), "{e}");
}

#[test]
fn a_scene_needs_initial_or_ensemble() {
    let text = format!("molecule = \"h2o\"\n{RUN}");
    let e = parse_scene("bad.toml", &text).unwrap_err();
    assert!(e.message.contains("missing field `initial`") && e.help.contains("[ensemble]"), "{e}");
}

#[test]
fn the_samplers_own_refusal_is_located_at_the_method() {
    // One quantum number for water's three modes: refused by the normal-mode sampler (the
    // count), located at `method`.
    let e = error("[ensemble]\ntrajectories = 10\nmethod = \"normal-modes\"\nquanta = [0]");
    check(&e, 4, "cannot sample this ensemble", "change the method or its parameters");
    assert!(e.message.contains("give 3 quantum numbers"), "{e}");
}

#[test]
fn a_bad_number_in_the_states_file_is_located_in_that_file() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-ensemble-states");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("states.csv"), "r1,r2,alpha\n1.8,1.8,1.82\n1.8,oops,1.82\n").unwrap();
    let text =
        format!("molecule = \"h2o\"\n[ensemble]\ntrajectories = 2\nmethod = \"file\"\nfile = \"states.csv\"\n{RUN}");
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let scene = rovib::ensemble::load_scene(&path).unwrap();
    let Err(Error::File(e)) = run_ensemble(&scene, &EnsembleOptions::new(dir.join("out"))) else {
        panic!("expected a located error")
    };
    assert_eq!((e.path.as_str(), e.line, e.column), (dir.join("states.csv").to_str().unwrap(), 3, 5), "{e}");
    assert!(e.message.contains("`oops` is not a finite number"), "{e}");
    // Too few states for the trajectories asked for: located at `trajectories` in the scene.
    std::fs::write(dir.join("states.csv"), "r1,r2,alpha\n1.8,1.8,1.82\n").unwrap();
    let Err(Error::File(e)) = run_ensemble(&scene, &EnsembleOptions::new(dir.join("out"))) else {
        panic!("expected a located error")
    };
    assert_eq!(e.line, 3, "{e}");
    assert!(e.message.contains("has 1 states but trajectories = 2") && e.help.contains("at most 1"), "{e}");
}

/// Every line of the shipped ensemble scenes deleted or its value replaced by something wrong:
/// parsing and binding never panic, and every error is located in the file.
#[test]
fn mutated_ensemble_scenes_never_panic_and_every_error_is_located() {
    use rovib::ensemble::output_times;
    use rovib::molecules::H2o;
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");
    let mut checked = 0;
    for name in ["h2o_thermal.toml", "h2o_quasiclassical.toml", "h2o_ensemble_bench.toml"] {
        let original = std::fs::read_to_string(format!("{dir}/{name}")).unwrap();
        let lines: Vec<&str> = original.lines().collect();
        for i in 0..lines.len() {
            let Some((key, _)) = lines[i].split_once('=') else { continue };
            for replacement in ["", "-1", "0", "1e400", "\"nonsense\"", "[]", "[1, 2, 3]", "{ x = 1 }", "1.5"] {
                let mut mutated = lines.clone();
                let line = if replacement.is_empty() { String::new() } else { format!("{key}= {replacement}") };
                mutated[i] = &line;
                let text = mutated.join("\n");
                let scene = match parse_scene("bad.toml", &text) {
                    Ok(s) => s,
                    Err(e) => {
                        assert!(!e.message.is_empty() && !e.help.is_empty(), "{e}");
                        continue;
                    }
                };
                let result = parse_ensemble(&scene)
                    .and_then(|e| e.bind(&H2o, &scene, &output_times(scene.t_end, scene.output_interval)).map(|_| ()));
                if let Err(e) = result {
                    assert_eq!(e.path, "bad.toml");
                    assert!(!e.message.is_empty() && !e.help.is_empty(), "{e}");
                    assert!(e.line >= 1 || e.message.contains("[ensemble]") || e.message.contains("missing"), "{e}");
                }
                checked += 1;
            }
        }
    }
    assert!(checked > 50, "{checked}");
}

/// Keys that describe one trajectory and its files are refused in an ensemble where they are
/// written, with what to do instead (they were accepted and had no effect).
#[test]
fn single_run_keys_are_refused_in_an_ensemble() {
    let ensemble = "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n";
    let text = format!("molecule = \"h2o\"\n[initial]\nq = {{ r1 = 1.0 }}\n{ensemble}{RUN}");
    let e = parse_ensemble(&parse_scene("bad.toml", &text).unwrap()).unwrap_err();
    check(&e, 2, "an ensemble does not use [initial]", "method = \"file\"");
    for (key, line, message, help) in [
        ("outputs = [\"trajectory\"]", 9, "`run.outputs` does not apply to an ensemble", "keep_trajectories"),
        ("euler_unwrapped = true", 9, "`run.euler_unwrapped` does not apply to an ensemble", "`rovib run`"),
        ("euler_unwrapped = false", 9, "`run.euler_unwrapped` does not apply to an ensemble", "remove it"),
    ] {
        let text = format!("molecule = \"h2o\"\n{ensemble}{RUN}{key}\n");
        let e = parse_ensemble(&parse_scene("bad.toml", &text).unwrap()).unwrap_err();
        check(&e, line, message, help);
    }
}

/// A histogram whose width or bin width overflows or cannot be resolved at the range's
/// magnitude (NaN or coinciding bin edges) is refused at its range.
#[test]
fn histogram_ranges_that_are_not_representable() {
    for (range, bins) in [("[-1e308, 1e308]", 10), ("[1e10, 1.000000000001e10]", 1000000), ("[0, 1e-310]", 1)] {
        let e = error(&format!(
            "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
             [statistics]\nhistograms = [{{ quantity = \"r1\", bins = {bins}, range = {range} }}]"
        ));
        check(&e, 7, "has a width or bin width that is not a finite, resolvable number", "range = [0, 10]");
    }
}

/// The names a definition may not give a coordinate are exactly the ensemble's own quantities.
#[test]
fn the_reserved_coordinate_names_are_the_quantity_names() {
    use rovib::ensemble::quantity::Quantity;
    assert_eq!(Quantity::reserved_names(), rovib_codegen::definition::RESERVED_QUANTITY_NAMES.to_vec());
}

/// Threads: at most one per block and a few per core, with a note when fewer than asked run.
#[test]
fn threads_are_capped_by_the_work_and_the_cores() {
    use rovib::ensemble::{MAX_THREADS_PER_CORE, worker_threads};
    assert_eq!(worker_threads(None, 2, 100), (2, None));
    assert_eq!(worker_threads(Some(2), 2, 100), (2, None));
    let (t, note) = worker_threads(Some(100_000), 2, 1_000_000);
    assert_eq!(t, 2 * MAX_THREADS_PER_CORE);
    assert!(note.unwrap().contains("100000 threads were asked for, 8 run: this machine has 2 core(s)"));
    let (t, note) = worker_threads(Some(3000), 64, 1);
    assert_eq!(t, 1);
    assert!(note.unwrap().contains("the ensemble has 1 block(s) of 64 trajectories"));
    // Through the runner: the thread count used and the note in the report and summary.json.
    let text = "molecule = \"h2o\"\n[ensemble]\ntrajectories = 3\nthreads = 100000\nmethod = \"thermal\"\n\
                temperature = 300\nregion = { energy_cap = 0.1 }\n[run]\nend = 2\noutput_interval = 1\n";
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-ensemble-threads");
    let _ = std::fs::remove_dir_all(&out);
    let begin = std::time::Instant::now();
    let report = run_ensemble(&parse_scene("t.toml", text).unwrap(), &EnsembleOptions::new(&out)).unwrap();
    assert_eq!(report.threads, 1);
    assert!(begin.elapsed().as_secs() < 20);
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(summary.contains("100000 threads were asked for, 1 run"), "{summary}");
    let _ = std::fs::remove_dir_all(&out);
}

/// `[ensemble]` written with its nested tables as sub-tables, every error at the line and
/// column of what it is about, however deep: the method's keys are read with their places
/// inside `region` and `region.limits` too.
#[test]
fn errors_inside_the_nested_tables_of_a_method_are_at_their_place() {
    let nested = |limits: &str| {
        format!(
            "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\n\
             [ensemble.region]\nenergy_cap = 0.1\n\n[ensemble.region.limits]\nr1 = [1.0, 2.0]\n{limits}\n"
        )
    };
    let at = |e: &FileError, line: usize, column: usize| {
        assert_eq!((e.line, e.column), (line, column), "{e}");
    };
    // A limit in the wrong order: at its value (line 12 of the file, after `alpha = `).
    let e = error(&nested("alpha = [2.0, 1.0]"));
    check(
        &e,
        12,
        "the limits of `alpha` must be two finite numbers [low, high] with low < high",
        "alpha = [low, high]",
    );
    at(&e, 12, 9);
    // A value of the wrong type inside a limit: at the element.
    let e = error(&nested("alpha = [1.0, \"x\"]"));
    check(&e, 12, "invalid type: string \"x\", expected f64", "ensemble reference");
    at(&e, 12, 15);
    // A key `region` does not take: at the key.
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\n\
         [ensemble.region]\nenergy_cap = 0.1\n  limit = { r1 = [1.0, 2.0] }",
    );
    check(&e, 8, "unknown field `limit`, expected `energy_cap` or `limits`", "ensemble reference");
    at(&e, 8, 3);
    // A cap that is not positive, inside an inline table: at the value.
    let e =
        error("[ensemble]\ntrajectories = 10\nmethod = \"thermal\"\ntemperature = 300\nregion = { energy_cap = -1 }");
    check(&e, 6, "`region.energy_cap` must be a positive finite energy, got -1", "ensemble.energy_unit");
    at(&e, 6, 25);
    // A nested table of another method: at the key.
    let e = error(
        "[ensemble]\ntrajectories = 10\nmethod = \"normal-modes\"\nquanta = [0, 0, 0]\n\n[ensemble.region]\nenergy_cap = 0.1",
    );
    check(&e, 7, "`region` does not apply to the normal-modes method", "the normal-modes method takes energy");
    at(&e, 7, 1);
}
