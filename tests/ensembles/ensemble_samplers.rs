//! Ensembles through the runner with rovib's own samplers (thermal, microcanonical): what the
//! runner's statistics must show for the right distribution (equipartition, Liouville
//! stationarity, the energy shell) and byte-identical outputs on 1 and 2 threads.

use crate::common;
use common::ensemble::{column, csv};
use std::path::PathBuf;

use rovib::ensemble::{EnsembleOptions, run_ensemble};
use rovib::molecules::H2o;
use rovib::runtime::nalgebra::SVector;
use rovib::runtime::sample::BOLTZMANN;
use rovib::runtime::{Kinematics, Molecule};
use rovib::scene::{Scene, parse_scene};

fn out_dir(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-ensemble-samplers-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn options(name: &str, threads: usize) -> EnsembleOptions {
    common::ensemble::options(out_dir(name), threads)
}

fn scene(body: &str) -> Scene {
    parse_scene("test.toml", &format!("molecule = \"h2o\"\n{body}")).unwrap()
}

/// Mean and standard error of the mean.
fn mean_se(x: &[f64]) -> (f64, f64) {
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let v = x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (v / n).sqrt())
}

const THERMAL: &str = "[ensemble]\nmethod = \"thermal\"\ntemperature = 300\nregion = { energy_cap = 0.1 }\n";

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 6 s unoptimised on a loaded 2-core machine"]
fn thermal_water_through_the_runner_has_equipartition_at_t0() {
    // Water has 3N − 3 = 6 quadratic momentum degrees of freedom (3 vibrational, 3 rotational):
    // ⟨T⟩ = 3 kT whatever the metric, if (J, p) is Gaussian with covariance kT·M(q).
    let s = scene(&format!(
        "{THERMAL}trajectories = 2000\nseed = 3\n[statistics]\nmeans = [\"T\"]\n[run]\nend = 1\noutput_interval = 1\n"
    ));
    let r = run_ensemble(&s, &options("equipartition", 2)).unwrap();
    assert_eq!(r.outcome.completed, 2000);
    let (t, se) = r.mean("T", 0).unwrap();
    let expected = 3.0 * BOLTZMANN * 300.0;
    assert!((t - expected).abs() < 4.0 * se, "⟨T⟩ = {t} ± {se} hartree, expected {expected}");
    // The tolerance is tight enough to see a wrong temperature (10 % off is > 4σ here).
    assert!(0.1 * expected > 4.0 * se, "σ = {se} too large to test anything");
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 6 s unoptimised on a loaded 2-core machine"]
fn thermal_water_is_stationary_under_propagation() {
    // Liouville: a canonical ensemble propagated exactly keeps its averages. Compare t = 0 with
    // t = end through the per-trajectory differences (kept trajectories), whose standard error
    // accounts for the correlation between the two times.
    let end = 300.0;
    let s = scene(&format!(
        "{THERMAL}trajectories = 400\nseed = 9\nkeep_trajectories = 1\n[statistics]\nmeans = [\"T\", \"r1\", \"alpha\"]\n\
         [integrator]\nmethod = \"dop853\"\nrtol = 1e-9\natol = 1e-9\n[run]\nend = {end}\noutput_interval = {end}\n"
    ));
    let o = options("stationary", 2);
    let r = run_ensemble(&s, &o).unwrap();
    assert_eq!(r.outcome.completed, 400);
    let mut diffs = [Vec::new(), Vec::new(), Vec::new()];
    let mut starts = [Vec::new(), Vec::new(), Vec::new()];
    for i in 0..400 {
        let (h, rows) = csv(&o.out_dir.join(format!("trajectories/{i}/trajectory.csv")));
        assert_eq!(rows.len(), 2);
        let (cr1, cr2, ca, ch) = (column(&h, "q_r1"), column(&h, "q_r2"), column(&h, "q_alpha"), column(&h, "H"));
        // T = H − U(q), U from the molecule (trajectory.csv carries H, not T).
        let kinetic = |row: &[f64]| row[ch] - H2o.potential(&SVector::from([row[cr1], row[cr2], row[ca]]));
        let values = |row: &[f64]| [kinetic(row), row[cr1], row[ca]];
        let (a, b) = (values(&rows[0]), values(&rows[1]));
        for k in 0..3 {
            diffs[k].push(b[k] - a[k]);
            starts[k].push(a[k]);
        }
    }
    for (k, name) in ["T", "r1", "alpha"].iter().enumerate() {
        // The files agree with the runner's statistics at t = 0 (so the differences are the
        // runner's ensemble).
        let (m0, _) = r.mean(name, 0).unwrap();
        assert!(
            (mean_se(&starts[k]).0 - m0).abs() <= 1e-12 * m0.abs().max(1e-3),
            "{name}: files and statistics differ"
        );
        let (d, se) = mean_se(&diffs[k]);
        assert!(d.abs() < 4.0 * se, "{name} drifts by {d} ± {se} over {end} a.u.");
        // The drift test can see something: the spread of the change is not zero.
        assert!(se > 0.0);
    }
}

#[test]
fn microcanonical_water_through_the_runner_starts_every_trajectory_on_the_shell() {
    let e = H2o.potential(&H2o.reference_geometry().unwrap()) + 0.01;
    let s = scene(&format!(
        "[ensemble]\nmethod = \"microcanonical\"\nenergy = {e:?}\ntrajectories = 64\nseed = 4\nregion = {{ energy_cap = 0.05 }}\n\
         keep_trajectories = 1\n[statistics]\nmeans = [\"H\"]\n[run]\nend = 10\noutput_interval = 10\n"
    ));
    let o = options("microcanonical", 2);
    let r = run_ensemble(&s, &o).unwrap();
    assert_eq!(r.outcome.completed, 64);
    for i in 0..64 {
        let (h, rows) = csv(&o.out_dir.join(format!("trajectories/{i}/trajectory.csv")));
        let h0 = rows[0][column(&h, "H")];
        assert!((h0 - e).abs() <= 1e-12 * e.abs(), "trajectory {i}: H(0) = {h0}, E = {e}");
    }
    let (h, se) = r.mean("H", 0).unwrap();
    assert!((h - e).abs() <= 1e-12 * e.abs() && se < 1e-12 * e.abs(), "⟨H⟩ = {h} ± {se}");
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 14 s unoptimised on a loaded 2-core machine"]
fn thermal_ensembles_on_one_and_two_threads_are_byte_identical() {
    // 150 trajectories: two full blocks and a partial one.
    let s = scene(&format!(
        "{THERMAL}trajectories = 150\nseed = 21\n[statistics]\nmeans = [\"r1\", \"alpha\", \"T\", \"H\", \"Lz\"]\n\
         correlations = [\"r1\"]\n[run]\nend = 200\noutput_interval = 20\n"
    ));
    let a = run_ensemble(&s, &options("threads1", 1)).unwrap();
    let b = run_ensemble(&s, &options("threads2", 2)).unwrap();
    assert_eq!((a.threads, b.threads), (1, 2));
    for file in ["ensemble.csv", "correlations.csv"] {
        let x = std::fs::read(a.files.iter().find(|f| f.ends_with(file)).unwrap()).unwrap();
        let y = std::fs::read(b.files.iter().find(|f| f.ends_with(file)).unwrap()).unwrap();
        assert!(x == y, "{file} differs between 1 and 2 threads");
    }
    // Another seed changes the statistics (the comparison can fail).
    let c = scene(&format!(
        "{THERMAL}trajectories = 150\nseed = 22\n[statistics]\nmeans = [\"r1\", \"alpha\", \"T\", \"H\", \"Lz\"]\n\
         correlations = [\"r1\"]\n[run]\nend = 200\noutput_interval = 20\n"
    ));
    let c = run_ensemble(&c, &options("seed22", 2)).unwrap();
    assert_ne!(a.outcome.statistics, c.outcome.statistics);
}

/// Thermal CO2 (linear at equilibrium) through the runner, with lanes and without: no
/// trajectory fails (nearly linear starts whose first trial step reaches the singular
/// geometry continue in the Cartesian chart from their own start), the two runs agree to
/// round-off, and α stays in its declared range [0, π] at every output time, also for
/// trajectories that come back from the Cartesian chart (2 histogram bins split at π).
#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 30 s unoptimised on a loaded 2-core machine"]
fn thermal_co2_starts_every_trajectory_and_keeps_alpha_in_range() {
    let n = 4000;
    let pi = std::f64::consts::PI;
    let text = format!(
        "molecule = \"co2\"\n[ensemble]\ntrajectories = {n}\nseed = 3\nmethod = \"thermal\"\ntemperature = 300\n\
         region = {{ energy_cap = 0.1 }}\n[statistics]\nmeans = [\"alpha\", \"r1\", \"H\"]\n\
         histograms = [{{ quantity = \"alpha\", bins = 2, range = [{}, {}], times = [0, 100, 200] }}]\n\
         [integrator]\nmethod = \"dop853\"\nrtol = 1e-9\natol = 1e-9\n[run]\nend = 200\noutput_interval = 100\n",
        pi - 0.5,
        pi + 0.5
    );
    let s = parse_scene("co2.toml", &text).unwrap();
    let lanes = options("co2-lanes", 2);
    let mut scalar = options("co2-scalar", 2);
    scalar.lanes = false;
    let a = run_ensemble(&s, &lanes).unwrap();
    let b = run_ensemble(&s, &scalar).unwrap();
    for (r, what) in [(&a, "lanes"), (&b, "no lanes")] {
        assert_eq!(
            r.outcome.completed,
            n,
            "{what}: {} failed: {:?}",
            r.outcome.failed_count(),
            r.outcome.first_failures
        );
    }
    for k in 0..3 {
        for q in ["alpha", "r1", "H"] {
            let (x, y) = (a.mean(q, k).unwrap().0, b.mean(q, k).unwrap().0);
            assert!((x - y).abs() <= 1e-12 * x.abs(), "⟨{q}⟩ at output {k}: {x} with lanes, {y} without");
        }
    }
    let (h, rows) = csv(&lanes.out_dir.join("histograms.csv"));
    let (low, count) = (column(&h, "bin_low"), column(&h, "count"));
    let above: Vec<&Vec<f64>> = rows.iter().filter(|r| r[low] > pi - 1e-9).collect();
    assert_eq!(above.len(), 3);
    assert!(above.iter().all(|r| r[count] == 0.0), "α beyond π: {above:?}");
    let outside = &common::ensemble::summary(&lanes.out_dir)["histograms_outside_range"];
    let above = outside.as_array().unwrap().iter().flat_map(|h| h["above"].as_array().unwrap().clone());
    assert!(above.into_iter().all(|c| c.as_u64() == Some(0)), "{outside}");
}
