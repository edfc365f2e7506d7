//! The Cartesian cross-check: Newton's equations for the atoms in the lab frame, independent of
//! the Hamiltonian's kinetic matrices, and a driver that compares them with a Hamiltonian
//! trajectory started from the same lab-frame initial condition.
//!
//! The two sides share only the masses and the potential `U(q)` (they must simulate the same
//! physics): the Cartesian forces are `F_i = −Σ_k ∂U/∂q_k ∂q_k/∂x_i`, with `q(x)` a plain
//! function of the lab positions (distances, angles, dihedrals from [`super::internal_coordinates`])
//! and `∂q/∂x` by forward-mode automatic differentiation. Nothing of the body frame, the Euler
//! angles, W, G or the kinetic matrices enters. Agreement of positions to 1e-8 bohr over several
//! vibrational periods, with and without rotation, therefore checks the whole Hamiltonian path
//! (eqs. 1–16, the G matrices, the generated kinetic matrices and their derivatives) and the
//! frame conversion [`to_lab`] at once.
//!
//! To cross-check another molecule: add its `q_of_x` (coordinates in the molecule's order and
//! units: bohr and rad) to `internal_coordinates.rs`, then call [`cross_check`] with an initial
//! [`PhaseState`] (see `tests/cartesian.rs`).
#![allow(dead_code)]

use std::convert::Infallible;
use std::ops::ControlFlow;

use super::internal_coordinates::{Dual, V3, jacobian};
use rovib::runtime::Molecule;
use rovib::runtime::frames::{CentreOfMass, LabState, to_lab, to_lab_body};
use rovib::runtime::hamiltonian::fast::{BodyState, ReducedSystem, Reduction};
use rovib::runtime::hamiltonian::{HamiltonianSystem, PhaseState, hamiltonian};
use rovib::runtime::integrate::{Dop853Options, Method, OdeSystem, Stats, solve};
use rovib::runtime::nalgebra::{SMatrix, SVector, Vector3};

/// Internal coordinates from lab positions, generic enough for forward-mode differentiation.
pub type QOfX = fn(&[V3<Dual>]) -> Vec<Dual>;

/// Newton's equations `m_i ẍ_i = −∂U(q(x))/∂x_i` on the flat state `[x, v]` of
/// [`LabState::write_to`] (dimension `6·NA`).
pub struct CartesianSystem<'a, M, const N: usize, const NA: usize> {
    molecule: &'a M,
    masses: [f64; NA],
    q_of_x: QOfX,
}

impl<'a, M: Molecule<N, NA>, const N: usize, const NA: usize> CartesianSystem<'a, M, N, NA> {
    /// The system of `molecule`'s potential with `masses` (electron masses) and coordinates
    /// `q_of_x` (which must return the molecule's N coordinates, in its order).
    pub fn new(molecule: &'a M, masses: [f64; NA], q_of_x: QOfX) -> Self {
        Self { molecule, masses, q_of_x }
    }

    pub fn masses(&self) -> &[f64; NA] {
        &self.masses
    }

    /// `q(x)` of lab positions (column i is atom i).
    pub fn q(&self, x: &SMatrix<f64, 3, NA>) -> SVector<f64, N> {
        let (q, _) = jacobian(&atoms(x), self.q_of_x);
        assert_eq!(q.len(), N, "q_of_x returns {} coordinates, {} has {N}", q.len(), self.molecule.name());
        SVector::from_column_slice(&q)
    }

    /// The forces `F_i = −Σ_k ∂U/∂q_k ∂q_k/∂x_i` (column i is atom i) and `U`.
    pub fn forces(&self, x: &SMatrix<f64, 3, NA>) -> (SMatrix<f64, 3, NA>, f64) {
        let (q, dq_dx) = jacobian(&atoms(x), self.q_of_x);
        assert_eq!(q.len(), N, "q_of_x returns {} coordinates, {} has {N}", q.len(), self.molecule.name());
        let mut du = SVector::<f64, N>::zeros();
        let u = self.molecule.potential_gradient(&SVector::from_column_slice(&q), &mut du);
        let f = SMatrix::from_fn(|axis, i| -(0..N).map(|k| du[k] * dq_dx[k][i][axis]).sum::<f64>());
        (f, u)
    }

    /// `E = ½ Σ m_i |v_i|² + U(q(x))` of a flat state, hartree.
    pub fn energy(&self, y: &[f64]) -> f64 {
        let lab = LabState::<NA>::read_from(y);
        lab.kinetic_energy(&self.masses) + self.molecule.potential(&self.q(&lab.positions))
    }

    /// The angular momentum about the centre of mass of a flat state, ħ.
    pub fn angular_momentum(&self, y: &[f64]) -> Vector3<f64> {
        LabState::<NA>::read_from(y).angular_momentum(&self.masses)
    }
}

fn atoms<const NA: usize>(x: &SMatrix<f64, 3, NA>) -> Vec<[f64; 3]> {
    (0..NA).map(|i| [x[(0, i)], x[(1, i)], x[(2, i)]]).collect()
}

impl<M: Molecule<N, NA>, const N: usize, const NA: usize> OdeSystem for CartesianSystem<'_, M, N, NA> {
    type Error = Infallible;

    fn dim(&self) -> usize {
        6 * NA
    }

    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
        let lab = LabState::<NA>::read_from(y);
        let (f, _) = self.forces(&lab.positions);
        let (dx, dv) = dydt.split_at_mut(3 * NA);
        dx.copy_from_slice(lab.velocities.as_slice());
        for i in 0..NA {
            for axis in 0..3 {
                dv[3 * i + axis] = f[(axis, i)] / self.masses[i];
            }
        }
        Ok(())
    }
}

/// How to run a cross-check.
#[derive(Copy, Clone, Debug)]
pub struct CrossCheck {
    /// End time, ħ/E_h (start at 0).
    pub t_end: f64,
    /// Comparison interval, ħ/E_h.
    pub output_interval: f64,
    /// The integrator of the Hamiltonian side.
    pub hamiltonian: Method,
    /// The integrator of the Cartesian side.
    pub cartesian: Method,
    /// Which Hamiltonian formulation to integrate.
    pub formulation: Formulation,
}

/// The Hamiltonian side of a cross-check.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Formulation {
    /// The seed path in Euler angles (`HamiltonianSystem`): singular at θ = 0, π.
    Seed,
    /// The production path: body-frame J and a unit quaternion on the fast right-hand side
    /// (`ReducedSystem` with nothing reduced): regular at every orientation.
    Production,
}

impl CrossCheck {
    /// DOP853 at the same tolerances on both sides.
    pub fn dop853(t_end: f64, output_interval: f64, rtol: f64, atol: f64) -> Self {
        let method = Method::Dop853(Dop853Options { rtol, atol, ..Dop853Options::default() });
        Self { t_end, output_interval, hamiltonian: method, cartesian: method, formulation: Formulation::Seed }
    }

    /// The same, integrating the production path.
    pub fn production(self) -> Self {
        Self { formulation: Formulation::Production, ..self }
    }

    /// The same with another integrator on the Hamiltonian side only, so that a method (DOP853
    /// at a looser tolerance, Gauss–Legendre, RK4) is judged against a Cartesian reference that
    /// keeps the tight settings.
    pub fn with_hamiltonian_method(self, method: Method) -> Self {
        Self { hamiltonian: method, ..self }
    }
}

/// What a cross-check measured.
#[derive(Clone, Debug)]
pub struct CrossCheckReport<const N: usize> {
    /// The comparison times.
    pub times: Vec<f64>,
    /// max over output times and atoms of |x_i(Hamiltonian) − x_i(Cartesian)|, bohr.
    pub max_position_difference: f64,
    /// The same for velocities, bohr per ħ/E_h.
    pub max_velocity_difference: f64,
    /// |q(x(0)) − q| at the start: checks that `q_of_x` matches the parametrization.
    pub initial_q_mismatch: f64,
    /// max |E(t) − E(0)| of the Cartesian run (`½ Σ m v² + U`) and of the Hamiltonian run (H),
    /// hartree.
    pub cartesian_energy_drift: f64,
    pub hamiltonian_energy_drift: f64,
    /// max |L(t) − L(0)| of the Cartesian run, ħ, and |L(0)|.
    pub cartesian_angular_momentum_drift: f64,
    pub angular_momentum: f64,
    /// max over output times and atoms of |x_i(t) − x_i(0) − V t|: how far the atoms move (so
    /// that the position differences can be judged against it), bohr.
    pub max_displacement: f64,
    /// min |sin θ| over the Hamiltonian run's outputs.
    pub min_sin_theta: f64,
    /// The closest approach of θ to 0 or π at the comparison times, rad.
    pub min_theta: f64,
    /// q at each output time (Hamiltonian run).
    pub q: Vec<SVector<f64, N>>,
    /// Integrator work on each side.
    pub hamiltonian_stats: Stats,
    pub cartesian_stats: Stats,
}

/// Integrates `initial` (with centre of mass `com`) with the Hamiltonian (seed path) and the
/// lab-frame Cartesian equations from the same [`to_lab`] initial condition, with the methods of
/// `settings`, and compares the lab-frame positions and velocities at every output
/// time.
pub fn cross_check<M, const N: usize, const NA: usize>(
    molecule: &M,
    q_of_x: QOfX,
    initial: &PhaseState<N>,
    com: &CentreOfMass,
    settings: &CrossCheck,
) -> CrossCheckReport<N>
where
    M: Molecule<N, NA>,
{
    cross_check_with_masses(molecule, molecule.masses(), q_of_x, initial, com, settings)
}

/// [`cross_check`] with other masses on the Cartesian side: a negative control, to show how
/// large a difference a given error in the physics makes.
pub fn cross_check_with_masses<M, const N: usize, const NA: usize>(
    molecule: &M,
    cartesian_masses: [f64; NA],
    q_of_x: QOfX,
    initial: &PhaseState<N>,
    com: &CentreOfMass,
    settings: &CrossCheck,
) -> CrossCheckReport<N>
where
    M: Molecule<N, NA>,
{
    // The Hamiltonian trajectory, kept as body-formulation states at the output times (the
    // seed's phase states converted; the production path's directly, so that nothing on this
    // side goes through Euler angles).
    let mut states: Vec<BodyState<N>> = Vec::new();
    let mut energies = Vec::new();
    let mut times = Vec::new();
    let failed = |e: &dyn std::error::Error| -> ! {
        panic!("{}: Hamiltonian run failed: {e} ({:?})", molecule.name(), e.source())
    };
    let hamiltonian_stats = match settings.formulation {
        Formulation::Seed => {
            let mut system = HamiltonianSystem::new(molecule);
            let mut y0 = vec![0.0; PhaseState::<N>::DIM];
            initial.write_to(&mut y0).unwrap();
            solve(
                &mut system,
                &settings.hamiltonian,
                0.0,
                &y0,
                settings.t_end,
                settings.output_interval,
                &mut |t: f64, y: &[f64]| {
                    let s = PhaseState::<N>::read_from(y).unwrap();
                    times.push(t);
                    states.push(BodyState::from_phase(&s).unwrap());
                    energies.push(hamiltonian(molecule, &s).unwrap());
                    ControlFlow::Continue(())
                },
            )
            .unwrap_or_else(|e| failed(&e))
        }
        Formulation::Production => {
            let mut system = ReducedSystem::new(molecule, Reduction::none(), initial);
            let mut y0 = vec![0.0; system.dim()];
            system.reduce(initial, &mut y0).unwrap();
            let copy = system;
            solve(
                &mut system,
                &settings.hamiltonian,
                0.0,
                &y0,
                settings.t_end,
                settings.output_interval,
                &mut |t: f64, y: &[f64]| {
                    times.push(t);
                    states.push(copy.expand_body(y).unwrap());
                    energies.push(copy.energy(y).unwrap());
                    ControlFlow::Continue(())
                },
            )
            .unwrap_or_else(|e| failed(&e))
        }
    };

    // The Cartesian trajectory from the same lab-frame state.
    let lab0 = to_lab(molecule, initial, com).unwrap();
    let mut cartesian = CartesianSystem::new(molecule, cartesian_masses, q_of_x);
    let initial_q_mismatch = (cartesian.q(&lab0.positions) - initial.q).amax();
    let mut x0 = vec![0.0; LabState::<NA>::DIM];
    lab0.write_to(&mut x0);
    let mut labs = Vec::new();
    let cartesian_stats = solve(
        &mut cartesian,
        &settings.cartesian,
        0.0,
        &x0,
        settings.t_end,
        settings.output_interval,
        &mut |_t: f64, y: &[f64]| {
            labs.push(y.to_vec());
            ControlFlow::Continue(())
        },
    )
    .unwrap_or_else(|e| panic!("{}: Cartesian run failed: {e}", molecule.name()));
    assert_eq!(labs.len(), states.len());

    let e0_cart = cartesian.energy(&x0);
    let e0_ham = hamiltonian(molecule, initial).unwrap();
    let l0 = cartesian.angular_momentum(&x0);
    let mut report = CrossCheckReport {
        times,
        max_position_difference: 0.0,
        max_velocity_difference: 0.0,
        initial_q_mismatch,
        cartesian_energy_drift: 0.0,
        hamiltonian_energy_drift: 0.0,
        cartesian_angular_momentum_drift: 0.0,
        angular_momentum: l0.norm(),
        max_displacement: 0.0,
        min_sin_theta: f64::INFINITY,
        q: states.iter().map(|s| s.q).collect(),
        min_theta: f64::INFINITY,
        hamiltonian_stats,
        cartesian_stats,
    };
    // Compare with the centre of mass advanced to each output time.
    for (((t, state), energy), y) in report.times.clone().iter().zip(&states).zip(&energies).zip(&labs) {
        let moved = CentreOfMass { position: com.position + com.velocity * *t, velocity: com.velocity };
        let from_h = to_lab_body(molecule, state, &moved).unwrap();
        let lab = LabState::<NA>::read_from(y);
        report.max_position_difference = report.max_position_difference.max((from_h.positions - lab.positions).amax());
        report.max_velocity_difference =
            report.max_velocity_difference.max((from_h.velocities - lab.velocities).amax());
        report.cartesian_energy_drift = report.cartesian_energy_drift.max((cartesian.energy(y) - e0_cart).abs());
        report.hamiltonian_energy_drift = report.hamiltonian_energy_drift.max((energy - e0_ham).abs());
        report.cartesian_angular_momentum_drift =
            report.cartesian_angular_momentum_drift.max((cartesian.angular_momentum(y) - l0).amax());
        let drift = SMatrix::<f64, 3, NA>::from_fn(|axis, _| com.velocity[axis] * *t);
        report.max_displacement = report.max_displacement.max((lab.positions - lab0.positions - drift).amax());
        // θ is the angle between the body and lab z axes: cos θ = R₃₃ (from the rotation itself,
        // accurate near 0 through the length of the cross product).
        let r = state.rotation();
        let theta = r[(0, 2)].hypot(r[(1, 2)]).atan2(r[(2, 2)]);
        report.min_sin_theta = report.min_sin_theta.min(theta.sin().abs());
        report.min_theta = report.min_theta.min(theta.min(std::f64::consts::PI - theta));
    }
    report
}

/// The number of full oscillations of `signal` (upward crossings of its mean, with a hysteresis
/// of a quarter of its half-range so that small ripples do not count).
pub fn oscillations(signal: &[f64]) -> usize {
    let mean = signal.iter().sum::<f64>() / signal.len() as f64;
    let (lo, hi) = signal.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &s| (lo.min(s), hi.max(s)));
    let band = 0.25 * 0.5 * (hi - lo);
    let mut below = signal[0] < mean;
    let mut crossings: usize = 0;
    for &s in signal {
        if below && s > mean + band {
            below = false;
            crossings += 1;
        } else if !below && s < mean - band {
            below = true;
        }
    }
    // Crossings count starts of oscillations; the first may be cut off at t = 0.
    crossings.saturating_sub(1)
}
