//! `rovib bench` reports fixed step sizes in the scene's time unit, with the value in
//! atomic units beside it. Checked against CODATA's atomic unit of time, not against our own
//! conversion: 1 a.u. = ħ/E_h = 2.4188843265857e-17 s.

use crate::common;

use std::path::{Path, PathBuf};

/// Atomic units of time in one femtosecond (CODATA 2018: 1e-15 s / 2.4188843265857e-17 s).
const AU_PER_FS: f64 = 1e-15 / 2.4188843265857e-17;

/// A short water scene in `unit`, 4 fs long with outputs every 2 fs (written in that unit).
fn scene(dir: &Path, unit: &str, fs: f64) -> PathBuf {
    let text = format!(
        "molecule = \"h2o\"\n[units]\nlength = \"angstrom\"\nangle = \"deg\"\ntime = \"{unit}\"\n\
         [initial]\nq = {{ r1 = 1.0078, r2 = 0.95785, alpha = 104.5 }}\nj = [3.0, 8.0, 2.0]\n\
         [run]\nend = {:?}\noutput_interval = {:?}\n",
        4.0 / fs,
        2.0 / fs
    );
    let path = dir.join(format!("{unit}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The fixed-step rows of bench.md: (method, step in the scene's unit, the unit, step in a.u.).
fn fixed_steps(markdown: &str) -> Vec<(String, f64, String, f64)> {
    let table = markdown.split("## Which method").next().unwrap();
    table
        .lines()
        .filter_map(|line| {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            let step = cells.get(2)?.strip_prefix("step = ")?;
            // "1.2345e-1 fs (5.1034 a.u.)"
            let (value, rest) = step.split_once(' ')?;
            let (unit, au) = rest.split_once(" (")?;
            let au = au.strip_suffix(" a.u.)")?;
            Some((cells[1].to_owned(), value.parse().ok()?, unit.to_owned(), au.parse().ok()?))
        })
        .collect()
}

#[test]
fn fixed_steps_are_reported_in_the_scenes_time_unit() {
    let dir = common::cli::temp_dir("bench-units", "units");
    for (unit, fs) in [("fs", 1.0), ("ps", 1000.0)] {
        let out = dir.join(unit);
        let report = rovib::bench::bench(&scene(&dir, unit, fs), Some(&out), true).expect("bench runs");
        let markdown = std::fs::read_to_string(out.join("bench.md")).unwrap();
        assert!(markdown.contains(&format!("End time {} {unit}", 4.0 / fs)), "{markdown}");
        let rows = fixed_steps(&markdown);
        let fixed: Vec<_> = report.trials.iter().filter(|t| t.method != "dop853").collect();
        assert!(!fixed.is_empty());
        assert_eq!(rows.len(), fixed.len(), "one row per fixed-step run:\n{markdown}");
        for ((method, value, row_unit, au), trial) in rows.iter().zip(&fixed) {
            assert_eq!((method.as_str(), row_unit.as_str()), (trial.method, unit), "{markdown}");
            // Printed with 5 significant digits (scene unit) and 4 decimals (a.u.).
            let expected = trial.parameter / (AU_PER_FS * fs);
            assert!((value - expected).abs() <= 5e-5 * expected, "{method}: {value} {unit}, expected {expected}");
            assert!((au - trial.parameter).abs() <= 5e-5, "{method}: {au} a.u., run with {}", trial.parameter);
            assert!((value * AU_PER_FS * fs - au).abs() <= 1e-4 * au, "{method}: {value} {unit} is not {au} a.u.");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
