//! Reference problems with known solutions, for testing integrators: the unit tests of the
//! methods and the integration tests in `runtime/tests/` use the same definitions.

use core::convert::Infallible;

use super::OdeSystem;

/// The Kepler problem `q'' = −q/|q|³` as a first-order system `(q1, q2, p1, p2)`; started at
/// pericentre with eccentricity `e` its period is 2π.
pub struct Kepler;

impl Kepler {
    /// The state at pericentre for eccentricity `e`.
    pub fn initial(e: f64) -> [f64; 4] {
        [1.0 - e, 0.0, 0.0, ((1.0 + e) / (1.0 - e)).sqrt()]
    }

    /// The energy `½|p|² − 1/|q|`.
    pub fn energy(y: &[f64]) -> f64 {
        0.5 * (y[2] * y[2] + y[3] * y[3]) - 1.0 / y[0].hypot(y[1])
    }
}

impl OdeSystem for Kepler {
    type Error = Infallible;
    fn dim(&self) -> usize {
        4
    }
    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
        let r = y[0].hypot(y[1]);
        let r3 = r * r * r;
        dydt[0] = y[2];
        dydt[1] = y[3];
        dydt[2] = -y[0] / r3;
        dydt[3] = -y[1] / r3;
        Ok(())
    }
}

/// The non-autonomous scalar problem `y' = y·cos t`, `y(0) = 1`, with the exact solution
/// `y = exp(sin t)`.
pub struct ExpSin;

impl ExpSin {
    /// The exact solution from `y(0) = 1`.
    pub fn exact(t: f64) -> f64 {
        t.sin().exp()
    }
}

impl OdeSystem for ExpSin {
    type Error = Infallible;
    fn dim(&self) -> usize {
        1
    }
    fn rhs(&mut self, t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
        dydt[0] = y[0] * t.cos();
        Ok(())
    }
}
