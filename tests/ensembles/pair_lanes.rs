//! The pair estimator on SIMD lanes against one trajectory at a time: the model atom–atom pair
//! `molecules/n2ar_pair.toml` with `[pairs]` classes and `run.stop_outside`, run with lanes and
//! with `--no-lanes`. Each trajectory's forward and backward runs are separate lane jobs; every
//! output the two runs write (correlations, spectrum, moments, pair-state counts, correlations
//! and spectra per class, means, stops) agrees to round-off (measured: 4e-14 of each column's
//! largest value).

use crate::common;
use common::ensemble::csv;
use std::path::{Path, PathBuf};

use rovib::ensemble::run_ensemble;
use rovib::scene::parse_scene;

fn out_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-pairlanes-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// 96 pairs at 250 K in d ∈ [5.5, 20] bohr, 600 a.u. each way, stopped once d passes 11 bohr.
const SCENE: &str = r#"molecule = "n2ar_pair"
[units]
length = "bohr"
[ensemble]
trajectories = 96
seed = 2811
method = "thermal"
temperature = 250.0
region = { limits = { r = [1.47, 2.67], d = [5.5, 20.0], alpha = [0.0, 3.141592653589793] } }
[statistics]
means = ["d", "mu_x"]
correlations = ["mu_x", "mu_y", "mu_z"]
[spectrum]
estimator = "pair"
max_wavenumber = 1500.0
[pairs]
monomers = [["N2"], ["Ar"]]
distance = "d"
[integrator]
method = "dop853"
rtol = 1e-9
atol = 1e-10
[run]
end = 600.0
output_interval = 20.0
stop_outside = { d = [0.0, 11.0] }
"#;

fn run(name: &str, lanes: bool) -> (PathBuf, serde_json::Value) {
    let scene = parse_scene("pairlanes.toml", SCENE).unwrap();
    let dir = out_dir(name);
    let mut o = common::ensemble::options(dir.clone(), 2);
    o.lanes = lanes;
    run_ensemble(&scene, &o).unwrap();
    let summary = common::ensemble::summary(&dir);
    (dir, summary)
}

/// The largest difference between two CSV files of one layout, relative to each column's
/// largest magnitude.
fn worst_difference(a: &Path, b: &Path) -> f64 {
    let ((ha, ra), (hb, rb)) = (csv(a), csv(b));
    assert_eq!(ha, hb, "{}: headers differ", a.display());
    assert_eq!(ra.len(), rb.len(), "{}: row counts differ", a.display());
    let mut worst = 0.0f64;
    for c in 0..ha.len() {
        let scale = ra.iter().map(|r| r[c].abs()).filter(|x| x.is_finite()).fold(0.0, f64::max);
        for (x, y) in ra.iter().zip(&rb) {
            let (x, y) = (x[c], y[c]);
            if x.is_nan() && y.is_nan() {
                continue;
            }
            let d = if x == y { 0.0 } else { (x - y).abs() / scale };
            assert!(d.is_finite(), "{}: column {} has {x} against {y}", a.display(), ha[c]);
            worst = worst.max(d);
        }
    }
    worst
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 22 s unoptimised on a loaded 2-core machine"]
fn pair_ensembles_on_lanes_have_the_one_at_a_time_outputs_to_round_off() {
    let (a, sa) = run("lanes", true);
    let (b, sb) = run("nolanes", false);
    // Both directions stopped somewhere, so the stops are exercised on lanes.
    assert!(sa["stops"]["stopped"].as_u64().unwrap() > 0, "no pair left the region");
    for key in ["completed", "failed", "interrupted_or_not_run"] {
        assert_eq!(sa["trajectories"][key], sb["trajectories"][key], "trajectories.{key}");
    }
    assert_eq!(sa["trajectories"]["completed"].as_u64(), Some(96));
    assert_eq!(sa["stops"], sb["stops"], "stops");
    assert_eq!(sa["pair_states"]["states"], sb["pair_states"]["states"]);
    for c in ["bound", "metastable", "free"] {
        let (x, y) = (&sa["pair_states"]["classes"][c], &sb["pair_states"]["classes"][c]);
        assert_eq!(x["count"], y["count"], "{c} count");
    }
    for file in [
        "correlations.csv",
        "spectrum.csv",
        "moments.csv",
        "ensemble.csv",
        "lifetimes.csv",
        "stops.csv",
        "histograms.csv",
        "pair_states.csv",
        "correlations_by_state.csv",
        "spectrum_by_state.csv",
    ] {
        let worst = worst_difference(&a.join(file), &b.join(file));
        eprintln!("{file}: lanes against one at a time, largest relative difference {worst:.1e}");
        assert!(worst <= 1e-12, "{file}: lanes and one at a time differ by {worst:e} (relative)");
    }
}
