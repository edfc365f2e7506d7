//! Ensembles run in memory (`EnsembleOptions::in_memory`) and the states an ensemble draws
//! (`ensemble::draw::draw_states`), checked against the files of the same scene and seed.

use std::path::{Path, PathBuf};

use rovib::ensemble::draw::draw_states;
use rovib::ensemble::{EnsembleOptions, run_ensemble};
use rovib::scene::parse_scene;

use crate::common::ensemble::{csv, options};

fn temp_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-in-memory-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Thermal water with means, r1's correlation and the three dipole components (a spectrum).
const SCENE: &str = r#"
molecule = "h2o"
[ensemble]
trajectories = 12
seed = 3
method = "thermal"
temperature = 300.0
region = { energy_cap = 0.1 }
[statistics]
means = ["r1", "H"]
correlations = ["r1", "mu_x", "mu_y", "mu_z"]
[integrator]
method = "dop853"
rtol = 1e-8
atol = 1e-8
[run]
end = 400.0
output_interval = 10.0
"#;

/// The rows of a CSV file skipping `#` lines, as its header and columns.
fn columns(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let kept: String = text.lines().filter(|l| !l.starts_with('#')).map(|l| format!("{l}\n")).collect();
    let plain = path.with_extension("plain.csv");
    std::fs::write(&plain, kept).unwrap();
    let (header, rows) = csv(&plain);
    let columns = (0..header.len()).map(|j| rows.iter().map(|r| r[j]).collect()).collect();
    (header, columns)
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn an_ensemble_in_memory_gives_the_numbers_of_the_files_bit_for_bit_and_writes_nothing() {
    let scene = parse_scene("memory.toml", SCENE).unwrap();
    let dir = temp_dir("files");
    let written = run_ensemble(&scene, &options(dir.clone(), 2)).unwrap();
    assert!(written.tables.is_none());
    let mut memory_options = EnsembleOptions::in_memory();
    memory_options.threads = Some(1);
    let memory = run_ensemble(&scene, &memory_options).unwrap();
    assert!(memory.files.is_empty());
    assert_eq!(memory.outcome.completed, 12);
    let tables = memory.tables.as_ref().unwrap();

    // Means and standard errors: ensemble.csv's.
    let (header, cols) = columns(&dir.join("ensemble.csv"));
    for q in ["r1", "H"] {
        let unit = memory.units[memory.quantities.iter().position(|n| n == q).unwrap()];
        let m: Vec<f64> = (0..memory.times.len()).map(|k| memory.mean(q, k).unwrap().0).collect();
        let j = header.iter().position(|h| *h == format!("{q}_mean_{unit}")).unwrap();
        assert!(same_bits(&m, &cols[j]), "{q}");
    }

    // Correlations and spectrum: every column of correlations.csv and spectrum.csv.
    for (file, table) in
        [("correlations.csv", &tables.correlations), ("spectrum.csv", tables.spectrum.as_ref().unwrap())]
    {
        let (header, cols) = columns(&dir.join(file));
        assert_eq!(header, table.names, "{file}");
        assert!(cols[0].len() > 10, "{file}");
        for (j, name) in header.iter().enumerate() {
            assert!(same_bits(&cols[j], table.column(name).unwrap()), "{file}: {name}");
        }
    }
    assert!(tables.correlations.column("mu_x_C_(e*bohr)^2").is_some(), "{:?}", tables.correlations.names);
    assert!(tables.spectrum.as_ref().unwrap().column("sigma_harmonic_cm2").is_some());
}

#[test]
fn an_ensemble_in_memory_refuses_what_needs_a_folder() {
    let kept = SCENE.replace("seed = 3", "seed = 3\nkeep_trajectories = 2");
    let scene = parse_scene("memory.toml", &kept).unwrap();
    let e = run_ensemble(&scene, &EnsembleOptions::in_memory()).unwrap_err().to_string();
    assert!(e.contains("keep_trajectories") && e.contains("output folder"), "{e}");
    let mut resume = EnsembleOptions::in_memory();
    resume.resume = true;
    let scene = parse_scene("memory.toml", SCENE).unwrap();
    let e = run_ensemble(&scene, &resume).unwrap_err().to_string();
    assert!(e.contains("no checkpoint"), "{e}");
}

#[test]
fn drawn_states_are_the_ensembles_initial_states() {
    // A thermal ensemble keeping every trajectory: row 0 of each kept trajectory.csv is the
    // state drawn for it.
    let kept = SCENE.replace("seed = 3", "seed = 3\nkeep_trajectories = 1");
    let dir = temp_dir("kept");
    let scene = parse_scene("memory.toml", &kept).unwrap();
    run_ensemble(&scene, &options(dir.clone(), 1)).unwrap();
    let drawn = draw_states(&scene, 12).unwrap();
    assert_eq!((drawn.molecule.as_str(), drawn.coordinates, drawn.h.len()), ("h2o", 3, 12));
    for i in 0..12 {
        let (header, rows) = csv(&dir.join("trajectories").join(i.to_string()).join("trajectory.csv"));
        let row = &rows[0];
        let at = |name: &str| row[header.iter().position(|h| h == name).unwrap()];
        for (k, c) in ["r1", "r2", "alpha"].iter().enumerate() {
            assert!((at(&format!("q_{c}")) - drawn.q[3 * i + k]).abs() < 1e-12, "trajectory {i} q_{c}");
            assert!((at(&format!("p_{c}")) - drawn.p[3 * i + k]).abs() < 1e-12, "trajectory {i} p_{c}");
        }
        for (k, c) in ["Jx", "Jy", "Jz"].iter().enumerate() {
            assert!((at(c) - drawn.j[3 * i + k]).abs() < 1e-9, "trajectory {i} {c}");
        }
        assert!((at("H") - drawn.h[i]).abs() < 1e-12, "trajectory {i} H");
    }

    // A states file: its rows, as given.
    let states = dir.join("states.csv");
    std::fs::write(&states, "q_r1,q_r2,q_alpha,p_r1\n1.8,1.9,1.8,0.1\n1.85,1.75,1.9,-0.2\n").unwrap();
    let text = format!(
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = 2\nmethod = \"file\"\nfile = {:?}\n[run]\nend = 10.0\noutput_interval = 1.0\n",
        states.display().to_string()
    );
    let scene = parse_scene("file.toml", &text).unwrap();
    let drawn = draw_states(&scene, 2).unwrap();
    assert_eq!(drawn.q, vec![1.8, 1.9, 1.8, 1.85, 1.75, 1.9]);
    assert_eq!(drawn.p, vec![0.1, 0.0, 0.0, -0.2, 0.0, 0.0]);
    assert!(draw_states(&scene, 3).unwrap_err().to_string().contains("state 2"));
    assert!(draw_states(&scene, u64::MAX).is_err());
}
