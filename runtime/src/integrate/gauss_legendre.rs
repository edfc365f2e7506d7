//! Gauss–Legendre collocation (implicit Runge–Kutta with 2 or 3 stages, orders 4 and 6) at a
//! fixed step: symplectic and symmetric, so the energy error of a Hamiltonian system stays
//! bounded over long runs instead of drifting.
//!
//! Sources:
//! - the methods: Hairer, Lubich & Wanner, *Geometric Numerical Integration*, 2nd ed.,
//!   Springer 2006, section II.1.3 (Table 1.3 there gives both tableaux) and VI.4 (symplecticity);
//! - solving the stage equations by fixed-point iteration with a starting guess extrapolated from
//!   the previous step's collocation polynomial: same book, section VIII.6.1;
//! - iterating to round-off, stopping when the increments stop decreasing, and adding the
//!   increment with compensated summation: E. Hairer, R. I. McLachlan & A. Razakarivony,
//!   "Achieving Brouwer's law with implicit Runge–Kutta methods", BIT 48 (2008) 231–243.

use super::{FixedStep, InvalidInput, Observer, OdeSystem, SolveError, Stats, check_dim, check_positive, eval_checked};

/// Largest number of stages supported (the 3-stage method).
const MAX_STAGES: usize = 3;

/// A stall of the fixed-point iteration counts as convergence only below this scaled increment:
/// round-off leaves increments of a few 1e-16 (relative to `|y| + |Z|`), so a stall far above
/// that means the iteration is not contracting (step too large) rather than converged.
const STALL_LIMIT: f64 = 1e-10;

/// Options of [`GaussLegendre`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaussLegendreOptions {
    /// Number of stages: 2 (order 4) or 3 (order 6). Default 3.
    pub stages: usize,
    /// Largest step size (time units of the system: ħ/E_h in rovib). Each output interval is cut
    /// into equal steps no longer than this (see [`GaussLegendre::integrate`]). Default 1.0,
    /// about 1/400 of the period of the fastest molecular vibration (O–H stretch, ≈ 370 ħ/E_h).
    pub step: f64,
    /// Add each step's increment with compensated (Kahan) summation, so that round-off in the
    /// state does not accumulate as a random walk of size ε·|y| per step. Default `true`; switch
    /// off only to measure the difference.
    pub compensated: bool,
    /// Most fixed-point iterations per step before the step fails with
    /// [`SolveError::NotConverged`]. Default 100 (a well-resolved step needs about 5–20).
    pub max_iterations: u32,
    /// Most steps a run may take before it fails with [`SolveError::TooManySteps`].
    /// Default [`super::DEFAULT_MAX_STEPS`] (a run's count is known in advance: `rovib run`
    /// refuses a scene that needs more before it starts).
    pub max_steps: u64,
}

impl Default for GaussLegendreOptions {
    fn default() -> Self {
        Self { stages: 3, step: 1.0, compensated: true, max_iterations: 100, max_steps: super::DEFAULT_MAX_STEPS }
    }
}

impl GaussLegendreOptions {
    /// Checks that the options can be run with.
    pub fn validate(&self) -> Result<(), InvalidInput> {
        if !(self.stages == 2 || self.stages == 3) {
            return Err(InvalidInput(format!("Gauss–Legendre needs 2 or 3 stages, not {}", self.stages)));
        }
        check_positive("the Gauss–Legendre step", self.step)?;
        if self.max_iterations == 0 {
            return Err(InvalidInput("max_iterations must be at least 1".into()));
        }
        if self.max_steps == 0 {
            return Err(InvalidInput("max_steps must be at least 1".into()));
        }
        Ok(())
    }
}

/// Butcher tableau of an `s`-stage Gauss method (entries beyond `s` are zero).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Tableau {
    pub(crate) s: usize,
    pub(crate) a: [[f64; MAX_STAGES]; MAX_STAGES],
    pub(crate) b: [f64; MAX_STAGES],
    pub(crate) c: [f64; MAX_STAGES],
}

impl Tableau {
    /// The Gauss tableau with `stages` (2 or 3) stages, from the closed forms
    ///
    /// ```text
    /// s = 2 (order 4), r = √3:
    ///   c = 1/2 − r/6, 1/2 + r/6          b = 1/2, 1/2
    ///   A = | 1/4          1/4 − r/6 |
    ///       | 1/4 + r/6    1/4       |
    ///
    /// s = 3 (order 6), r = √15:
    ///   c = 1/2 − r/10, 1/2, 1/2 + r/10   b = 5/18, 4/9, 5/18
    ///   A = | 5/36          2/9 − r/15    5/36 − r/30 |
    ///       | 5/36 + r/24   2/9           5/36 − r/24 |
    ///       | 5/36 + r/30   2/9 + r/15    5/36        |
    /// ```
    ///
    /// (Hairer, Lubich & Wanner, GNI, Table II.1.3; Hairer & Wanner, Solving ODEs II, Table
    /// IV.5.2). `sqrt` is correctly rounded and each entry is one or two further correctly
    /// rounded operations, so every coefficient is within about 2e-17 of its exact value; mirror
    /// entries use the same expressions, so the symmetry `a[s−1−i][s−1−j] + a[i][j] = b[j]` and
    /// `b[i] = b[s−1−i]` survive rounding.
    pub(crate) fn gauss(stages: usize) -> Self {
        let mut t = Self { s: stages, a: [[0.0; MAX_STAGES]; MAX_STAGES], b: [0.0; MAX_STAGES], c: [0.0; MAX_STAGES] };
        if stages == 2 {
            let r = 3.0_f64.sqrt() / 6.0;
            t.c[..2].copy_from_slice(&[0.5 - r, 0.5 + r]);
            t.b[..2].copy_from_slice(&[0.5, 0.5]);
            t.a[0][..2].copy_from_slice(&[0.25, 0.25 - r]);
            t.a[1][..2].copy_from_slice(&[0.25 + r, 0.25]);
        } else {
            let r = 15.0_f64.sqrt();
            let (r10, r15, r24, r30) = (r / 10.0, r / 15.0, r / 24.0, r / 30.0);
            let (a0, a1) = (5.0 / 36.0, 2.0 / 9.0);
            t.c = [0.5 - r10, 0.5, 0.5 + r10];
            t.b = [5.0 / 18.0, 4.0 / 9.0, 5.0 / 18.0];
            t.a = [[a0, a1 - r15, a0 - r30], [a0 + r24, a1, a0 - r24], [a0 + r30, a1 + r15, a0]];
        }
        t
    }

    /// Coefficients `β` of the starting guess `Z_i⁰ = Σ_j β_ij Z_j` (GNI VIII.6.1): the
    /// previous step's collocation polynomial `w` (degree `s`, `w(0) = 0`, `w(c_j) = Z_j` in
    /// units of the previous step) extrapolated to the new stages,
    /// `Z_i⁰ = w(1 + ratio·c_i) − w(1)`, where `ratio` is the new step over the previous one.
    fn extrapolation(&self, ratio: f64) -> [[f64; MAX_STAGES]; MAX_STAGES] {
        let s = self.s;
        // Lagrange basis on the nodes {0, c_1, …, c_s}, for node c_j (vanishes at 0).
        let basis = |j: usize, theta: f64| {
            let mut v = theta / self.c[j];
            for m in 0..s {
                if m != j {
                    v *= (theta - self.c[m]) / (self.c[j] - self.c[m]);
                }
            }
            v
        };
        let mut beta = [[0.0; MAX_STAGES]; MAX_STAGES];
        for (i, row) in beta.iter_mut().enumerate().take(s) {
            let theta = 1.0 + ratio * self.c[i];
            for (j, entry) in row.iter_mut().enumerate().take(s) {
                *entry = basis(j, theta) - basis(j, 1.0);
            }
        }
        beta
    }
}

/// Gauss–Legendre collocation with its workspace for one dimension.
#[derive(Clone, Debug)]
pub struct GaussLegendre {
    options: GaussLegendreOptions,
    tableau: Tableau,
    /// The state `y_n` (rounded).
    y: Vec<f64>,
    /// Compensated summation: what rounding `y_n` has lost so far.
    carry: Vec<f64>,
    /// Stage increments `Z_i = Y_i − y_n`, stage after stage (`s·dim`).
    z: Vec<f64>,
    /// Second `s·dim` buffer, for the starting guess.
    z_guess: Vec<f64>,
    /// Stage derivatives `F_i = f(t + c_i h, y_n + Z_i)` (`s·dim`).
    f: Vec<f64>,
    /// Scratch: stage argument, later the new state.
    scratch: Vec<f64>,
    /// Scratch: the increment, later the new carry.
    increment: Vec<f64>,
    /// Length of the previous step, whose `Z` is in `z`; `None` at the start of a run.
    previous_step: Option<f64>,
}

impl GaussLegendre {
    /// Allocates the workspace for systems of dimension `dim`.
    pub fn new(dim: usize, options: GaussLegendreOptions) -> Result<Self, InvalidInput> {
        check_dim(dim)?;
        options.validate()?;
        let s = options.stages;
        Ok(Self {
            options,
            tableau: Tableau::gauss(s),
            y: vec![0.0; dim],
            carry: vec![0.0; dim],
            z: vec![0.0; s * dim],
            z_guess: vec![0.0; s * dim],
            f: vec![0.0; s * dim],
            scratch: vec![0.0; dim],
            increment: vec![0.0; dim],
            previous_step: None,
        })
    }

    /// The options this solver was created with.
    pub fn options(&self) -> &GaussLegendreOptions {
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
    /// Keep `output_interval` a multiple of `step` if the step must be exactly `step`.
    ///
    /// # Errors
    ///
    /// [`SolveError::InvalidInput`] for wrong dimensions or bad times, [`SolveError::Rhs`] if
    /// the system fails, [`SolveError::NonFinite`] if a stage derivative or the new state is not
    /// finite, [`SolveError::NotConverged`] if the stage equations do not converge within
    /// `max_iterations` (the step is too large for fixed-point iteration),
    /// [`SolveError::TooManySteps`] past `max_steps`; each with the last accepted state.
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

    /// Writes the starting guess for the stage increments of a step of length `h` into `z`.
    fn starting_guess<S: OdeSystem + ?Sized>(
        &mut self,
        system: &mut S,
        t: f64,
        h: f64,
        stats: &mut Stats,
    ) -> Result<(), SolveError<S::Error>> {
        let n = self.y.len();
        let s = self.tableau.s;
        match self.previous_step {
            Some(h_previous) => {
                let beta = self.tableau.extrapolation(h / h_previous);
                for i in 0..s {
                    let guess = &mut self.z_guess[i * n..(i + 1) * n];
                    guess.fill(0.0);
                    for j in 0..s {
                        let zj = &self.z[j * n..(j + 1) * n];
                        for (g, &v) in guess.iter_mut().zip(zj) {
                            *g += beta[i][j] * v;
                        }
                    }
                }
                core::mem::swap(&mut self.z, &mut self.z_guess);
            }
            None => {
                // No polynomial yet: follow the tangent, Z_i = c_i h f(t, y).
                let (f0, _) = self.f.split_at_mut(n);
                eval_checked(system, t, &self.y, f0, &self.y, stats)?;
                for i in 0..s {
                    let ch = self.tableau.c[i] * h;
                    for (z, &fv) in self.z[i * n..(i + 1) * n].iter_mut().zip(&self.f[..n]) {
                        *z = ch * fv;
                    }
                }
            }
        }
        Ok(())
    }
}

impl FixedStep for GaussLegendre {
    fn state(&self) -> &[f64] {
        &self.y
    }

    fn step_and_limit(&self) -> (f64, u64) {
        (self.options.step, self.options.max_steps)
    }

    fn restart(&mut self, y0: &[f64]) {
        self.y.copy_from_slice(y0);
        self.carry.fill(0.0);
        self.previous_step = None;
    }

    fn step<S: OdeSystem + ?Sized>(
        &mut self,
        system: &mut S,
        t: f64,
        h: f64,
        stats: &mut Stats,
    ) -> Result<(), SolveError<S::Error>> {
        let n = self.y.len();
        let tab = self.tableau;
        let s = tab.s;
        self.starting_guess(system, t, h, stats)?;

        // Fixed-point iteration Z ← h A F(Z) to round-off (HMR 2008): stop when the increment
        // is exactly zero or has stopped decreasing at round-off level. The norm scales each
        // component by |y| + |Z| so that coordinates and momenta of any size count alike.
        let mut previous_norm = f64::INFINITY;
        let mut converged = false;
        for _ in 0..self.options.max_iterations {
            for i in 0..s {
                for ((arg, &y), &z) in self.scratch.iter_mut().zip(&self.y).zip(&self.z[i * n..]) {
                    *arg = y + z;
                }
                let fi = &mut self.f[i * n..(i + 1) * n];
                eval_checked(system, t + tab.c[i] * h, &self.scratch, fi, &self.y, stats)?;
            }
            let mut norm: f64 = 0.0;
            for i in 0..s {
                for k in 0..n {
                    let mut sum = 0.0;
                    for j in 0..s {
                        sum += tab.a[i][j] * self.f[j * n + k];
                    }
                    let new = h * sum;
                    let old = self.z[i * n + k];
                    let change = (new - old).abs();
                    if change != 0.0 {
                        norm = norm.max(change / (self.y[k].abs() + new.abs().max(old.abs())));
                    }
                    self.z[i * n + k] = new;
                }
            }
            if norm == 0.0 || (norm >= previous_norm && previous_norm <= STALL_LIMIT) {
                converged = true;
                break;
            }
            previous_norm = norm;
        }
        if !converged {
            return Err(SolveError::NotConverged { t, y: self.y.clone() });
        }

        // The increment uses the last F, evaluated at Z equal to the final one up to round-off,
        // which saves the s evaluations a fresh F(Z) would cost (HMR 2008).
        for k in 0..n {
            let mut sum = 0.0;
            for j in 0..s {
                sum += tab.b[j] * self.f[j * n + k];
            }
            self.increment[k] = h * sum;
        }
        if self.options.compensated {
            // Kahan: the carry holds the low-order bits of y that did not fit into y itself.
            for k in 0..n {
                let with_carry = self.carry[k] + self.increment[k];
                let y_new = self.y[k] + with_carry;
                self.scratch[k] = y_new;
                self.increment[k] = with_carry + (self.y[k] - y_new);
            }
        } else {
            for k in 0..n {
                self.scratch[k] = self.y[k] + self.increment[k];
            }
        }
        if !self.scratch.iter().all(|v| v.is_finite()) {
            return Err(SolveError::NonFinite { t: t + h, y: self.y.clone() });
        }
        core::mem::swap(&mut self.y, &mut self.scratch);
        if self.options.compensated {
            core::mem::swap(&mut self.carry, &mut self.increment);
        }
        self.previous_step = Some(h);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The simplifying assumptions that make the s-stage Gauss method of order 2s:
    /// B(2s): Σ b_i c_i^(k−1) = 1/k (k ≤ 2s), C(s): Σ_j a_ij c_j^(k−1) = c_i^k / k (k ≤ s),
    /// D(s): Σ_i b_i c_i^(k−1) a_ij = b_j (1 − c_j^k) / k (k ≤ s); and symplecticity
    /// b_i a_ij + b_j a_ji = b_i b_j.
    #[test]
    fn tableaux_satisfy_order_and_symplecticity_conditions() {
        for s in [2, 3] {
            let t = Tableau::gauss(s);
            for k in 1..=2 * s {
                let sum: f64 = (0..s).map(|i| t.b[i] * t.c[i].powi(k as i32 - 1)).sum();
                assert!((sum - 1.0 / k as f64).abs() < 1e-15, "B({k}) for s = {s}");
            }
            for i in 0..s {
                for k in 1..=s {
                    let sum: f64 = (0..s).map(|j| t.a[i][j] * t.c[j].powi(k as i32 - 1)).sum();
                    let exact = t.c[i].powi(k as i32) / k as f64;
                    assert!((sum - exact).abs() < 1e-15, "C({k}), row {i}, s = {s}");
                }
            }
            for j in 0..s {
                for k in 1..=s {
                    let sum: f64 = (0..s).map(|i| t.b[i] * t.c[i].powi(k as i32 - 1) * t.a[i][j]).sum();
                    let exact = t.b[j] * (1.0 - t.c[j].powi(k as i32)) / k as f64;
                    assert!((sum - exact).abs() < 1e-15, "D({k}), column {j}, s = {s}");
                }
            }
            for i in 0..s {
                for j in 0..s {
                    let defect = t.b[i] * t.a[i][j] + t.b[j] * t.a[j][i] - t.b[i] * t.b[j];
                    assert!(defect.abs() < 1e-16, "symplecticity ({i}, {j}), s = {s}");
                    let mirror = t.a[s - 1 - i][s - 1 - j] + t.a[i][j] - t.b[j];
                    assert!(mirror.abs() < 1e-16, "symmetry ({i}, {j}), s = {s}");
                }
            }
        }
    }

    /// The extrapolated guess reproduces any polynomial of degree ≤ s through 0 exactly.
    #[test]
    fn extrapolation_is_exact_for_polynomials_of_degree_s() {
        for s in [2, 3] {
            let t = Tableau::gauss(s);
            let w = |theta: f64| theta + 0.3 * theta * theta - 0.7 * theta.powi(s as i32);
            for ratio in [1.0, 0.5, 0.8] {
                let beta = t.extrapolation(ratio);
                for i in 0..s {
                    let guess: f64 = (0..s).map(|j| beta[i][j] * w(t.c[j])).sum();
                    let exact = w(1.0 + ratio * t.c[i]) - w(1.0);
                    assert!((guess - exact).abs() < 1e-13, "s = {s}, ratio {ratio}, i = {i}");
                }
            }
        }
    }

    #[test]
    fn stages_other_than_2_or_3_are_rejected() {
        for stages in [0, 1, 4] {
            let options = GaussLegendreOptions { stages, ..Default::default() };
            assert!(GaussLegendre::new(2, options).is_err());
        }
    }
}
