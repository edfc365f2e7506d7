//! The Cartesian chart on SIMD lanes: Newton's equations of [`crate::cartesian_system`] for
//! `T::LANES` trajectories at once, the right-hand side of [`crate::integrate::Dop853Lanes`].
//!
//! The state layout is [`CartesianSystem`]'s (`6·NA` components: positions, then velocities,
//! relative to the centre of mass). The gradient is the molecule's generated lane form
//! [`Molecule::cartesian_potential_gradient_lanes`]: the `f64` gradient's operations, so each
//! lane computes the numbers of [`CartesianSystem`]'s right-hand side to round-off (`T`'s
//! transcendental functions are polynomials within 2 ulp of libm). A lane whose gradient is not finite (an angle at
//! exactly π) takes [`CartesianSystem`]'s symmetric average across that point, lane by lane; a
//! lane whose state or derivative is still not finite fails. No allocation.

use nalgebra::SMatrix;

use crate::cartesian_system::{CartesianError, CartesianSystem};
use crate::integrate::LaneSystem;
use crate::lanes::{Real, finite_mask};
use crate::molecule::Molecule;

/// Newton's equations of a molecule in the Cartesian chart, `T::LANES` trajectories at once.
#[derive(Clone, Copy, Debug)]
pub struct CartesianLanes<'a, M: ?Sized, const N: usize, const NA: usize> {
    scalar: CartesianSystem<'a, M, N, NA>,
    inverse_masses: [f64; NA],
}

impl<'a, M, const N: usize, const NA: usize> CartesianLanes<'a, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The lane system of `molecule`; fails if it has no Cartesian potential or no lane form of
    /// its gradient.
    pub fn new(molecule: &'a M) -> Result<Self, CartesianError> {
        let scalar = CartesianSystem::new(molecule)?;
        if !available(molecule) {
            return Err(CartesianError::NoCartesianPotential { molecule: molecule.name() });
        }
        Ok(Self { scalar, inverse_masses: molecule.masses().map(|m| 1.0 / m) })
    }

    /// `6·NA`.
    pub const DIM: usize = 6 * NA;
}

/// Whether `molecule` has a generated lane form of its Cartesian gradient (what
/// [`CartesianLanes`] needs).
pub fn available<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize>(molecule: &M) -> bool {
    let x = [[0.0f64; 3]; NA];
    let mut g = [[0.0f64; 3]; NA];
    molecule.cartesian_potential_gradient_lanes(&x, &mut g).is_some()
}

impl<M, T, const N: usize, const NA: usize> LaneSystem<T> for CartesianLanes<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
    T: Real,
{
    fn dim(&self) -> usize {
        6 * NA
    }

    #[inline]
    fn rhs(&mut self, _t: T, y: &[T], dydt: &mut [T]) -> u32 {
        if y.len() != 6 * NA || dydt.len() != 6 * NA {
            return 0;
        }
        let zero = T::splat(0.0);
        let x: [[T; 3]; NA] = core::array::from_fn(|i| [y[3 * i], y[3 * i + 1], y[3 * i + 2]]);
        let mut grad = [[zero; 3]; NA];
        if self.scalar.molecule().cartesian_potential_gradient_lanes(&x, &mut grad).is_none() {
            return 0;
        }
        let mut ok = T::ALL;
        let kinked = !finite_mask(grad.as_flattened()) & T::ALL;
        if kinked != 0 {
            for lane in (0..T::LANES).filter(|l| kinked & (1 << l) != 0) {
                let xs = SMatrix::<f64, 3, NA>::from_fn(|a, i| x[i][a].lane(lane));
                let mut g = SMatrix::<f64, 3, NA>::zeros();
                match self.scalar.gradient(&xs, &mut g) {
                    Ok(()) => {
                        for (i, row) in grad.iter_mut().enumerate() {
                            for (a, v) in row.iter_mut().enumerate() {
                                v.set_lane(lane, g[(a, i)]);
                            }
                        }
                    }
                    Err(_) => ok &= !(1 << lane),
                }
            }
        }
        dydt[..3 * NA].copy_from_slice(&y[3 * NA..6 * NA]);
        for (i, row) in grad.iter().enumerate() {
            let inverse_mass = T::splat(self.inverse_masses[i]);
            for (a, &g) in row.iter().enumerate() {
                dydt[3 * NA + 3 * i + a] = -g * inverse_mass;
            }
        }
        ok & finite_mask(y) & finite_mask(dydt)
    }
}
