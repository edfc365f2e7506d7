//! A plain Cartesian code against rovib, at equal accuracy, on the same thermal states.
//!
//! The Cartesian baseline integrates Newton's equations of the atoms in the lab frame that moves
//! with the centre of mass (`dx/dt = v`, `dv/dt = −∂U/∂x / m`: 6·NA components) with the same
//! DOP853 and the potential's Cartesian gradient `∂U/∂x` that the generator emits for molecules
//! declared by kind. No internal coordinate, no orientation, no kinetic matrix: what a user
//! without rovib would write. rovib integrates the same states in internal coordinates and a
//! quaternion (`2N + 7` components), one trajectory at a time and on SIMD lanes, and in its own
//! Cartesian chart on SIMD lanes (the Cartesian code's equations, `CartesianLanes`, with the
//! generated lane form of `∂U/∂x`).
//!
//! For every contender and tolerance (rtol = atol) it measures:
//! States: the canonical distribution at 300 K, or normal-mode sampling (kT per mode on average)
//! where rejection sampling accepts too little (printed). Molecules: water, hydrogen peroxide and
//! ammonia, the shipped non-linear molecules declared by kind (the Cartesian code needs the
//! generated U(x), which molecules given by explicit positions, such as ethane, do not have).
//!
//! - the **error**: after `T_END`, the largest distance (bohr) of any atom from where the
//!   reference puts it, lab frame; the median over the states (the reference: the Cartesian code
//!   at rtol = atol = 1e-13, itself checked against rovib's internal chart at 1e-13, printed);
//! - the **cost**: thread CPU time per trajectory, the contenders interleaved round by round in
//!   one process, median over the rounds; trajectories per CPU-second is its inverse.
//!
//! Then, per contender, the cost at equal error (log-log interpolation between the tolerances
//! that bracket the target errors) and its ratio to the Cartesian code.
//!
//! ```sh
//! cargo bench --bench cartesian_baseline                 # water, h2o2, nh3; 5 rounds
//! cargo bench --bench cartesian_baseline -- h2o 9 512     # molecule, rounds, states
//! ```
//!
//! Built with cargo's `bench` profile (release: opt-level 3, no `-C target-cpu`) unless RUSTFLAGS
//! say otherwise; the program prints the vector features of the build. Single thread, memory a
//! few MB; at the defaults a few minutes per molecule.

use std::hint::black_box;
use std::ops::ControlFlow;

use nix::time::{ClockId, clock_gettime};
use rovib::molecules::{H2o, H2o2, Nh3};
use rovib::runtime::Molecule;
use rovib::runtime::cartesian_lanes::CartesianLanes;
use rovib::runtime::cartesian_system::CartesianSystem;
use rovib::runtime::frames::{CentreOfMass, to_lab_body};
use rovib::runtime::hamiltonian::BodyState;
use rovib::runtime::hamiltonian::fast::{ReducedSystem, Reduction};
use rovib::runtime::hamiltonian::lanes::ProductionLanes;
use rovib::runtime::integrate::{Dop853, Dop853Lanes, Dop853Options, LaneFailure, LaneFeeder, Stats};
use rovib::runtime::lanes::{F64x2, F64x4, Real};
use rovib::runtime::nalgebra::SMatrix;
use rovib::runtime::sample::{ModeEnergies, Region, RotationSampling, Spec, sampler};

fn cpu() -> f64 {
    let t = clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID).expect("thread CPU clock");
    t.tv_sec() as f64 + t.tv_nsec() as f64 * 1e-9
}

/// a.u. of time (2.4 ps), with outputs every 100 a.u. as the ensemble benchmark has them.
const T_END: f64 = 1e4;
const INTERVAL: f64 = 100.0;
const TOLERANCES: [f64; 7] = [1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12];
const REFERENCE_TOLERANCE: f64 = 1e-13;
/// Errors (bohr) at which the contenders are compared.
const TARGETS: [f64; 3] = [1e-6, 1e-8, 1e-10];

fn options(tol: f64) -> Dop853Options {
    Dop853Options { rtol: tol, atol: tol, ..Default::default() }
}

/// The states of one molecule in the three layouts, and the reference final positions.
struct Case<'m, M, const N: usize, const NA: usize> {
    molecule: &'m M,
    body: Vec<BodyState<N>>,
    /// Reduced layout (q, p, quaternion, J) of each state.
    reduced: Vec<Vec<f64>>,
    /// Cartesian layout (x relative to the centre of mass, v) of each state.
    cartesian: Vec<Vec<f64>>,
}

impl<'m, M, const N: usize, const NA: usize> Case<'m, M, N, NA>
where
    M: Molecule<N, NA> + Sync,
{
    /// `count` states drawn from `spec` with seed 1.
    fn new(molecule: &'m M, spec: &Spec<N>, count: usize) -> Self {
        let sampler = sampler(molecule, spec, 1).expect("a sampler");
        let body: Vec<BodyState<N>> = (0..count as u64).map(|i| sampler.draw(i).expect("a state")).collect();
        let system = ReducedSystem::from_body(molecule, Reduction::none(), &body[0]);
        let reduced = body
            .iter()
            .map(|b| {
                let mut y = vec![0.0; 2 * N + 7];
                system.reduce_body(b, &mut y).expect("a regular state");
                y
            })
            .collect();
        let cartesian = body
            .iter()
            .map(|b| {
                let lab = to_lab_body(molecule, b, &CentreOfMass::default()).expect("a lab state");
                let mut y = vec![0.0; 6 * NA];
                CartesianSystem::<M, N, NA>::flat(&lab, &mut y);
                y
            })
            .collect();
        Self { molecule, body, reduced, cartesian }
    }

    /// Final lab positions of every state by the Cartesian code at `tol`, and CPU s per trajectory.
    fn cartesian(&self, tol: f64) -> (Vec<SMatrix<f64, 3, NA>>, f64) {
        let mut system = CartesianSystem::new(self.molecule).expect("a molecule declared by kind");
        let mut solver = Dop853::new(6 * NA, options(tol)).expect("valid options");
        let mut finals = Vec::with_capacity(self.cartesian.len());
        let t0 = cpu();
        for y0 in &self.cartesian {
            let mut last = vec![0.0; 6 * NA];
            let mut observer = |_t: f64, y: &[f64]| {
                last.copy_from_slice(y);
                ControlFlow::Continue(())
            };
            solver.integrate(&mut system, 0.0, y0, T_END, INTERVAL, &mut observer).expect("a Cartesian run");
            finals.push(CartesianSystem::<M, N, NA>::positions(&last));
        }
        let cost = (cpu() - t0) / self.cartesian.len() as f64;
        (finals, cost)
    }

    /// rovib's internal chart, one trajectory at a time.
    fn internal(&self, tol: f64) -> (Vec<SMatrix<f64, 3, NA>>, f64) {
        let mut system = ReducedSystem::from_body(self.molecule, Reduction::none(), &self.body[0]);
        let mut solver = Dop853::new(2 * N + 7, options(tol)).expect("valid options");
        let mut last_states = Vec::with_capacity(self.reduced.len());
        let t0 = cpu();
        for y0 in &self.reduced {
            let mut last = vec![0.0; 2 * N + 7];
            let mut observer = |_t: f64, y: &[f64]| {
                last.copy_from_slice(y);
                ControlFlow::Continue(())
            };
            solver.integrate(&mut system, 0.0, y0, T_END, INTERVAL, &mut observer).expect("an internal run");
            last_states.push(last);
        }
        let cost = (cpu() - t0) / self.reduced.len() as f64;
        (self.positions(&system, &last_states), cost)
    }

    /// rovib's internal chart on `T::LANES` SIMD lanes (what `rovib ensemble` runs).
    fn lanes<T: Real>(&self, tol: f64) -> (Vec<SMatrix<f64, 3, NA>>, f64) {
        let mut solver = Dop853Lanes::<T>::new(2 * N + 7, options(tol)).expect("valid options");
        let mut feed =
            Feed { starts: &self.reduced, next: 0, held: [0; 8], last: vec![Vec::new(); self.reduced.len()] };
        let t0 = cpu();
        solver
            .integrate(&mut ProductionLanes::new(self.molecule, 1e-12), 0.0, T_END, INTERVAL, &mut feed)
            .expect("a run");
        let cost = (cpu() - t0) / self.reduced.len() as f64;
        let system = ReducedSystem::from_body(self.molecule, Reduction::none(), &self.body[0]);
        (self.positions(&system, &feed.last), cost)
    }

    /// rovib's Cartesian chart on `T::LANES` SIMD lanes (the same equations as the Cartesian
    /// code, with the generated lane form of `∂U/∂x`).
    fn cartesian_lanes<T: Real>(&self, tol: f64) -> (Vec<SMatrix<f64, 3, NA>>, f64) {
        let mut solver = Dop853Lanes::<T>::new(6 * NA, options(tol)).expect("valid options");
        let mut system = CartesianLanes::new(self.molecule).expect("a lane form of the Cartesian gradient");
        let mut feed =
            Feed { starts: &self.cartesian, next: 0, held: [0; 8], last: vec![Vec::new(); self.cartesian.len()] };
        let t0 = cpu();
        solver.integrate(&mut system, 0.0, T_END, INTERVAL, &mut feed).expect("a run");
        let cost = (cpu() - t0) / self.cartesian.len() as f64;
        (feed.last.iter().map(|y| CartesianSystem::<M, N, NA>::positions(y)).collect(), cost)
    }

    fn positions(&self, system: &ReducedSystem<'_, M, N, NA>, states: &[Vec<f64>]) -> Vec<SMatrix<f64, 3, NA>> {
        states
            .iter()
            .map(|y| {
                let body = system.expand_body(y).expect("a final state");
                to_lab_body(self.molecule, &body, &CentreOfMass::default()).expect("lab positions").positions
            })
            .collect()
    }
}

/// Hands the states to the lanes in order and keeps each trajectory's last output.
struct Feed<'a> {
    starts: &'a [Vec<f64>],
    next: usize,
    /// The trajectory each lane holds.
    held: [usize; 8],
    last: Vec<Vec<f64>>,
}

impl LaneFeeder for Feed<'_> {
    fn next(&mut self, lane: usize, y0: &mut [f64]) -> bool {
        let Some(s) = self.starts.get(self.next) else { return false };
        y0.copy_from_slice(s);
        self.held[lane] = self.next;
        self.next += 1;
        true
    }
    fn observe(&mut self, lane: usize, _t: f64, y: &[f64]) -> ControlFlow<()> {
        let slot = &mut self.last[self.held[lane]];
        slot.clear();
        slot.extend_from_slice(y);
        ControlFlow::Continue(())
    }
    fn finish(&mut self, _lane: usize, result: Result<Stats, LaneFailure>) {
        result.expect("a lane run");
    }
}

/// Per state, the largest distance (bohr) of an atom from its reference position; the median.
fn median_error<const NA: usize>(a: &[SMatrix<f64, 3, NA>], reference: &[SMatrix<f64, 3, NA>]) -> f64 {
    let mut e: Vec<f64> = a
        .iter()
        .zip(reference)
        .map(|(x, r)| (0..NA).map(|i| (x.column(i) - r.column(i)).norm()).fold(0.0, f64::max))
        .collect();
    median(&mut e)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// log-log interpolation of cost at `target` error on a curve of (error, cost) points; `None`
/// outside the measured errors.
fn cost_at(curve: &[(f64, f64)], target: f64) -> Option<f64> {
    let mut points: Vec<(f64, f64)> = curve.iter().copied().filter(|p| p.0 > 0.0).collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points.windows(2).find(|w| w[0].0 <= target && target <= w[1].0).map(|w| {
        let (x0, x1) = (w[0].0.ln(), w[1].0.ln());
        let s = if x1 > x0 { (target.ln() - x0) / (x1 - x0) } else { 0.0 };
        (w[0].1.ln() + s * (w[1].1.ln() - w[0].1.ln())).exp()
    })
}

const CONTENDERS: [&str; 6] =
    ["cartesian", "internal", "lanes x2", "lanes x4", "cartesian lanes x2", "cartesian lanes x4"];

fn compare<M, const N: usize, const NA: usize>(name: &str, molecule: &M, spec: &Spec<N>, rounds: usize, count: usize)
where
    M: Molecule<N, NA> + Sync,
{
    let case = Case::new(molecule, spec, count);
    let (reference, _) = case.cartesian(REFERENCE_TOLERANCE);
    let (internal_reference, _) = case.internal(REFERENCE_TOLERANCE);
    println!(
        "\n{name}: {count} states ({spec:?}, seed 1), {T_END} a.u.; the two references (Cartesian and internal at \
         {REFERENCE_TOLERANCE:e}) differ by {:.1e} bohr (median)",
        median_error(&internal_reference, &reference)
    );
    let run = |c: usize, tol: f64| match c {
        0 => case.cartesian(tol),
        1 => case.internal(tol),
        2 => case.lanes::<F64x2>(tol),
        3 => case.lanes::<F64x4>(tol),
        4 => case.cartesian_lanes::<F64x2>(tol),
        _ => case.cartesian_lanes::<F64x4>(tol),
    };
    // errors[c][k] and costs[c][k][round]
    let mut errors = [[0.0; TOLERANCES.len()]; CONTENDERS.len()];
    let mut costs = vec![vec![Vec::new(); TOLERANCES.len()]; CONTENDERS.len()];
    for round in 0..rounds {
        // Rotate the order of the contenders from round to round.
        for i in 0..CONTENDERS.len() {
            let c = (i + round) % CONTENDERS.len();
            for (k, &tol) in TOLERANCES.iter().enumerate() {
                let (finals, cost) = run(c, tol);
                if round == 0 {
                    errors[c][k] = median_error(&finals, &reference);
                }
                costs[c][k].push(cost);
                black_box(finals);
            }
        }
        eprint!("round {} of {rounds} done\r", round + 1);
    }
    eprintln!();
    println!(
        "| contender | rtol = atol | median error (bohr) | CPU µs per trajectory (median of {rounds}) | trajectories per CPU-second |"
    );
    println!("| --- | --- | ---: | ---: | ---: |");
    let mut curves = vec![Vec::new(); CONTENDERS.len()];
    for c in 0..CONTENDERS.len() {
        for (k, tol) in TOLERANCES.iter().enumerate() {
            let cost = median(&mut costs[c][k].clone());
            curves[c].push((errors[c][k], cost));
            println!(
                "| {} | {tol:.0e} | {:.2e} | {:.1} | {:.0} |",
                CONTENDERS[c],
                errors[c][k],
                cost * 1e6,
                1.0 / cost
            );
        }
    }
    println!(
        "\nat equal error (log-log interpolation), trajectories per CPU-second and relative to the Cartesian code:"
    );
    for target in TARGETS {
        let base = cost_at(&curves[0], target);
        let cells: Vec<String> = (0..CONTENDERS.len())
            .map(|c| match (cost_at(&curves[c], target), base) {
                (Some(x), Some(b)) => format!("{} {:.0}/s ({:.2}x)", CONTENDERS[c], 1.0 / x, b / x),
                (Some(x), None) => format!("{} {:.0}/s", CONTENDERS[c], 1.0 / x),
                (None, _) => format!("{} outside the measured errors", CONTENDERS[c]),
            })
            .collect();
        println!("error {target:.0e} bohr: {}", cells.join("; "));
    }
}

/// The canonical distribution at 300 K below 0.1 hartree above the minimum; where rejection
/// sampling of it accepts too little, normal-mode sampling with kT per mode on average (random
/// phases, thermal rotation).
fn thermal_or_modes<M, const N: usize, const NA: usize>(molecule: &M, modes: usize) -> Spec<N>
where
    M: Molecule<N, NA> + Sync,
{
    let thermal = Spec::Thermal { temperature: 300.0, region: Region::capped(0.1) };
    if sampler(molecule, &thermal, 1).is_ok() {
        return thermal;
    }
    let kt = 300.0 * rovib::runtime::sample::BOLTZMANN;
    Spec::NormalModes {
        energies: ModeEnergies::Random { total: modes as f64 * kt },
        rotation: RotationSampling::Thermal { temperature: 300.0 },
    }
}

fn main() {
    // `cargo bench` passes `--bench`; skip flags.
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let which = args.first().map_or("all", String::as_str);
    let rounds: usize = args.get(1).and_then(|a| a.parse().ok()).unwrap_or(5);
    let count: Option<usize> = args.get(2).and_then(|a| a.parse().ok());
    println!(
        "target features: sse2 {}, avx {}, avx2 {}, fma {}, avx512f {}; one thread, thread CPU time",
        cfg!(target_feature = "sse2"),
        cfg!(target_feature = "avx"),
        cfg!(target_feature = "avx2"),
        cfg!(target_feature = "fma"),
        cfg!(target_feature = "avx512f")
    );
    if matches!(which, "all" | "h2o") {
        compare("water (h2o)", &H2o, &thermal_or_modes(&H2o, 3), rounds, count.unwrap_or(256));
    }
    // The other shipped molecules declared by kind (the Cartesian code needs U(x)), non-linear.
    if matches!(which, "all" | "h2o2") {
        compare("hydrogen peroxide (h2o2)", &H2o2, &thermal_or_modes(&H2o2, 6), rounds, count.unwrap_or(64));
    }
    if matches!(which, "all" | "nh3") {
        compare("ammonia (nh3)", &Nh3, &thermal_or_modes(&Nh3, 6), rounds, count.unwrap_or(64));
    }
}
