//! Harmonic normal modes at a minimum of the potential, by Wilson's GF method.
//!
//! # Method
//!
//! At a stationary point `q₀` of `U` the small-amplitude vibrations (at zero angular momentum)
//! have the kinetic energy `T = ½ q̇ᵀ G⁻¹ q̇` and the potential `U₀ + ½ δqᵀ F δq`, with
//!
//! * `F` the Hessian of `U` in q: central differences (fourth order, step
//!   [`HESSIAN_STEP`] bohr or rad) of the generated gradient [`Molecule::potential_gradient`],
//!   symmetrized;
//! * `G = G22(q₀) = (a − Aᵀ I⁻¹ A)⁻¹`, the vibrational block of the inverse kinetic metric
//!   ([`InverseMetric`]): Wilson's G matrix, with the rotation split off.
//!
//! The normal modes solve `G F l_k = ω_k² l_k`. With `G = C Cᵀ` (Cholesky) and the symmetric
//! eigenproblem `Cᵀ F C v_k = ω_k² v_k`, the mode vectors are `l_k = C v_k`, normalised so that
//! `Lᵀ G⁻¹ L = 1` and `Lᵀ F L = diag(ω_k²)`: `δq = L Q` turns the harmonic energy into
//! `Σ_k ½ (Q̇_k² + ω_k² Q_k²)` in mass-weighted normal coordinates `Q` (bohr·√m_e).
//!
//! # Units
//!
//! `ω_k` in hartree (atomic units, ħ = 1: angular frequency in E_h/ħ, which is also the quantum
//! `ħω_k` in hartree); wavenumbers in cm⁻¹ (`ω_k` times [`HARTREE_IN_WAVENUMBERS`]).
//!
//! # Stationarity and minimality
//!
//! A point is accepted as stationary when the Newton step to the stationary point,
//! `|F⁻¹ ∇U|`, is at most [`STATIONARY_TOLERANCE`] (bohr or rad) in every coordinate, i.e. the
//! true stationary point of the quadratic model is closer than that. [`stationary_point`]
//! finds one by Newton's method from a starting geometry (the reference geometry of a
//! definition need not be the equilibrium: ch4's is not). A stationary point where some
//! `ω_k² < 0` is a saddle, not a minimum: [`NormalModes::at`] fails with
//! [`ModesError::NotMinimum`], naming the mode's imaginary wavenumber and the coordinates that
//! dominate it, since normal-mode sampling about a saddle is meaningless.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

use crate::hamiltonian::InverseMetric;
use crate::molecule::{KineticMatrices, Molecule};
use crate::units::HARTREE_IN_WAVENUMBERS;

/// Step of the central differences of the gradient, bohr or rad.
pub const HESSIAN_STEP: f64 = 1e-4;

/// The largest Newton step (bohr or rad, per coordinate) at which a point counts as stationary.
pub const STATIONARY_TOLERANCE: f64 = 1e-6;

/// Why normal modes could not be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ModesError {
    /// The point is not stationary.
    #[error(
        "the geometry is not a stationary point of the potential: ∂U/∂{coordinate} = {gradient:e} hartree per unit, \
         the stationary point is about {distance:.2e} (bohr or rad) away along {coordinate}"
    )]
    NotStationary {
        /// The coordinate with the largest Newton step.
        coordinate: &'static str,
        /// Its gradient component, hartree per bohr or rad.
        gradient: f64,
        /// The Newton step along it.
        distance: f64,
    },
    /// The point is a saddle or a maximum.
    #[error(
        "the stationary point is not a minimum: normal mode {mode} has negative curvature (imaginary wavenumber \
         {wavenumber:.1}i cm⁻¹), mostly along {coordinates}"
    )]
    NotMinimum {
        /// The 0-based index of the mode (ascending ω²).
        mode: usize,
        /// |ω| of the mode in cm⁻¹ (the wavenumber is imaginary).
        wavenumber: f64,
        /// The coordinates with the largest components of the mode vector.
        coordinates: String,
    },
    /// Newton's method did not find a stationary point, or the Hessian or metric is singular.
    #[error("{0}")]
    Failed(String),
}

/// The harmonic normal modes at a minimum `q₀` (see the module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct NormalModes<const N: usize> {
    /// The minimum, bohr and rad.
    pub q0: SVector<f64, N>,
    /// `U(q₀)`, hartree.
    pub u0: f64,
    /// The Hessian `F` of U at q₀, hartree per bohr² (or rad², bohr·rad).
    pub hessian: SMatrix<f64, N, N>,
    /// Wilson's G matrix `G22(q₀)`.
    pub g: SMatrix<f64, N, N>,
    /// Angular frequencies `ω_k`, hartree (ħ = 1), ascending.
    pub omega: SVector<f64, N>,
    /// Mode vectors in q: column k is `l_k`, with `Lᵀ G⁻¹ L = 1` (δq = L Q).
    pub vectors: SMatrix<f64, N, N>,
}

impl<const N: usize> NormalModes<N> {
    /// The normal modes at `q0`, which must be a stationary point and a minimum.
    pub fn at<M, const NA: usize>(molecule: &M, q0: &SVector<f64, N>) -> Result<Self, ModesError>
    where
        M: Molecule<N, NA> + ?Sized,
    {
        let coords = molecule.coordinates();
        let hessian = hessian(molecule, q0);
        let mut grad = SVector::zeros();
        let u0 = molecule.potential_gradient(q0, &mut grad);
        if !u0.is_finite() || grad.iter().any(|g| !g.is_finite()) {
            return Err(ModesError::Failed(format!(
                "the potential or its gradient is not finite at q = {:?}",
                q0.as_slice()
            )));
        }
        if N == 0 {
            // A rigid molecule has no vibration: no modes (and no metric block to factor).
            let zero = SMatrix::<f64, N, N>::zeros();
            return Ok(Self { q0: *q0, u0, hessian, g: zero, omega: SVector::zeros(), vectors: zero });
        }
        let step = newton_step(&hessian, &grad)?;
        if let Some(k) = (0..N).max_by(|&a, &b| step[a].abs().total_cmp(&step[b].abs()))
            && step[k].abs() > STATIONARY_TOLERANCE
        {
            return Err(ModesError::NotStationary {
                coordinate: coords[k].name,
                gradient: grad[k],
                distance: step[k].abs(),
            });
        }
        let mut k = KineticMatrices::default();
        molecule.kinetic(q0, &mut k);
        let g = InverseMetric::new(&k, q0)
            .map_err(|e| ModesError::Failed(format!("no G matrix at the stationary point: {e}")))?
            .g
            .g22;
        let c =
            g.cholesky().ok_or_else(|| ModesError::Failed("Wilson's G matrix is not positive definite".into()))?.l();
        let s = c.transpose() * hessian * c;
        let s = DMatrix::from_fn(N, N, |i, j| 0.5 * (s[(i, j)] + s[(j, i)]));
        let eig = s.symmetric_eigen();
        let mut order: Vec<usize> = (0..N).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let mut omega = SVector::<f64, N>::zeros();
        let mut vectors = SMatrix::<f64, N, N>::zeros();
        for (col, &i) in order.iter().enumerate() {
            let v = SVector::<f64, N>::from_fn(|r, _| eig.eigenvectors[(r, i)]);
            let l: SVector<f64, N> = c * v;
            let lambda = eig.eigenvalues[i];
            if lambda <= 0.0 {
                let mut idx: Vec<usize> = (0..N).collect();
                idx.sort_by(|&a, &b| l[b].abs().total_cmp(&l[a].abs()));
                let names: Vec<String> =
                    idx.iter().take(2.min(N)).map(|&j| format!("{} ({:+.3})", coords[j].name, l[j])).collect();
                return Err(ModesError::NotMinimum {
                    mode: col,
                    wavenumber: (-lambda).sqrt() * HARTREE_IN_WAVENUMBERS,
                    coordinates: names.join(", "),
                });
            }
            omega[col] = lambda.sqrt();
            vectors.set_column(col, &l);
        }
        Ok(Self { q0: *q0, u0, hessian, g, omega, vectors })
    }

    /// Harmonic wavenumbers in cm⁻¹, ascending.
    pub fn wavenumbers(&self) -> SVector<f64, N> {
        self.omega * HARTREE_IN_WAVENUMBERS
    }

    /// The harmonic zero-point energy `½ Σ ħω_k`, hartree.
    pub fn zero_point_energy(&self) -> f64 {
        0.5 * self.omega.sum()
    }

    /// The normal coordinates `Q = L⁻¹ (q − q₀)` (or velocities `L⁻¹ q̇`): `L⁻¹ = Lᵀ G⁻¹`.
    pub fn to_normal(&self, dq: &SVector<f64, N>) -> SVector<f64, N> {
        // Lᵀ G⁻¹ L = 1 ⇒ L⁻¹ = Lᵀ G⁻¹.
        let g_inv_dq = self.g.cholesky().map(|c| c.solve(dq)).unwrap_or_else(SVector::zeros);
        self.vectors.transpose() * g_inv_dq
    }
}

/// The Hessian of U at q: fourth-order central differences of the generated gradient with step
/// [`HESSIAN_STEP`], symmetrized. Hartree per (bohr or rad)².
pub fn hessian<M, const N: usize, const NA: usize>(molecule: &M, q: &SVector<f64, N>) -> SMatrix<f64, N, N>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut h = SMatrix::<f64, N, N>::zeros();
    for k in 0..N {
        let grad_at = |t: f64| {
            let mut x = *q;
            x[k] += t;
            let mut g = SVector::<f64, N>::zeros();
            molecule.potential_gradient(&x, &mut g);
            g
        };
        let s = HESSIAN_STEP;
        let column = (grad_at(-2.0 * s) - 8.0 * grad_at(-s) + 8.0 * grad_at(s) - grad_at(2.0 * s)) / (12.0 * s);
        h.set_column(k, &column);
    }
    (h + h.transpose()) * 0.5
}

fn newton_step<const N: usize>(f: &SMatrix<f64, N, N>, grad: &SVector<f64, N>) -> Result<SVector<f64, N>, ModesError> {
    if N == 0 {
        // A rigid molecule: no coordinate to move, every point is stationary.
        return Ok(SVector::zeros());
    }
    let fd = DMatrix::from_fn(N, N, |i, j| f[(i, j)]);
    let gd = DVector::from_fn(N, |i, _| grad[i]);
    fd.lu().solve(&gd).filter(|s| s.iter().all(|x| x.is_finite())).map(|s| SVector::from_fn(|i, _| s[i])).ok_or_else(
        || ModesError::Failed("the Hessian of the potential is singular: no isolated stationary point".into()),
    )
}

/// A stationary point of U found by Newton's method from `start` (at most 50 steps; a step is
/// limited to 0.2 bohr or rad per coordinate), converged when the Newton step is below
/// [`STATIONARY_TOLERANCE`] / 100. It may be a saddle: [`NormalModes::at`] tells.
pub fn stationary_point<M, const N: usize, const NA: usize>(
    molecule: &M,
    start: &SVector<f64, N>,
) -> Result<SVector<f64, N>, ModesError>
where
    M: Molecule<N, NA> + ?Sized,
{
    let mut q = *start;
    if N == 0 {
        return Ok(q);
    }
    for _ in 0..50 {
        let mut grad = SVector::zeros();
        let u = molecule.potential_gradient(&q, &mut grad);
        if !u.is_finite() || grad.iter().any(|g| !g.is_finite()) {
            return Err(ModesError::Failed(format!(
                "the potential is not finite at q = {:?} while looking for its minimum",
                q.as_slice()
            )));
        }
        let step = newton_step(&hessian(molecule, &q), &grad)?;
        let largest = step.amax();
        q -= step * (0.2 / largest).min(1.0);
        if largest <= 1e-2 * STATIONARY_TOLERANCE {
            return Ok(q);
        }
    }
    Err(ModesError::Failed(format!(
        "Newton's method found no stationary point of the potential within 50 steps from q = {:?}",
        start.as_slice()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-written bent triatomic with two coordinates would need the whole trait; the
    /// integration tests (tests/ensembles/sampling.rs) check the modes of the generated molecules. Here:
    /// the Newton step of a quadratic is exact.
    #[test]
    fn newton_step_of_a_quadratic() {
        let f = SMatrix::<f64, 2, 2>::new(2.0, 0.5, 0.5, 1.0);
        let x0 = SVector::<f64, 2>::new(0.3, -0.7);
        let grad = f * x0;
        let s = newton_step(&f, &grad).unwrap();
        assert!((s - x0).amax() < 1e-15);
    }
}
