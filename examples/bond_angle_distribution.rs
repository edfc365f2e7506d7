//! The H–O–H bond-angle distribution of a small thermal-like ensemble of rotating, vibrating
//! water molecules: an ensemble run on the production system ([`ReducedSystem`]) with DOP853,
//! and a custom [`Observer`] that records something the `rovib` CLI does not (a histogram of
//! the bond angle α, with its mean and standard deviation).
//!
//! ```sh
//! cargo run --release --features examples --example bond_angle_distribution                  # out/bond_angle_distribution.csv
//! cargo run --release --features examples --example bond_angle_distribution -- angles.csv    # another CSV path
//! ```
//!
//! It prints the histogram as text and writes it as CSV (columns `alpha_low_deg`,
//! `alpha_high_deg`, `count`, `density_per_deg`), and compares the standard deviation with the
//! classical harmonic prediction √(k_B T (F⁻¹)_αα). It fails (exit status 1, with a message)
//! if the energy is not conserved to 1e-7 or the distribution is far from the harmonic one.
//! Runs in about half a second in release mode.
//!
//! # The ensemble
//!
//! Each trajectory starts from a classical Boltzmann distribution at [`TEMPERATURE_K`] in the
//! harmonic approximation, drawn with a small deterministic generator (the same numbers on
//! every run, no dependency):
//!
//! * the geometry q from `exp(−½ δqᵀ F δq / k_B T)`, F the Hessian of the potential at the
//!   equilibrium (by central differences of the generated gradient), i.e. δq ~ N(0, k_B T F⁻¹);
//! * at that q, the momenta b = (J, p) from `exp(−½ bᵀ M⁻¹ b / k_B T)`, the exact kinetic part
//!   of the canonical distribution, with `M = [[I, A], [Aᵀ, a]]` the kinetic metric: b ~ N(0,
//!   k_B T M). (Equivalently the velocities (ω, q̇) = M⁻¹ b are Maxwell–Boltzmann distributed.)
//!
//! "Thermal-like", because the configurational part leaves out the anharmonicity and the
//! Jacobian factor √det M of the exact classical distribution; over the trajectory each
//! molecule then explores its own energy shell.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use rovib::molecules::H2o;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::hamiltonian::{euler_momenta_from_angular_momentum, rotation_matrix};
use rovib::runtime::integrate::{Dop853, Dop853Options, Observer};
use rovib::runtime::nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rovib::runtime::units::AU_TIME_IN_FS;
use rovib::runtime::{Kinematics, KineticMatrices, Molecule, PhaseState};

/// Temperature of the initial distribution.
const TEMPERATURE_K: f64 = 500.0;
/// Boltzmann's constant in hartree per kelvin (CODATA 2018: k_B / E_h = 3.166 811 563 × 10⁻⁶ K⁻¹).
const BOLTZMANN_HARTREE_PER_K: f64 = 3.166_811_563_455_6e-6;
/// Number of trajectories.
const TRAJECTORIES: usize = 50;
/// Length of each trajectory and the interval at which α is sampled, in femtoseconds.
const DURATION_FS: f64 = 1000.0;
const SAMPLE_INTERVAL_FS: f64 = 0.5;
/// Seed of the pseudo-random initial conditions.
const SEED: u64 = 20_240_501;

/// The histogram: `BINS` bins of `BIN_WIDTH_DEG` from `ALPHA_MIN_DEG` (centred on 104.5°, the
/// model's equilibrium, and wide enough for ±5σ at 500 K).
const ALPHA_MIN_DEG: f64 = 75.5;
const BIN_WIDTH_DEG: f64 = 2.0;
const BINS: usize = 29;

/// The largest relative change of H over a trajectory accepted (DOP853 at tolerance 1e-10
/// gives a few 1e-9 over 1 ps).
const MAX_ENERGY_ERROR: f64 = 1e-7;

/// Where the CSV goes unless a path is given on the command line.
const DEFAULT_CSV: &str = "out/bond_angle_distribution.csv";

/// Water has 3 internal coordinates (r1, r2, α); the production system's flat state is
/// `[q (3), p (3), orientation quaternion (4), body-frame J (3)]`: 13 numbers.
const DIM: usize = 2 * 3 + 4 + 3;

/// The custom observer: called by the integrator with `(t, y)` at every output time, it bins
/// the bond angle and accumulates its mean and variance.
///
/// It allocates nothing per call: the bins are a fixed-size array and the last state a
/// fixed-size buffer, all created once before the runs, so `observe` is arithmetic only
/// (the DOP853 step does not allocate either). One observer collects the whole ensemble.
struct BondAngleHistogram {
    /// Index of α in the flat state (q comes first).
    alpha_index: usize,
    counts: [u64; BINS],
    /// Samples below and above the histogram's range (they still count in the mean).
    below: u64,
    above: u64,
    samples: u64,
    /// Σ (α − α_e) and Σ (α − α_e)² in degrees: shifted by the equilibrium angle so that the
    /// variance Σx²/n − (Σx/n)² does not lose digits to cancellation.
    shift_deg: f64,
    sum: f64,
    sum_sq: f64,
    /// The state at the latest output time (after a run: the final state).
    last_state: [f64; DIM],
}

impl Observer for BondAngleHistogram {
    fn observe(&mut self, _t: f64, y: &[f64]) -> ControlFlow<()> {
        let alpha_deg = y[self.alpha_index].to_degrees();
        let x = (alpha_deg - ALPHA_MIN_DEG) / BIN_WIDTH_DEG;
        if x < 0.0 {
            self.below += 1;
        } else if x >= BINS as f64 {
            self.above += 1;
        } else {
            // 0 ≤ x < BINS, so the truncation is a valid index.
            self.counts[x as usize] += 1;
        }
        let d = alpha_deg - self.shift_deg;
        self.samples += 1;
        self.sum += d;
        self.sum_sq += d * d;
        self.last_state.copy_from_slice(y);
        ControlFlow::Continue(())
    }
}

impl BondAngleHistogram {
    fn mean_and_std_deg(&self) -> (f64, f64) {
        let n = self.samples as f64;
        let mean = self.sum / n;
        let variance = (self.sum_sq / n - mean * mean).max(0.0);
        (self.shift_deg + mean, variance.sqrt())
    }
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let csv_path = csv_path_from_args()?;
    let csv = create_csv(&csv_path)?;
    let started = Instant::now();
    let water = H2o;
    let kt = BOLTZMANN_HARTREE_PER_K * TEMPERATURE_K;

    // The equilibrium: h2o.toml's reference geometry is the model's minimum (r_e, r_e, α_e).
    let q_e = water.reference_geometry().expect("h2o.toml gives a reference for every coordinate");
    let alpha_index = water.coordinates().iter().position(|c| c.name == "alpha").expect("h2o has a coordinate alpha");

    // Configurational sampling: δq ~ N(0, k_B T F⁻¹) = L z with L Lᵀ = k_B T F⁻¹, z ~ N(0, 1).
    let f = hessian(&water, &q_e);
    let f_inv = f.try_inverse().expect("the Hessian at a minimum is invertible");
    let q_factor = (f_inv * kt).cholesky().expect("F⁻¹ at a minimum is positive definite").l();
    let harmonic_std_deg = (kt * f_inv[(alpha_index, alpha_index)]).sqrt().to_degrees();

    // The production system (body-frame J and a unit quaternion on the fast right-hand side:
    // no gimbal lock, no workspace, no allocation) and one DOP853 solver whose workspace is
    // allocated once and reused for every trajectory.
    let options = Dop853Options { rtol: 1e-10, atol: 1e-10, ..Dop853Options::default() };
    let mut solver = Dop853::new(DIM, options).map_err(|e| e.to_string())?;
    let t_end = DURATION_FS / AU_TIME_IN_FS; // atomic units of time
    let output_interval = SAMPLE_INTERVAL_FS / AU_TIME_IN_FS;

    let mut histogram = BondAngleHistogram {
        alpha_index,
        counts: [0; BINS],
        below: 0,
        above: 0,
        samples: 0,
        shift_deg: q_e[alpha_index].to_degrees(),
        sum: 0.0,
        sum_sq: 0.0,
        last_state: [0.0; DIM],
    };

    let mut rng = SplitMix64(SEED);
    let mut worst_energy_error = 0.0_f64;
    let mut steps = 0;
    let mut mean_j = 0.0;
    for trajectory in 0..TRAJECTORIES {
        let q = q_e + q_factor * rng.normal_vector::<3>();
        let state = thermal_state(&water, q, kt, &mut rng)?;
        mean_j += state.pe[0] / TRAJECTORIES as f64; // p_φ = |J| in our lab frame
        let mut system = ReducedSystem::new(&water, Reduction::none(), &state);
        let mut y0 = [0.0; DIM];
        system.reduce(&state, &mut y0).map_err(|e| format!("trajectory {trajectory}: initial state: {e}"))?;
        let h0 = system.energy(&y0).map_err(|e| format!("trajectory {trajectory}: initial state: {e}"))?;

        let stats = solver
            .integrate(&mut system, 0.0, &y0, t_end, output_interval, &mut histogram)
            .map_err(|e| format!("trajectory {trajectory}: {}", with_source(&e)))?;
        steps += stats.steps;

        let h_end = system.energy(&histogram.last_state).map_err(|e| format!("trajectory {trajectory}: {e}"))?;
        worst_energy_error = worst_energy_error.max(((h_end - h0) / h0).abs());
    }
    let elapsed = started.elapsed();

    let (mean, std) = histogram.mean_and_std_deg();
    println!(
        "water, {TRAJECTORIES} trajectories of {DURATION_FS} fs from a {TEMPERATURE_K} K ensemble \
         (mean |J| = {mean_j:.1} ħ), α sampled every {SAMPLE_INTERVAL_FS} fs: {} samples",
        histogram.samples
    );
    println!("DOP853 (rtol = atol = 1e-10), production system: {steps} steps in {:.2} s", elapsed.as_secs_f64());
    println!("worst relative energy error |H(t_end) − H(0)| / |H(0)| = {worst_energy_error:.1e}\n");
    print_histogram(&histogram);
    println!(
        "\nmean α = {mean:.3}°, standard deviation {std:.3}° \
         (classical harmonic prediction: {:.3}°, {harmonic_std_deg:.3}°)",
        histogram.shift_deg
    );
    if histogram.below + histogram.above > 0 {
        println!(
            "outside the histogram's range: {} below {ALPHA_MIN_DEG}°, {} above {}°",
            histogram.below,
            histogram.above,
            ALPHA_MIN_DEG + BINS as f64 * BIN_WIDTH_DEG
        );
    }

    // Running the example is a check: the energy must be conserved to the integrator's
    // tolerance, and the distribution must be close to the harmonic one (deterministic seed, so
    // this cannot fail by chance; 50 trajectories give σ to a few per cent).
    if worst_energy_error > MAX_ENERGY_ERROR {
        return Err(format!(
            "the energy changed by {worst_energy_error:e} (relative) in some trajectory, more than {MAX_ENERGY_ERROR:e}"
        ));
    }
    if (mean - histogram.shift_deg).abs() > 0.25 * harmonic_std_deg || (std / harmonic_std_deg - 1.0).abs() > 0.25 {
        return Err("the distribution is far from the harmonic prediction: check the sampling".into());
    }

    write_csv(csv, &histogram).map_err(|e| format!("cannot write {}: {e}", csv_path.display()))?;
    println!("wrote {}", csv_path.display());
    Ok(())
}

/// A state at geometry `q` with momenta from the Boltzmann distribution at `kt` (hartree):
/// `b = (J, p) ~ N(0, k_B T M(q))` with the kinetic metric `M = [[I, A], [Aᵀ, a]]`.
///
/// The lab frame is oriented with Z along the (conserved) lab-frame angular momentum, so
/// `p_φ = |J|` and θ is the angle between J and the body z axis; that keeps θ away from the
/// z-x-z Euler angles' gimbal lock at θ = 0, π unless J comes to lie along the body z axis.
fn thermal_state(water: &H2o, q: SVector<f64, 3>, kt: f64, rng: &mut SplitMix64) -> Result<PhaseState<3>, String> {
    let mut k = KineticMatrices::<3>::default();
    water.kinetic(&q, &mut k);
    let mut metric = SMatrix::<f64, 6, 6>::zeros();
    metric.fixed_view_mut::<3, 3>(0, 0).copy_from(&k.inertia);
    metric.fixed_view_mut::<3, 3>(0, 3).copy_from(&k.coriolis);
    metric.fixed_view_mut::<3, 3>(3, 0).copy_from(&k.coriolis.transpose());
    metric.fixed_view_mut::<3, 3>(3, 3).copy_from(&k.a);
    let l = metric.cholesky().ok_or_else(|| format!("the kinetic metric is not positive definite at q = {q:?}"))?.l();
    let b = l * rng.normal_vector::<6>() * kt.sqrt();
    let j = Vector3::new(b[0], b[1], b[2]);
    let p = SVector::<f64, 3>::new(b[3], b[4], b[5]);

    // Euler angles (z-x-z, R = Rz(φ) Rx(θ) Rz(ψ)) with R J = |J| Ẑ: the third row of R is
    // (sin θ sin ψ, sin θ cos ψ, cos θ), which must equal J / |J|.
    let j_norm = j.norm();
    let euler = Vector3::new(0.0, (j[2] / j_norm).acos(), j[0].atan2(j[1]));
    debug_assert!((rotation_matrix(&euler) * j - Vector3::new(0.0, 0.0, j_norm)).norm() <= 1e-12 * j_norm);
    let pe = euler_momenta_from_angular_momentum(&euler, &j);
    Ok(PhaseState { q, p, euler, pe })
}

/// The Hessian of the potential at `q` by fourth-order central differences of the generated
/// gradient (hartree / (bohr or rad)²), symmetrized.
fn hessian(water: &H2o, q: &SVector<f64, 3>) -> Matrix3<f64> {
    let step = 1e-4;
    let gradient_at = |k: usize, t: f64| {
        let mut x = *q;
        x[k] += t;
        let mut g = SVector::<f64, 3>::zeros();
        water.potential_gradient(&x, &mut g);
        g
    };
    let f = Matrix3::from_fn(|i, k| {
        let g = |t| gradient_at(k, t)[i];
        (g(-2.0 * step) - 8.0 * g(-step) + 8.0 * g(step) - g(2.0 * step)) / (12.0 * step)
    });
    (f + f.transpose()) * 0.5
}

/// Prints the histogram as bars of `#`, scaled to the fullest bin.
fn print_histogram(h: &BondAngleHistogram) {
    let fullest = h.counts.iter().copied().max().unwrap_or(0).max(1);
    println!("   α / deg         fraction");
    for (i, &count) in h.counts.iter().enumerate() {
        let low = ALPHA_MIN_DEG + i as f64 * BIN_WIDTH_DEG;
        let bar = "#".repeat((60 * count).div_ceil(fullest) as usize);
        let fraction = count as f64 / h.samples as f64;
        println!("{low:>6.1}–{:<6.1} {:>6.2} % {bar}", low + BIN_WIDTH_DEG, 100.0 * fraction);
    }
}

/// Creates the CSV file (and its directory), before the computation, so that a bad path fails
/// at once.
fn create_csv(path: &Path) -> Result<BufWriter<File>, String> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        fs::create_dir_all(dir).map_err(|e| format!("cannot create the directory {}: {e}", dir.display()))?;
    }
    let file = File::create(path).map_err(|e| format!("cannot create {}: {e}", path.display()))?;
    Ok(BufWriter::new(file))
}

/// Writes the histogram as CSV; the density is normalised over all samples (it integrates to 1
/// minus the fraction outside the range).
fn write_csv(mut out: impl Write, h: &BondAngleHistogram) -> std::io::Result<()> {
    writeln!(out, "alpha_low_deg,alpha_high_deg,count,density_per_deg")?;
    for (i, &count) in h.counts.iter().enumerate() {
        let low = ALPHA_MIN_DEG + i as f64 * BIN_WIDTH_DEG;
        let density = count as f64 / (h.samples as f64 * BIN_WIDTH_DEG);
        writeln!(out, "{low},{},{count},{density}", low + BIN_WIDTH_DEG)?;
    }
    out.flush()
}

/// The CSV path: the only command-line argument, or [`DEFAULT_CSV`].
fn csv_path_from_args() -> Result<PathBuf, String> {
    let mut args = std::env::args_os().skip(1);
    match (args.next(), args.next()) {
        (None, _) => Ok(PathBuf::from(DEFAULT_CSV)),
        (Some(path), None) => Ok(PathBuf::from(path)),
        (Some(_), Some(_)) => {
            Err("expected at most one argument, the CSV path (default out/bond_angle_distribution.csv)".into())
        }
    }
}

/// An error with its source, if any: a solver error does not repeat the system's own error
/// (e.g. which block of the metric became singular), it is the source.
fn with_source(e: &dyn std::error::Error) -> String {
    match e.source() {
        Some(source) => format!("{e}: {source}"),
        None => e.to_string(),
    }
}

/// A tiny deterministic pseudo-random generator (SplitMix64, Steele, Lea & Flood 2014): plenty
/// for drawing initial conditions, and no dependency.
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in (0, 1]: the top 53 bits, shifted away from 0 so that its logarithm is finite.
    fn uniform(&mut self) -> f64 {
        ((self.next_u64() >> 11) + 1) as f64 / (1u64 << 53) as f64
    }

    /// A standard normal number (Box–Muller).
    fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// A vector of independent standard normal numbers.
    fn normal_vector<const D: usize>(&mut self) -> SVector<f64, D> {
        SVector::from_fn(|_, _| self.normal())
    }
}
