//! Classical fourth-order Runge–Kutta at a fixed step: the plain baseline the other methods are
//! measured against.
//!
//! Source: the "classical" method of Kutta (1901), Table 1.2 (right) in Hairer, Nørsett &
//! Wanner, *Solving Ordinary Differential Equations I*, 2nd ed., Springer 1993, section II.1.

use super::{FixedStep, InvalidInput, Observer, OdeSystem, SolveError, Stats, check_dim, check_positive, eval_checked};

/// Options of [`Rk4`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rk4Options {
    /// Largest step size (time units of the system: ħ/E_h in rovib). Each output interval is cut
    /// into equal steps no longer than this (see [`Rk4::integrate`]). Default 1.0, about 1/400 of
    /// the period of the fastest molecular vibration (an O–H stretch, ≈ 9 fs ≈ 370 ħ/E_h).
    pub step: f64,
    /// Most steps a run may take before it fails with [`SolveError::TooManySteps`].
    /// Default [`super::DEFAULT_MAX_STEPS`] (a run's count is known in advance: `rovib run`
    /// refuses a scene that needs more before it starts).
    pub max_steps: u64,
}

impl Default for Rk4Options {
    fn default() -> Self {
        Self { step: 1.0, max_steps: super::DEFAULT_MAX_STEPS }
    }
}

impl Rk4Options {
    /// Checks that the options can be run with.
    pub fn validate(&self) -> Result<(), InvalidInput> {
        check_positive("the RK4 step", self.step)?;
        if self.max_steps == 0 {
            return Err(InvalidInput("max_steps must be at least 1".into()));
        }
        Ok(())
    }
}

/// Classical RK4 with its workspace for one dimension.
#[derive(Clone, Debug)]
pub struct Rk4 {
    options: Rk4Options,
    y: Vec<f64>,
    y_stage: Vec<f64>,
    k1: Vec<f64>,
    k2: Vec<f64>,
    k3: Vec<f64>,
    k4: Vec<f64>,
}

impl Rk4 {
    /// Allocates the workspace for systems of dimension `dim`.
    pub fn new(dim: usize, options: Rk4Options) -> Result<Self, InvalidInput> {
        check_dim(dim)?;
        options.validate()?;
        Ok(Self {
            options,
            y: vec![0.0; dim],
            y_stage: vec![0.0; dim],
            k1: vec![0.0; dim],
            k2: vec![0.0; dim],
            k3: vec![0.0; dim],
            k4: vec![0.0; dim],
        })
    }

    /// The options this solver was created with.
    pub fn options(&self) -> &Rk4Options {
        &self.options
    }

    /// The dimension this solver was created for.
    pub fn dim(&self) -> usize {
        self.y.len()
    }

    /// Integrates from `(t0, y0)` to `t_end`, calling `observer` at `t0` and at every output time
    /// (the rule is in [`solve`](super::solve)). Does not allocate unless it fails.
    ///
    /// Each output interval of length `L` is cut into `n = ceil(L / step)` equal steps, so the
    /// step actually used is `L / n ≤ step` and every output time (and `t_end`) is hit exactly.
    ///
    /// # Errors
    ///
    /// [`SolveError::InvalidInput`] for wrong dimensions or bad times, [`SolveError::Rhs`] if
    /// the system fails, [`SolveError::NonFinite`] if a stage derivative or the new state is not
    /// finite, [`SolveError::TooManySteps`] past `max_steps`; each with the last accepted state.
    pub fn integrate<S, O>(
        &mut self,
        system: &mut S,
        t0: f64,
        y0: &[f64],
        t_end: f64,
        output_interval: f64,
        observer: &mut O,
    ) -> Result<Stats, SolveError<S::Error>>
    where
        S: OdeSystem + ?Sized,
        O: Observer + ?Sized,
    {
        self.integrate_fixed(system, t0, y0, t_end, output_interval, observer)
    }
}

impl FixedStep for Rk4 {
    fn state(&self) -> &[f64] {
        &self.y
    }

    fn step_and_limit(&self) -> (f64, u64) {
        (self.options.step, self.options.max_steps)
    }

    fn restart(&mut self, y0: &[f64]) {
        self.y.copy_from_slice(y0);
    }

    fn step<S: OdeSystem + ?Sized>(
        &mut self,
        system: &mut S,
        t: f64,
        h: f64,
        stats: &mut Stats,
    ) -> Result<(), SolveError<S::Error>> {
        let half = 0.5 * h;
        eval_checked(system, t, &self.y, &mut self.k1, &self.y, stats)?;
        for i in 0..self.y.len() {
            self.y_stage[i] = self.y[i] + half * self.k1[i];
        }
        eval_checked(system, t + half, &self.y_stage, &mut self.k2, &self.y, stats)?;
        for i in 0..self.y.len() {
            self.y_stage[i] = self.y[i] + half * self.k2[i];
        }
        eval_checked(system, t + half, &self.y_stage, &mut self.k3, &self.y, stats)?;
        for i in 0..self.y.len() {
            self.y_stage[i] = self.y[i] + h * self.k3[i];
        }
        eval_checked(system, t + h, &self.y_stage, &mut self.k4, &self.y, stats)?;
        let sixth = h / 6.0;
        // Write into the stage buffer first so that a non-finite result leaves `y` as the last
        // accepted state.
        for i in 0..self.y.len() {
            self.y_stage[i] = self.y[i] + sixth * (self.k1[i] + 2.0 * (self.k2[i] + self.k3[i]) + self.k4[i]);
        }
        if !self.y_stage.iter().all(|v| v.is_finite()) {
            return Err(SolveError::NonFinite { t: t + h, y: self.y.clone() });
        }
        self.y.copy_from_slice(&self.y_stage);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::convert::Infallible;
    use core::ops::ControlFlow;

    /// y' = y, whose RK4 step multiplies by the degree-4 Taylor polynomial of e^h exactly.
    struct Growth;

    impl OdeSystem for Growth {
        type Error = Infallible;
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
            dydt[0] = y[0];
            Ok(())
        }
    }

    #[test]
    fn one_step_is_the_taylor_polynomial() {
        let h = 0.1;
        let mut rk = Rk4::new(1, Rk4Options { step: h, ..Default::default() }).unwrap();
        let mut last = 0.0;
        let stats = rk
            .integrate(&mut Growth, 0.0, &[1.0], h, h, &mut |_t: f64, y: &[f64]| {
                last = y[0];
                ControlFlow::Continue(())
            })
            .unwrap();
        let taylor = 1.0 + h + h * h / 2.0 + h * h * h / 6.0 + h * h * h * h / 24.0;
        assert!((last - taylor).abs() < 1e-15, "{last} vs {taylor}");
        assert_eq!(stats.steps, 1);
        assert_eq!(stats.rhs_evals, 4);
    }

    #[test]
    fn steps_are_shrunk_to_fit_output_intervals() {
        // 1.0 / 0.3 → 4 steps of 0.25 per interval.
        let mut rk = Rk4::new(1, Rk4Options { step: 0.3, ..Default::default() }).unwrap();
        let mut times = Vec::new();
        let stats = rk
            .integrate(&mut Growth, 0.0, &[1.0], 2.5, 1.0, &mut |t: f64, _y: &[f64]| {
                times.push(t);
                ControlFlow::Continue(())
            })
            .unwrap();
        assert_eq!(times, [0.0, 1.0, 2.0, 2.5]);
        // 4 + 4 + 2 (0.5 / 0.3 → 2 steps of 0.25).
        assert_eq!(stats.steps, 10);
    }
}
