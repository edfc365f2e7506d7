//! The classical IR spectrum of an ensemble (`spectrum.csv`): at low temperature the bands sit
//! at the harmonic wavenumbers of `rovib freq` (an independent GF calculation, itself checked
//! against a Cartesian Hessian in tests/freq.rs), within half the stated resolution 1/(cT).

mod common;

use common::ensemble::{column, options};
use rovib::cli::freq::frequencies;
use rovib::ensemble::run_ensemble;
use rovib::scene::parse_scene;

const SCENE: &str = r#"molecule = "h2o"
[ensemble]
trajectories = 8
seed = 7
method = "thermal"
temperature = 10.0
region = { energy_cap = 0.01 }
[statistics]
means = ["H"]
correlations = ["mu_x", "mu_y", "mu_z"]
[integrator]
method = "dop853"
rtol = 1e-9
atol = 1e-9
[run]
end = 100000.0
output_interval = 20.0
"#;

#[test]
fn low_temperature_bands_sit_at_the_harmonic_wavenumbers() {
    let dir = std::env::temp_dir().join(format!("rovib-spectrum-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let scene = parse_scene("ir.toml", SCENE).unwrap();
    let report = run_ensemble(&scene, &options(dir.clone(), 2)).unwrap();
    assert_eq!(report.outcome.completed, 8);
    let text = std::fs::read_to_string(dir.join("spectrum.csv")).unwrap();
    let mut lines = text.lines();
    let comment = lines.next().unwrap();
    let resolution: f64 = comment.split_whitespace().nth(3).unwrap().parse().unwrap();
    let header: Vec<String> = lines.next().unwrap().split(',').map(str::to_owned).collect();
    let rows: Vec<Vec<f64>> = lines.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    let (nu, sigma) = (column(&header, "wavenumber_cm-1"), column(&header, "sigma_harmonic_cm2"));
    // T = 1e5 a.u. = 2.42 ps: 1/(cT) = 13.8 cm-1.
    assert!((resolution - 13.79).abs() < 0.05, "resolution {resolution}");
    let harmonic = frequencies("h2o").unwrap().wavenumbers;
    for &w in &harmonic {
        // The band's centroid within ±50 cm-1 (the bands are 111 cm-1 apart or more; the
        // rotational contour at 10 K is ±20 cm-1 wide).
        let band: Vec<&Vec<f64>> = rows.iter().filter(|r| (r[nu] - w).abs() < 50.0).collect();
        let weight: f64 = band.iter().map(|r| r[sigma]).sum();
        let centroid = band.iter().map(|r| r[nu] * r[sigma]).sum::<f64>() / weight;
        assert!(weight > 0.0);
        assert!(
            (centroid - w).abs() < resolution / 2.0,
            "band at {centroid:.2} cm-1, harmonic {w:.2} cm-1 (resolution {resolution:.2})"
        );
        let wide: f64 = rows.iter().filter(|r| (r[nu] - w).abs() < 150.0).map(|r| r[sigma]).sum();
        println!(
            "band {w:.1} cm-1: centroid {centroid:.2} cm-1, {:.2} of the absorption within ±150 cm-1",
            weight / wide
        );
    }
}
