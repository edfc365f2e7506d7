//! What the classical IR spectrum costs against the ensemble's integration (docs/src/history/benchmarks.md,
//! "Dipoles and spectra").
//!
//! 1. The same thermal water ensemble as `scenes/h2o_ir.toml` (300 K, 2 ps, output every 20
//!    a.u.), on one worker thread, with and without `correlations = ["mu_x", "mu_y", "mu_z"]`
//!    (both keep the mean of H): the difference is the dipole at every output time, three tapered
//!    FFT autocorrelations per trajectory, and the spectrum and its files once at the end.
//!    Interleaved rounds; CPU time of the process (user + system, `/proc/self/stat`).
//! 2. The spectrum alone: `Spectrum::from_correlation` of a correlation of the same length and
//!    the three cross sections, thread CPU time, many repetitions.
//!
//! ```sh
//! cargo run --release --features examples --example spectrum_cost            # or: -- TRAJECTORIES ROUNDS
//! ```

mod common;
use common::thread_cpu;

use std::hint::black_box;

use rovib::ensemble::{EnsembleOptions, run_ensemble};
use rovib::runtime::ensemble::CorrelationWorkspace;
use rovib::runtime::spectrum::{QuantumCorrection, Spectrum};
use rovib::scene::parse_scene;

/// CPU time of the whole process (all threads), s: utime + stime of `/proc/self/stat`.
fn process_cpu() -> f64 {
    let text = std::fs::read_to_string("/proc/self/stat").expect("Linux /proc/self/stat");
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = &text[text.rfind(')').expect("a command name") + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = fields[11].parse::<f64>().expect("utime") + fields[12].parse::<f64>().expect("stime");
    ticks / 100.0 // USER_HZ
}

fn scene(trajectories: usize, dipole: bool) -> String {
    let correlations = if dipole { "correlations = [\"mu_x\", \"mu_y\", \"mu_z\"]\n" } else { "" };
    format!(
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = {trajectories}\nseed = 14\nmethod = \"thermal\"\n\
         temperature = 300.0\nregion = {{ energy_cap = 0.1 }}\n[statistics]\nmeans = [\"H\"]\n{correlations}\
         [integrator]\nmethod = \"dop853\"\nrtol = 1e-9\natol = 1e-9\n[run]\nend = 82680.0\noutput_interval = 20.0\n"
    )
}

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).map(|a| a.parse().expect("a number")).collect();
    let trajectories = args.first().copied().unwrap_or(100);
    let rounds = args.get(1).copied().unwrap_or(3);
    let dir = std::env::temp_dir().join(format!("rovib-spectrum-cost-{}", std::process::id()));
    let mut best = [f64::INFINITY; 2];
    let mut all = [Vec::new(), Vec::new()];
    for round in 0..rounds {
        for (i, dipole) in [false, true].into_iter().enumerate() {
            let text = scene(trajectories, dipole);
            let scene = parse_scene("spectrum_cost.toml", &text).expect("a valid scene");
            let out = dir.join(format!("{round}-{dipole}"));
            let mut options = EnsembleOptions::new(&out);
            options.threads = Some(1);
            options.checkpoint = false;
            let begin = process_cpu();
            let report = run_ensemble(&scene, &options).expect("the ensemble runs");
            let cpu = process_cpu() - begin;
            assert_eq!(report.outcome.completed as usize, trajectories);
            assert_eq!(out.join("spectrum.csv").exists(), dipole);
            best[i] = best[i].min(cpu);
            all[i].push(cpu);
            let _ = std::fs::remove_dir_all(&out);
        }
    }
    println!("thermal water, 300 K, 2 ps, 4135 output times, {trajectories} trajectories, 1 thread, {rounds} rounds");
    println!("  without the dipole: CPU {:.3?} s, best {:.3} s", all[0], best[0]);
    println!("  with the spectrum:  CPU {:.3?} s, best {:.3} s", all[1], best[1]);
    println!(
        "  ratio (best) {:.4}; per trajectory {:.2} ms against {:.2} ms",
        best[1] / best[0],
        1e3 * best[1] / trajectories as f64,
        1e3 * best[0] / trajectories as f64
    );

    // The spectrum alone, from a correlation of the same length.
    let n = 4135;
    let dt = 20.0;
    let x: Vec<f64> = (0..n).map(|k| (0.0075 * k as f64 * dt).cos() + 0.3 * (0.017 * k as f64 * dt).sin()).collect();
    let mut c = vec![0.0; n];
    let mut ws = CorrelationWorkspace::new(n);
    let repeats = 200;
    let begin = thread_cpu();
    for _ in 0..repeats {
        ws.tapered_autocorrelation(black_box(&x), &mut c);
        black_box(&c);
    }
    let per_correlation = (thread_cpu() - begin) / repeats as f64;
    let begin = thread_cpu();
    for _ in 0..repeats {
        let s = Spectrum::from_correlation(black_box(&c), dt, 5000.0, 4);
        for q in QuantumCorrection::ALL {
            black_box(s.cross_section(300.0, q));
        }
    }
    let per_spectrum = (thread_cpu() - begin) / repeats as f64;
    println!(
        "  one tapered autocorrelation (n = {n}): {:.1} µs; the spectrum and three cross sections: {:.1} µs",
        1e6 * per_correlation,
        1e6 * per_spectrum
    );
    let _ = std::fs::remove_dir_all(&dir);
}
