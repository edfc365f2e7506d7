//! `run.chart`: an ensemble integrated in the lab-frame Cartesian chart gives the statistics
//! of the internal chart within the integration error, on lanes the one-at-a-time outcome to
//! round-off, `auto` (the default) chooses the Cartesian chart for a molecule linear at its
//! reference geometry and the internal chart otherwise, and the key's wrong values and
//! unsupported scenes are located errors.

use crate::common;

use rovib::ensemble::{EnsembleReport, run_ensemble};
use rovib::scene::parse_scene;

/// A thermal water ensemble (300 K, energy cap 0.1 hartree; 16 trajectories, 400 a.u., DOP853 at rtol = atol = 1e-10) with
/// `extra` added to `[run]`.
fn text(extra: &str) -> String {
    text_for("h2o", extra)
}

/// [`text`] for `molecule`.
fn text_for(molecule: &str, extra: &str) -> String {
    format!(
        "molecule = \"{molecule}\"\n[ensemble]\ntrajectories = 16\nseed = 7\nmethod = \"thermal\"\ntemperature = 300\nregion = {{ energy_cap = 0.1 }}\n\
         [statistics]\nmeans = [\"r1\", \"r2\", \"alpha\", \"H\", \"J\", \"Lz\"]\n\
         [integrator]\nmethod = \"dop853\"\nrtol = 1e-10\natol = 1e-10\n\
         [run]\nend = 400\noutput_interval = 40\n{extra}"
    )
}

fn run(name: &str, extra: &str, lanes: bool) -> (EnsembleReport, serde_json::Value) {
    run_for("h2o", name, extra, lanes)
}

fn run_for(molecule: &str, name: &str, extra: &str, lanes: bool) -> (EnsembleReport, serde_json::Value) {
    let scene = parse_scene("test.toml", &text_for(molecule, extra)).unwrap();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-chart-choice-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    let mut options = common::ensemble::options(dir.clone(), 1);
    options.lanes = lanes;
    let report = run_ensemble(&scene, &options).unwrap();
    let summary = serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    (report, summary)
}

/// The same ensemble in both charts (each on lanes, the default): the means agree within 1e-7
/// (bohr, rad, hartree, ħ) at every output time. Each chart's final-state error at rtol = atol =
/// 1e-10 over 10⁴ a.u. measured 1e-10..1e-8 bohr (BENCHMARKS.md, "rovib against a plain
/// Cartesian code"), so over 400 a.u. the two trajectories of a state differ by well under 1e-8:
/// the bound leaves a factor 10 and is far below what a wrong conversion gives (a velocity or
/// angular momentum in the wrong frame moves r1 by ~1e-3 bohr and J by ~1 ħ within 400 a.u.).
/// The two runs did integrate different equations (their right-hand-side counts differ), and
/// summary.json names the chart.
#[test]
fn the_cartesian_chart_gives_the_internal_charts_statistics_within_the_tolerance() {
    let (internal, si) = run("internal", "", true);
    let (cartesian, sc) = run("cartesian", "chart = \"cartesian\"\n", true);
    assert_eq!(si["chart"], "internal");
    assert_eq!(sc["chart"], "cartesian");
    assert_eq!(internal.outcome.completed, 16, "{:?}", internal.outcome.first_failures);
    assert_eq!(cartesian.outcome.completed, 16, "{:?}", cartesian.outcome.first_failures);
    assert_ne!(internal.outcome.rhs_evaluations, cartesian.outcome.rhs_evaluations);
    let (a, b) = (&internal.outcome.statistics.means, &cartesian.outcome.statistics.means);
    assert_eq!(a.len(), b.len());
    let mut worst: f64 = 0.0;
    for (x, y) in a.iter().zip(b) {
        assert_eq!(x.count(), y.count());
        worst = worst.max((x.mean() - y.mean()).abs());
    }
    eprintln!("largest difference of the charts' means: {worst:e}");
    assert!(worst <= 1e-7, "the charts' means differ by up to {worst:e}");
}

/// On lanes the Cartesian chart computes each trajectory as the one-at-a-time path does (the
/// lane gradient is the f64 gradient's operations; `sin_cos`/`exp` within 2 ulp), so the
/// outcomes agree to round-off: the same counts and steps, means within 1e-11 relative.
#[test]
fn cartesian_lanes_give_the_one_at_a_time_outcome_to_round_off() {
    let (scalar, _) = run("cartesian-scalar", "chart = \"cartesian\"\n", false);
    let (lanes, _) = run("cartesian-lanes", "chart = \"cartesian\"\n", true);
    assert_eq!(scalar.outcome.completed, 16);
    assert_eq!(lanes.outcome.completed, 16);
    assert_eq!(scalar.outcome.steps, lanes.outcome.steps);
    assert_eq!(scalar.outcome.rhs_evaluations, lanes.outcome.rhs_evaluations);
    for (x, y) in scalar.outcome.statistics.means.iter().zip(&lanes.outcome.statistics.means) {
        assert!((x.mean() - y.mean()).abs() <= 1e-11 * y.mean().abs().max(1.0), "{} vs {}", x.mean(), y.mean());
    }
}

/// `auto`, the default, is a fixed rule on the molecule: co2, linear at its reference geometry
/// (where a thermal ensemble keeps switching charts), runs in the Cartesian chart; water in the
/// internal chart (the test above); co2 with `chart = "internal"`, with the switch turned off or
/// with a frozen coordinate (no Cartesian counterpart) in the internal chart. The chart chosen
/// gives the internal chart's means (with its switches) within 1e-7, as for water above: the
/// internal run of co2 did switch charts, so this also compares the switching path with a
/// trajectory that never switches.
#[test]
fn the_default_chart_is_cartesian_for_a_molecule_linear_at_its_reference_and_internal_otherwise() {
    let (auto, sa) = run_for("co2", "co2-auto", "", true);
    let (internal, si) = run_for("co2", "co2-internal", "chart = \"internal\"\n", true);
    assert_eq!(sa["chart"], "cartesian");
    assert_eq!(si["chart"], "internal");
    assert!(si["charts"]["switches"].as_u64().unwrap_or(0) > 0, "{}", si["charts"]);
    assert_eq!(auto.outcome.completed, 16, "{:?}", auto.outcome.first_failures);
    assert_eq!(internal.outcome.completed, 16, "{:?}", internal.outcome.first_failures);
    let mut worst: f64 = 0.0;
    for (x, y) in internal.outcome.statistics.means.iter().zip(&auto.outcome.statistics.means) {
        worst = worst.max((x.mean() - y.mean()).abs());
    }
    assert!(worst <= 1e-7, "the charts' means differ by up to {worst:e}");
    let (_, s) = run_for("co2", "co2-no-switch", "cartesian_fallback = false\n", false);
    assert_eq!(s["chart"], "internal");
    let (_, s) = run_for("co2", "co2-frozen", "frozen = [\"r1\"]\n", false);
    assert_eq!(s["chart"], "internal");
}

#[test]
fn a_wrong_chart_is_a_located_error_with_a_suggestion() {
    let f = parse_scene("test.toml", &text("chart = \"cartesain\"\n")).unwrap_err();
    assert_eq!(f.line, 17, "{f}");
    let e = f.to_string();
    assert!(e.contains("unknown `run.chart` \"cartesain\""), "{e}");
    assert!(e.contains("did you mean \"cartesian\""), "{e}");
}

/// Frozen coordinates have no Cartesian counterpart: refused at the key, before any output.
#[test]
fn the_cartesian_chart_with_frozen_coordinates_is_refused_at_the_key() {
    let scene = parse_scene("test.toml", &text("frozen = [\"alpha\"]\nchart = \"cartesian\"\n")).unwrap();
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-chart-choice-frozen");
    let _ = std::fs::remove_dir_all(&dir);
    let e = run_ensemble(&scene, &common::ensemble::options(dir.clone(), 1)).unwrap_err();
    let rovib::Error::File(f) = &e else { panic!("not a located error: {e}") };
    assert_eq!(f.line, 18, "{f}");
    let e = e.to_string();
    assert!(e.contains("not available") && e.contains("run.frozen"), "{e}");
    assert!(!dir.join("summary.json").exists());
}
