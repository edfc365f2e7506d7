//! Runs a collision ensemble (`method = "collision"`): draws each trajectory's initial state
//! ([`crate::runtime::sample::collision`]), integrates it until the fragments' centre-of-mass
//! separation R passes `r_stop` after the encounter (R first decreasing, then increasing) or
//! until `run.end`, and reduces the final states ([`super::collision_final`]) to
//! final_states.csv, collision_histograms.csv and summary.json.
//!
//! Trajectory `i` draws from its own random stream, so the results do not depend on the number
//! of threads; the records are sorted by index before they are written.

use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use super::EnsembleOptions;
use super::collision_final::{self as fin, Record};
use super::collision_scene::CollisionScene;
use super::runner::Failure;
use crate::error::Error;
use crate::runtime::Molecule;
use crate::runtime::frames::{CentreOfMass, lab_of_body_any};
use crate::runtime::hamiltonian::fast::{BodyState, ReducedSystem};
use crate::runtime::integrate::{Integrator, Observer, OdeSystem as _};
use crate::runtime::nalgebra::SMatrix;
use crate::runtime::sample::collision::Collision;
use crate::scene::Scene;

/// Observes one collision at the output times: H, R, the lifetime and the end rule.
struct Watch<'a, 'm, M, const N: usize, const NA: usize> {
    system: ReducedSystem<'m, M, N, NA>,
    molecule: &'m M,
    fragments: &'a [Vec<usize>; 2],
    masses: [f64; NA],
    r_stop: f64,
    lifetime_radius: f64,
    max_energy_error: f64,
    stop: &'a AtomicBool,
    k: usize,
    h0: f64,
    h: f64,
    t: f64,
    prev_r: f64,
    r_min: f64,
    descended: bool,
    ended: bool,
    lifetime: f64,
    body: Option<BodyState<N>>,
    failure: Option<(&'static str, f64, String)>,
    interrupted: bool,
    positions: SMatrix<f64, 3, NA>,
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> Observer for Watch<'_, '_, M, N, NA> {
    fn observe(&mut self, t: f64, y: &[f64]) -> ControlFlow<()> {
        if self.stop.load(Ordering::Relaxed) {
            self.interrupted = true;
            return ControlFlow::Break(());
        }
        let (body, h) = match self.system.expand_body_and_energy(y) {
            Ok(x) => x,
            Err(e) => {
                self.failure = Some(("right-hand side", t, e.to_string()));
                return ControlFlow::Break(());
            }
        };
        if self.k == 0 {
            self.h0 = h;
        }
        if let Err(e) = crate::output::energy_guard(self.h0, h, self.max_energy_error) {
            self.failure = Some(("energy guard", t, e.to_string()));
            return ControlFlow::Break(());
        }
        // R is the same in the body frame as in the lab frame.
        self.molecule.positions(&body.q, &mut self.positions);
        let r = fin::separation(&self.positions, &self.masses, self.fragments);
        if self.k > 0 {
            self.lifetime += fin::time_below(self.prev_r, r, t - self.t, self.lifetime_radius);
            if r < self.prev_r {
                self.descended = true;
            }
        }
        let turned = self.k > 0 && self.descended && r > self.prev_r;
        self.r_min = self.r_min.min(r);
        self.prev_r = r;
        self.t = t;
        self.h = h;
        self.body = Some(body);
        self.k += 1;
        if turned && r >= self.r_stop {
            self.ended = true;
            return ControlFlow::Break(());
        }
        ControlFlow::Continue(())
    }
}

/// The reason of a trajectory cut short by an interrupt (counted apart from failures).
const INTERRUPTED: &str = "interrupted";

/// What a collision ensemble produced (besides its files).
#[derive(Clone, Debug)]
pub struct CollisionReport {
    /// One record per completed trajectory, by index.
    pub records: Vec<Record>,
    /// Failed trajectories (the first [`super::runner::LISTED_FAILURES`] listed in summary.json).
    pub failures: Vec<Failure>,
    /// Trajectories cut short or not started because of an interrupt.
    pub interrupted: u64,
    /// Trajectories per stratum, as allocated.
    pub stratum_counts: Vec<u64>,
    /// The reduction (cross sections, energy-transfer moments).
    pub summary: fin::Summary,
}

/// Runs the collision ensemble of `scene` for molecule `m`.
pub fn run<M, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    trajectories: u64,
    seed: u64,
    threads: Option<usize>,
    c: &CollisionScene,
    options: &EnsembleOptions,
) -> Result<(CollisionReport, f64, usize), Error>
where
    M: Molecule<N, NA> + Sync,
{
    let src = scene.source();
    let spec = c.bind(m, &src, trajectories)?;
    let sampler = Collision::new(m, spec, seed).map_err(|e| {
        src.error(
            c.span.clone(),
            format!("cannot sample these collisions: {e}"),
            "change [collision] (see docs/src/howto/collisions.md)",
        )
    })?;
    let reduction = crate::start::frozen_reduction(m, scene)?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let n_threads = options.threads.or(threads).unwrap_or(cores).clamp(1, trajectories.min(256) as usize);
    let next = AtomicU64::new(0);
    let start = Instant::now();
    let results: Vec<Vec<Result<Record, Failure>>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..n_threads)
            .map(|_| {
                s.spawn(|| {
                    let mut out = Vec::new();
                    loop {
                        let index = next.fetch_add(1, Ordering::Relaxed);
                        if index >= trajectories || options.stop.load(Ordering::Relaxed) {
                            break;
                        }
                        out.push(one(m, scene, &sampler, c, reduction, index, &options.stop));
                    }
                    out
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap_or_default()).collect()
    });
    let wall = start.elapsed().as_secs_f64();
    let mut records = Vec::new();
    let mut failures = Vec::new();
    let mut interrupted = 0;
    for r in results.into_iter().flatten() {
        match r {
            Ok(rec) => records.push(rec),
            Err(f) if f.reason == INTERRUPTED => interrupted += 1,
            Err(f) => failures.push(f),
        }
    }
    records.sort_by_key(|r| r.index);
    failures.sort_by_key(|f| f.index);
    let counts = sampler.stratum_counts();
    let summary = fin::summarise(&records, &sampler.spec().strata, c.stratified);
    Ok((CollisionReport { records, failures, interrupted, stratum_counts: counts, summary }, wall, n_threads))
}

/// Draws, integrates and reduces trajectory `index`.
fn one<M, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    sampler: &Collision<'_, M, N, NA>,
    c: &CollisionScene,
    reduction: crate::runtime::hamiltonian::fast::Reduction<N>,
    index: u64,
    stop: &AtomicBool,
) -> Result<Record, Failure>
where
    M: Molecule<N, NA> + Sync,
{
    let fail = |reason: &str, time: Option<f64>, detail: String| Failure { index, reason: reason.into(), time, detail };
    let (state, drawn) = sampler.draw_detail(index).map_err(|e| fail("sampler", None, e.to_string()))?;
    let system = ReducedSystem::from_body(m, reduction, &state).with_min_pivot(scene.min_metric_pivot);
    let mut y0 = vec![0.0; system.dim()];
    system.reduce_body(&state, &mut y0).map_err(|e| fail("invalid initial state", Some(0.0), e.to_string()))?;
    let mut integrator = Integrator::new(&scene.method, system.dim())
        .map_err(|e| fail("invalid integrator settings", None, e.to_string()))?;
    let fragments = &sampler.spec().fragments;
    let mut watch = Watch {
        system,
        molecule: m,
        fragments,
        masses: m.masses(),
        r_stop: c.r_stop,
        lifetime_radius: c.lifetime_radius,
        max_energy_error: scene.max_energy_error,
        stop,
        k: 0,
        h0: 0.0,
        h: 0.0,
        t: 0.0,
        prev_r: c.r0,
        r_min: f64::INFINITY,
        descended: false,
        ended: false,
        lifetime: 0.0,
        body: None,
        failure: None,
        interrupted: false,
        positions: SMatrix::zeros(),
    };
    let mut sys = system;
    let result = integrator.integrate(&mut sys, 0.0, &y0, scene.t_end, scene.output_interval, &mut watch);
    if let Err(e) = result {
        let t = e.time();
        return Err(fail("integration", t, e.to_string()));
    }
    if let Some((reason, t, detail)) = watch.failure.take() {
        return Err(fail(reason, Some(t), detail));
    }
    if watch.interrupted {
        return Err(fail(INTERRUPTED, Some(watch.t), "stopped before the end".into()));
    }
    let end = watch.body.ok_or_else(|| fail("output", None, "no output time observed".into()))?;
    let lab0 = lab_of_body_any(m, &state, &CentreOfMass::AT_REST)
        .map_err(|e| fail("final state", Some(0.0), format!("the initial lab state: {e}")))?;
    let lab1 = lab_of_body_any(m, &end, &CentreOfMass::AT_REST)
        .map_err(|e| fail("final state", Some(watch.t), format!("the final lab state: {e}")))?;
    let masses = m.masses();
    let initial = fin::channels(sampler, &lab0, &masses);
    let fin_state = fin::channels(sampler, &lab1, &masses);
    let outcome = if !watch.ended {
        fin::Outcome::Complex
    } else if fin::rearranged(sampler, &lab1) {
        fin::Outcome::Reactive
    } else {
        fin::Outcome::Inelastic
    };
    let l0 = state.rotation() * state.j;
    let l1 = end.rotation() * end.j;
    Ok(Record {
        index,
        stratum: drawn.stratum,
        b: drawn.b,
        deflection: fin::deflection(&initial, &fin_state),
        initial,
        last: fin_state,
        outcome,
        lifetime: watch.lifetime,
        t_end: watch.t,
        r_min: watch.r_min,
        energy_change: watch.h - watch.h0,
        angular_momentum_change: (l1 - l0).norm(),
        angular_momentum: l0.norm(),
    })
}
