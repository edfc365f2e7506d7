//! DOP853 over SIMD lanes: `T::LANES` independent trajectories advance together, one per lane,
//! each with its own step size, error estimate, acceptance or rejection, output times and end.
//!
//! The twelve stages of a step are evaluated in lockstep (one [`LaneSystem::rhs`] call per
//! stage for all lanes, each lane at its own `t` and `h`); the step-size controller, the
//! output times and the bookkeeping run per lane in plain `f64`, in the same order of
//! operations as [`super::Dop853::integrate`]. Every lane therefore computes exactly what the
//! scalar solver computes for that trajectory, bit for bit, provided the lane system computes
//! the scalar system's numbers bit for bit: the same steps, rejections, outputs and counts
//! (`tests/numerics/lanes.rs` checks this with the scalar solver on the lane right-hand side, one
//! trajectory in every lane). [`crate::hamiltonian::lanes::ProductionLanes`] computes the scalar
//! production system's numbers to round-off (its `sin_cos` and `exp` are vector polynomials),
//! so its trajectories are the scalar ones to round-off.
//!
//! When a lane's trajectory ends (its end time, its observer's break, or a failure) the lane
//! takes the next trajectory from the [`LaneFeeder`] at once; the run ends when the feeder has
//! no more and every lane has finished.
//!
//! What lockstep costs: a lane whose step is rejected still takes part in the evaluation of
//! the first stage of the next step (`f(t + h, y_new)`, made for the lanes that accepted), and
//! when any lane needs the three extra stages of the dense output for an output time inside its
//! step, every lane computes them. These evaluations are not counted in a lane's statistics,
//! which count what the scalar solver would have evaluated.
//!
//! A failure is reported as a [`LaneFailure`] (kind and time, without the state or the
//! system's error): the scalar solver, run on the same trajectory, reproduces it with the full
//! [`super::super::SolveError`].

use core::ops::ControlFlow;

use super::coefficients::{A, BHH, C, D, ER};
use super::stages::{combine, weights};
use super::{Dop853Options, FAC1, FAC2, FSAL, SAFETY, STAGES, UROUND};
use crate::integrate::{InvalidInput, OutputGrid, Stats, check_dim, check_run};
use crate::lanes::{Real, finite_mask};

/// `T::LANES` systems of ODEs `dy/dt = f(t, y)` of one dimension, evaluated together, one per
/// lane of `T`.
pub trait LaneSystem<T: Real> {
    /// The dimension of `y`.
    fn dim(&self) -> usize;

    /// Writes `f(t, y)` into `dydt` for every lane and returns the mask of lanes whose
    /// evaluation succeeded (bit `i` for lane `i`); a failed lane's numbers are meaningless.
    fn rhs(&mut self, t: T, y: &[T], dydt: &mut [T]) -> u32;
}

/// How a lane's trajectory failed; the scalar [`super::Dop853`] returns the same failure, at the
/// same time, as a [`crate::integrate::SolveError`] with the state and the system's error.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum LaneFailure {
    /// The system failed (its mask bit was clear) at `t`.
    Rhs {
        /// Time of the failing evaluation.
        t: f64,
    },
    /// The step size fell below the minimum.
    StepSizeTooSmall {
        /// Time reached.
        t: f64,
        /// The step size.
        h: f64,
    },
    /// `max_steps` was reached.
    TooManySteps {
        /// Time reached.
        t: f64,
    },
}

impl LaneFailure {
    /// When it happened.
    pub fn time(&self) -> f64 {
        match *self {
            Self::Rhs { t } | Self::StepSizeTooSmall { t, .. } | Self::TooManySteps { t } => t,
        }
    }
}

/// Supplies the trajectories of a batched run and receives what they produce.
pub trait LaneFeeder {
    /// The next trajectory for lane `lane`: writes its initial state into `y0` and returns
    /// `true`, or returns `false` when there is no more work.
    fn next(&mut self, lane: usize, y0: &mut [f64]) -> bool;

    /// The state of lane `lane`'s trajectory at an output time (and at `t0`), as
    /// [`crate::integrate::Observer::observe`]: `Break` ends that trajectory (successfully).
    fn observe(&mut self, lane: usize, t: f64, y: &[f64]) -> ControlFlow<()>;

    /// Lane `lane`'s trajectory ended: its work counters, or how it failed.
    fn finish(&mut self, lane: usize, result: Result<Stats, LaneFailure>);
}

/// The per-lane state of the step-size controller.
#[derive(Copy, Clone, Debug, Default)]
struct Lane {
    running: bool,
    x: f64,
    h: f64,
    h_max: f64,
    fac_old: f64,
    reject: bool,
    last: bool,
    next_output: u64,
    stats: Stats,
}

/// The batched DOP853 solver and its workspace (see the module docs).
#[derive(Clone, Debug)]
pub struct Dop853Lanes<T> {
    options: Dop853Options,
    dim: usize,
    k: Vec<T>,
    y: Vec<T>,
    y_stage: Vec<T>,
    y_new: Vec<T>,
    weighted: Vec<T>,
    cont: Vec<T>,
    tmp: Vec<T>,
    y_out: Vec<f64>,
    lane_y: Vec<f64>,
    lanes: Vec<Lane>,
}

impl<T: Real> Dop853Lanes<T> {
    /// Allocates the workspace for `T::LANES` systems of dimension `dim`.
    pub fn new(dim: usize, options: Dop853Options) -> Result<Self, InvalidInput> {
        check_dim(dim)?;
        options.validate()?;
        if T::LANES > 32 {
            return Err(InvalidInput(format!("at most 32 lanes, not {}", T::LANES)));
        }
        let z = T::splat(0.0);
        Ok(Self {
            options,
            dim,
            k: vec![z; STAGES * dim],
            y: vec![z; dim],
            y_stage: vec![z; dim],
            y_new: vec![z; dim],
            weighted: vec![z; dim],
            cont: vec![z; 8 * dim],
            tmp: vec![z; dim],
            y_out: vec![0.0; dim],
            lane_y: vec![0.0; dim],
            lanes: vec![Lane::default(); T::LANES],
        })
    }

    /// Runs every trajectory the feeder supplies from `t0` to `t_end`, with outputs every
    /// `output_interval` (the rule of [`crate::integrate::solve`]). Fails only for invalid
    /// arguments; each trajectory's outcome goes to [`LaneFeeder::finish`].
    pub fn integrate<S, F>(
        &mut self,
        system: &mut S,
        t0: f64,
        t_end: f64,
        output_interval: f64,
        feeder: &mut F,
    ) -> Result<(), InvalidInput>
    where
        S: LaneSystem<T> + ?Sized,
        F: LaneFeeder + ?Sized,
    {
        // The trajectories' states are checked as they start; the common arguments here, with a
        // zero state from the workspace (no allocation).
        self.lane_y.fill(0.0);
        let grid = check_run(self.dim, system.dim(), t0, &self.lane_y, t_end, output_interval)?;
        let run = Run { t0, t_end, grid };
        for lane in 0..T::LANES {
            self.start(system, feeder, &run, lane);
        }
        while self.lanes.iter().any(|l| l.running) {
            self.round(system, feeder, &run);
        }
        Ok(())
    }

    /// Gives lane `lane` trajectories from the feeder until one is running (or there are none).
    fn start<S, F>(&mut self, system: &mut S, feeder: &mut F, run: &Run, lane: usize)
    where
        S: LaneSystem<T> + ?Sized,
        F: LaneFeeder + ?Sized,
    {
        let n = self.dim;
        self.lanes[lane].running = false;
        while feeder.next(lane, &mut self.lane_y) {
            let mut stats = Stats::default();
            for i in 0..n {
                self.y[i].set_lane(lane, self.lane_y[i]);
            }
            if feeder.observe(lane, run.t0, &self.lane_y).is_break() || run.grid.count == 0 {
                feeder.finish(lane, Ok(stats));
                continue;
            }
            // f(t0, y0) into stage 0 of this lane.
            stats.rhs_evals += 1;
            if !self.eval_lane(system, lane, run.t0, 0) {
                feeder.finish(lane, Err(LaneFailure::Rhs { t: run.t0 }));
                continue;
            }
            let h_max = self.options.max_step.min(run.t_end - run.t0);
            let h = match self.options.initial_step {
                Some(h) => h.min(h_max),
                None => match self.initial_step(system, lane, run.t0, h_max, &mut stats) {
                    Ok(h) => h,
                    Err(t) => {
                        feeder.finish(lane, Err(LaneFailure::Rhs { t }));
                        continue;
                    }
                },
            };
            self.lanes[lane] = Lane {
                running: true,
                x: run.t0,
                h,
                h_max,
                fac_old: 1e-4,
                reject: false,
                last: false,
                next_output: 1,
                stats,
            };
            return;
        }
    }

    /// `f(t, lane_y)` for one lane into stage `stage` of that lane (the other lanes' stages are
    /// left as they are); whether it succeeded.
    fn eval_lane<S: LaneSystem<T> + ?Sized>(&mut self, system: &mut S, lane: usize, t: f64, stage: usize) -> bool {
        let n = self.dim;
        for i in 0..n {
            self.y_stage[i] = T::splat(self.lane_y[i]);
        }
        let ok = (system.rhs(T::splat(t), &self.y_stage, &mut self.tmp) & 1) == 1;
        for i in 0..n {
            self.k[stage * n + i].set_lane(lane, self.tmp[i].lane(0));
        }
        ok
    }

    /// Hairer's `HINIT` for one lane, as [`super::Dop853`]'s (stage 0 of the lane holds
    /// `f(t0, y0)` and `lane_y` is `y0`); the error is the time of a failed evaluation.
    fn initial_step<S: LaneSystem<T> + ?Sized>(
        &mut self,
        system: &mut S,
        lane: usize,
        x: f64,
        h_max: f64,
        stats: &mut Stats,
    ) -> Result<f64, f64> {
        let n = self.dim;
        let (rtol, atol) = (self.options.rtol, self.options.atol);
        // y0 is kept in y_out (free until the first output) while lane_y holds the Euler step;
        // f(t0, y0) stays in the lane's stage 0. No allocation.
        self.y_out.copy_from_slice(&self.lane_y);
        let (mut dnf, mut dny) = (0.0, 0.0);
        for i in 0..n {
            let sk = atol + rtol * self.y_out[i].abs();
            dnf += (self.k[i].lane(lane) / sk).powi(2);
            dny += (self.y_out[i] / sk).powi(2);
        }
        let mut h: f64 = if dnf <= 1e-10 || dny <= 1e-10 { 1e-6 } else { (dny / dnf).sqrt() * 0.01 };
        h = h.min(h_max);
        for i in 0..n {
            self.lane_y[i] = self.y_out[i] + h * self.k[i].lane(lane);
        }
        stats.rhs_evals += 1;
        // Stage 1 of the lane is scratch here, as in the scalar solver.
        if !self.eval_lane(system, lane, x + h, 1) {
            return Err(x + h);
        }
        let mut der2: f64 = 0.0;
        for i in 0..n {
            let sk = atol + rtol * self.y_out[i].abs();
            der2 += ((self.k[n + i].lane(lane) - self.k[i].lane(lane)) / sk).powi(2);
        }
        der2 = der2.sqrt() / h;
        let der12 = der2.abs().max(dnf.sqrt());
        let h1 = if !der12.is_finite() {
            1e-3 * h
        } else if der12 <= 1e-15 {
            (1e-6_f64).max(h * 1e-3)
        } else {
            (0.01 / der12).powf(1.0 / 8.0)
        };
        self.lane_y.copy_from_slice(&self.y_out);
        Ok((100.0 * h).min(h1).min(h_max))
    }

    /// Ends lane `lane`'s trajectory and starts the next.
    fn finish<S, F>(
        &mut self,
        system: &mut S,
        feeder: &mut F,
        run: &Run,
        lane: usize,
        result: Result<Stats, LaneFailure>,
    ) where
        S: LaneSystem<T> + ?Sized,
        F: LaneFeeder + ?Sized,
    {
        feeder.finish(lane, result);
        self.start(system, feeder, run, lane);
    }

    /// One step attempt of every running lane.
    fn round<S, F>(&mut self, system: &mut S, feeder: &mut F, run: &Run)
    where
        S: LaneSystem<T> + ?Sized,
        F: LaneFeeder + ?Sized,
    {
        self.check_lanes(system, feeder, run);
        let mut running = 0u32;
        let (mut hv, mut xv) = (T::splat(0.0), T::splat(0.0));
        for (lane, l) in self.lanes.iter().enumerate() {
            if l.running {
                running |= 1 << lane;
                hv.set_lane(lane, l.h);
                xv.set_lane(lane, l.x);
            }
        }
        if running == 0 {
            return;
        }
        let mut failed_at = [0.0; 32];
        let failed = self.trial_step(system, running, xv, hv, &mut failed_at);
        let mut h_news = [0.0; 32];
        let mut accepted = self.control(running & !failed, &mut h_news);
        for lane in lanes_of(failed) {
            self.finish(system, feeder, run, lane, Err(LaneFailure::Rhs { t: failed_at[lane] }));
        }
        let mut x_new = [0.0; 32];
        accepted = self.eval_fsal(system, feeder, run, accepted, &mut x_new);
        accepted = self.dense_where_needed(system, feeder, run, accepted, &x_new, xv, hv);
        self.take_steps(accepted);
        for lane in lanes_of(accepted) {
            self.serve_and_advance(system, feeder, run, lane, x_new[lane], h_news[lane]);
        }
    }

    /// The checks at the top of the scalar solver's loop, per lane: a lane past `max_steps` or
    /// with too small a step ends its trajectory and takes the next; a lane that goes on
    /// shortens a last step to land on `t_end` and counts the step.
    #[inline]
    fn check_lanes<S, F>(&mut self, system: &mut S, feeder: &mut F, run: &Run)
    where
        S: LaneSystem<T> + ?Sized,
        F: LaneFeeder + ?Sized,
    {
        let opts = self.options;
        for lane in 0..T::LANES {
            while self.lanes[lane].running {
                let l = &mut self.lanes[lane];
                let failure = if l.stats.steps >= opts.max_steps {
                    Some(LaneFailure::TooManySteps { t: l.x })
                } else if 0.1 * l.h.abs() <= l.x.abs() * UROUND || l.h < opts.min_step || l.h.is_nan() {
                    Some(LaneFailure::StepSizeTooSmall { t: l.x, h: l.h })
                } else {
                    None
                };
                match failure {
                    Some(f) => self.finish(system, feeder, run, lane, Err(f)),
                    None => {
                        l.last = l.x + 1.01 * l.h > run.t_end;
                        if l.last {
                            l.h = run.t_end - l.x;
                        }
                        l.stats.steps += 1;
                        break;
                    }
                }
            }
        }
    }

    /// The twelve stages of the `running` lanes' steps (from `xv` with steps `hv`) in lockstep,
    /// leaving the 8th-order solution in `y_new` and `Σ b_i k_i` in `weighted`. Returns the mask
    /// of lanes whose evaluation failed, with the time of each one's first failing stage in
    /// `failed_at`.
    #[inline]
    fn trial_step<S: LaneSystem<T> + ?Sized>(
        &mut self,
        system: &mut S,
        running: u32,
        xv: T,
        hv: T,
        failed_at: &mut [f64; 32],
    ) -> u32 {
        let n = self.dim;
        let mut failed = 0u32;
        for stage in 1..FSAL {
            combine(&mut self.y_stage, &self.y, &self.k, n, hv, A[stage]);
            let tv = xv + T::splat(C[stage]) * hv;
            let ok = system.rhs(tv, &self.y_stage, &mut self.k[stage * n..(stage + 1) * n]);
            let newly = running & !ok & !failed;
            for lane in lanes_of(newly) {
                failed_at[lane] = tv.lane(lane);
            }
            failed |= newly;
        }
        weights(&mut self.weighted, &self.k, n, A[FSAL]);
        for i in 0..n {
            self.y_new[i] = self.y[i] + hv * self.weighted[i];
        }
        failed
    }

    /// Per lane of `lanes` (whose trial steps were evaluated): the error, the step-size factor
    /// and the decision, as the scalar solver. Writes each lane's proposed next step into
    /// `h_news`, shrinks a rejected lane's step, and returns the mask of accepted lanes.
    #[inline]
    fn control(&mut self, lanes: u32, h_news: &mut [f64; 32]) -> u32 {
        let n = self.dim;
        let opts = self.options;
        let (err5, err3) = self.error_sums();
        let y_new_finite = finite_mask(&self.y_new);
        let expo1 = 1.0 / 8.0 - opts.beta * 0.2;
        let mut accepted = 0u32;
        for lane in lanes_of(lanes) {
            self.lanes[lane].stats.rhs_evals += (FSAL - 1) as u64;
            let h = self.lanes[lane].h;
            let (e5, e3) = (err5.lane(lane), err3.lane(lane));
            let mut deno = e5 + 0.01 * e3;
            if deno <= 0.0 {
                deno = 1.0;
            }
            let err = h.abs() * e5 * (1.0 / (n as f64 * deno)).sqrt();
            let err = if err.is_finite() && y_new_finite >> lane & 1 == 1 { err } else { f64::INFINITY };
            let fac11 = err.powf(expo1);
            let fac = (fac11 / self.lanes[lane].fac_old.powf(opts.beta) / SAFETY).clamp(1.0 / FAC2, 1.0 / FAC1);
            h_news[lane] = h / fac;
            let l = &mut self.lanes[lane];
            if err <= 1.0 {
                l.fac_old = err.max(1e-4);
                l.stats.accepted += 1;
                accepted |= 1 << lane;
            } else {
                l.h = h / (1.0 / FAC1).min(fac11 / SAFETY);
                l.reject = true;
                l.stats.rejected += 1;
            }
        }
        accepted
    }

    /// `f(t + h, y_new)`, the first stage of the next step, for the `accepted` lanes, each at its
    /// step's end (written into `x_new`). A lane whose evaluation fails ends its trajectory;
    /// returns the accepted lanes that remain.
    #[inline]
    fn eval_fsal<S, F>(
        &mut self,
        system: &mut S,
        feeder: &mut F,
        run: &Run,
        mut accepted: u32,
        x_new: &mut [f64; 32],
    ) -> u32
    where
        S: LaneSystem<T> + ?Sized,
        F: LaneFeeder + ?Sized,
    {
        if accepted == 0 {
            return accepted;
        }
        let n = self.dim;
        let mut tv = T::splat(0.0);
        for lane in lanes_of(accepted) {
            let l = &self.lanes[lane];
            x_new[lane] = if l.last { run.t_end } else { l.x + l.h };
            tv.set_lane(lane, x_new[lane]);
        }
        let ok = system.rhs(tv, &self.y_new, &mut self.k[FSAL * n..(FSAL + 1) * n]);
        for lane in lanes_of(accepted) {
            self.lanes[lane].stats.rhs_evals += 1;
            if ok >> lane & 1 == 0 {
                accepted &= !(1 << lane);
                self.finish(system, feeder, run, lane, Err(LaneFailure::Rhs { t: x_new[lane] }));
            }
        }
        accepted
    }

    /// The dense output of every lane's step (from `xv` with steps `hv`), if an `accepted` lane
    /// has an output time inside its step (before `x_new`). A lane that needed it and whose
    /// extra stages failed ends its trajectory; returns the accepted lanes that remain.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn dense_where_needed<S, F>(
        &mut self,
        system: &mut S,
        feeder: &mut F,
        run: &Run,
        mut accepted: u32,
        x_new: &[f64; 32],
        xv: T,
        hv: T,
    ) -> u32
    where
        S: LaneSystem<T> + ?Sized,
        F: LaneFeeder + ?Sized,
    {
        let mut dense = 0u32;
        for lane in lanes_of(accepted) {
            let l = &self.lanes[lane];
            if l.next_output <= run.grid.count && run.grid.time(l.next_output) < x_new[lane] {
                dense |= 1 << lane;
            }
        }
        if dense == 0 {
            return accepted;
        }
        let ok = self.prepare_dense(system, xv, hv);
        for lane in lanes_of(dense) {
            self.lanes[lane].stats.rhs_evals += (STAGES - FSAL - 1) as u64;
            if ok >> lane & 1 == 0 {
                accepted &= !(1 << lane);
                let t = self.lanes[lane].x + C[FSAL + 1] * self.lanes[lane].h;
                self.finish(system, feeder, run, lane, Err(LaneFailure::Rhs { t }));
            }
        }
        accepted
    }

    /// The `accepted` lanes' new state and FSAL stage, all lanes at once when every lane
    /// accepted (the common case), else lane by lane. Nothing after this reads a lane's `y` or
    /// stage 0 before a finished lane is restarted (which overwrites both).
    #[inline]
    fn take_steps(&mut self, accepted: u32) {
        let n = self.dim;
        if accepted == T::ALL {
            self.y.copy_from_slice(&self.y_new);
            self.k.copy_within(FSAL * n..(FSAL + 1) * n, 0);
        } else {
            for lane in lanes_of(accepted) {
                for i in 0..n {
                    self.y[i].set_lane(lane, self.y_new[i].lane(lane));
                    let fsal = self.k[FSAL * n + i].lane(lane);
                    self.k[i].set_lane(lane, fsal);
                }
            }
        }
    }

    /// After lane `lane`'s step to `x_new` was accepted: serves the output times in
    /// `(x, x_new]`, then ends the trajectory (its observer's break or its last step) or moves
    /// the lane to `x_new` with the next step `h_new` (capped as the scalar solver caps it).
    #[inline]
    fn serve_and_advance<S, F>(
        &mut self,
        system: &mut S,
        feeder: &mut F,
        run: &Run,
        lane: usize,
        x_new: f64,
        h_new: f64,
    ) where
        S: LaneSystem<T> + ?Sized,
        F: LaneFeeder + ?Sized,
    {
        let n = self.dim;
        let mut stopped = false;
        while self.lanes[lane].next_output <= run.grid.count {
            let t_out = run.grid.time(self.lanes[lane].next_output);
            if t_out > x_new {
                break;
            }
            if t_out == x_new {
                for i in 0..n {
                    self.y_out[i] = self.y_new[i].lane(lane);
                }
            } else {
                self.interpolate(lane, t_out);
            }
            self.lanes[lane].next_output += 1;
            if feeder.observe(lane, t_out, &self.y_out).is_break() {
                stopped = true;
                break;
            }
        }
        if stopped {
            let stats = self.lanes[lane].stats;
            self.finish(system, feeder, run, lane, Ok(stats));
            return;
        }
        let l = &mut self.lanes[lane];
        l.x = x_new;
        if l.last {
            let stats = l.stats;
            self.finish(system, feeder, run, lane, Ok(stats));
            return;
        }
        let mut h_new = h_new.min(l.h_max);
        if l.reject {
            h_new = h_new.min(l.h);
        }
        l.reject = false;
        l.h = h_new;
    }

    /// Sums of the squared scaled 5th- and 3rd-order error estimates over the components, per
    /// lane, in the scalar solver's order (its `error_norm`).
    fn error_sums(&self) -> (T, T) {
        let n = self.dim;
        let (rtol, atol) = (T::splat(self.options.rtol), T::splat(self.options.atol));
        let stage = |s: usize| &self.k[s * n..(s + 1) * n];
        let (k0, k8, k11) = (stage(0), stage(8), stage(11));
        let er = ER.map(|(s, w)| (stage(s), T::splat(w)));
        let (mut err5, mut err3) = (T::splat(0.0), T::splat(0.0));
        for i in 0..n {
            let sk = atol + rtol * self.y[i].abs().max(self.y_new[i].abs());
            let e3 = self.weighted[i] - T::splat(BHH[0]) * k0[i] - T::splat(BHH[1]) * k8[i] - T::splat(BHH[2]) * k11[i];
            let r3 = e3 / sk;
            err3 = err3 + r3 * r3;
            let mut e5 = T::splat(0.0);
            for (ks, w) in &er {
                e5 = e5 + *w * ks[i];
            }
            let r5 = e5 / sk;
            err5 = err5 + r5 * r5;
        }
        (err5, err3)
    }

    /// The three extra stages and the dense-output coefficients of every lane's step (as
    /// `CONTD8`); returns the mask of lanes whose three evaluations succeeded.
    fn prepare_dense<S: LaneSystem<T> + ?Sized>(&mut self, system: &mut S, xv: T, hv: T) -> u32 {
        let n = self.dim;
        let mut ok = T::ALL;
        for stage in FSAL + 1..STAGES {
            combine(&mut self.y_stage, &self.y, &self.k, n, hv, A[stage]);
            let tv = xv + T::splat(C[stage]) * hv;
            ok &= system.rhs(tv, &self.y_stage, &mut self.k[stage * n..(stage + 1) * n]);
        }
        let (cont, k) = (&mut self.cont, &self.k);
        for i in 0..n {
            let y_diff = self.y_new[i] - self.y[i];
            let b_spline = hv * k[i] - y_diff;
            cont[i] = self.y[i];
            cont[n + i] = y_diff;
            cont[2 * n + i] = b_spline;
            cont[3 * n + i] = y_diff - hv * k[FSAL * n + i] - b_spline;
            for (row, d) in D.iter().enumerate() {
                let mut sum = T::splat(0.0);
                for &(stage, w) in d {
                    sum = sum + T::splat(w) * k[stage * n + i];
                }
                cont[(4 + row) * n + i] = hv * sum;
            }
        }
        ok
    }

    /// The dense output of lane `lane` at `t` in its step, into `y_out`.
    fn interpolate(&mut self, lane: usize, t: f64) {
        let n = self.dim;
        let (x, h) = (self.lanes[lane].x, self.lanes[lane].h);
        let s = (t - x) / h;
        let s1 = 1.0 - s;
        let c = |j: usize, i: usize| self.cont[j * n + i].lane(lane);
        for i in 0..n {
            let high = c(4, i) + s * (c(5, i) + s1 * (c(6, i) + s * c(7, i)));
            self.y_out[i] = c(0, i) + s * (c(1, i) + s1 * (c(2, i) + s * (c(3, i) + s1 * high)));
        }
    }
}

/// What every trajectory of a run shares.
struct Run {
    t0: f64,
    t_end: f64,
    grid: OutputGrid,
}

/// The lanes whose bits are set in `mask`.
fn lanes_of(mask: u32) -> impl Iterator<Item = usize> {
    let mut rest = mask;
    core::iter::from_fn(move || {
        (rest != 0).then(|| {
            let lane = rest.trailing_zeros() as usize;
            rest &= rest - 1;
            lane
        })
    })
}
