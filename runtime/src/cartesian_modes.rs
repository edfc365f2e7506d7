//! Harmonic normal modes from the mass-weighted Cartesian Hessian of `U(x)`: the method that
//! holds at a linear equilibrium, where the chart of internal coordinates and Euler angles (and
//! so Wilson's GF method of [`crate::modes`]) is singular.
//!
//! # Method
//!
//! At a stationary geometry `x₀` (bohr, centre of mass at the origin) the harmonic energy is
//! `½ Σ m_i |ẋ_i|² + ½ δxᵀ H δx` with `H = ∂²U/∂x∂x` (hartree/bohr²). In mass-weighted
//! coordinates `y_i = √m_i x_i` the frequencies are `ω² = eigenvalues of H_m = M^{-1/2} H M^{-1/2}`.
//! Translations (`√m_i e_a`) and infinitesimal rotations (`√m_i e_a × x_i`) leave `U` unchanged:
//! they span the external space, of dimension 6, or 5 for a linear geometry (the rotation about
//! the axis moves no atom). `H_m` is projected onto the orthogonal complement `D` of that space
//! (an orthonormal basis, from the eigenvectors of the projector `1 − E Eᵀ`) and `Dᵀ H_m D`
//! diagonalised: `3·NA − 5` modes for a linear molecule (each bend doubly degenerate: the two
//! perpendicular components of the linear bend), `3·NA − 6` otherwise (Wilson, Decius & Cross,
//! *Molecular Vibrations*, 1955, ch. 2; the projection as in electronic-structure codes'
//! frequency analyses).
//!
//! `H` is built from `U(x)` alone ([`Molecule::cartesian_potential`], the closed forms of a
//! definition whose coordinates are declared by kind), by second differences: the diagonal by the
//! fourth-order five-point formula, the off-diagonal entries from the second derivative along
//! `e_i + e_j`, `H_ij = ½ (D²_{e_i+e_j} − H_ii − H_jj)`, all with step [`CARTESIAN_HESSIAN_STEP`].
//! `U(x)` is finite and smooth at a linear geometry where its generated gradient is not (an
//! angle's closed form is not differentiable at exactly π), so no special case is needed there.
//! Truncation error `O(h⁴)`: about 1e-11 relative for bonds of ordinary stiffness; rounding
//! `≈ 3 ε |U| / h²`.

use nalgebra::{DMatrix, DVector, Matrix3, SMatrix, SVector, Vector3};

use crate::modes::ModesError;
use crate::molecule::Molecule;
use crate::units::HARTREE_IN_WAVENUMBERS;

/// Step of the second differences of `U(x)`, bohr.
pub const CARTESIAN_HESSIAN_STEP: f64 = 1e-3;

/// A geometry counts as linear when every atom lies within this fraction of the molecule's
/// size of the line through the centre of mass and the farthest atom.
pub const LINEAR_TOLERANCE: f64 = 1e-8;

/// Whether centred positions `x` (bohr, column `i` is atom `i`) lie on one line to
/// [`LINEAR_TOLERANCE`]: where the chart of internal coordinates and Euler angles is singular.
pub fn is_linear<const NA: usize>(x: &SMatrix<f64, 3, NA>) -> bool {
    let Some(far) = x.column_iter().map(|c| c.into_owned()).max_by(|a, b| a.norm().total_cmp(&b.norm())) else {
        return false;
    };
    let size = far.norm();
    if size.is_nan() || size <= 0.0 || !size.is_finite() {
        return false;
    }
    let axis = far / size;
    x.column_iter().all(|c| c.into_owned().cross(&axis).norm() <= LINEAR_TOLERANCE * size)
}

/// The normal modes at a stationary geometry, from the Cartesian Hessian (module documentation).
#[derive(Clone, Debug, PartialEq)]
pub struct CartesianModes<const NA: usize> {
    /// The geometry `R(q₀)`, bohr, centre of mass at the origin (column `i` is atom `i`).
    pub positions: SMatrix<f64, 3, NA>,
    /// `U(x₀)`, hartree.
    pub u0: f64,
    /// Whether the geometry is linear (5 external degrees of freedom instead of 6).
    pub linear: bool,
    /// The Cartesian Hessian `∂²U/∂x∂x`, hartree/bohr², index `3·atom + axis`.
    pub hessian: DMatrix<f64>,
    /// Angular frequencies `ω_k`, hartree (ħ = 1), ascending: `3·NA − 5` of them for a linear
    /// geometry, `3·NA − 6` otherwise.
    pub omega: Vec<f64>,
    /// Mode `k`'s Cartesian displacement per unit mass-weighted normal coordinate
    /// (`δx_i = l_{k,i} Q_k`, `Σ_i m_i |l_{k,i}|² = 1`), bohr per (bohr·√m_e).
    pub vectors: Vec<SMatrix<f64, 3, NA>>,
    /// The principal moments of inertia, m_e·bohr², ascending (the first is 0 for a linear
    /// geometry).
    pub moments: [f64; 3],
}

impl<const NA: usize> CartesianModes<NA> {
    /// The normal modes of `molecule` at `q0`, which should be a stationary point (see
    /// [`crate::modes::stationary_point`]); fails for a definition without coordinates by kind
    /// (no `U(x)`) and, naming the mode, at a saddle.
    pub fn at<M, const N: usize>(molecule: &M, q0: &SVector<f64, N>) -> Result<Self, ModesError>
    where
        M: Molecule<N, NA> + ?Sized,
    {
        let mut x0 = SMatrix::<f64, 3, NA>::zeros();
        molecule.positions(q0, &mut x0);
        let u = |x: &SMatrix<f64, 3, NA>| molecule.cartesian_potential(x);
        let u0 = u(&x0).ok_or_else(|| {
            ModesError::Failed(format!(
                "{} has no Cartesian potential U(x) (its definition gives atom positions rather than coordinates by \
                 kind), so there are no Cartesian normal modes",
                molecule.name()
            ))
        })?;
        if !u0.is_finite() {
            return Err(ModesError::Failed(format!("U(x) is not finite at q = {:?}", q0.as_slice())));
        }
        let dim = 3 * NA;
        let h = CARTESIAN_HESSIAN_STEP;
        // The second derivative of U along direction d (a unit or sum of two units), fourth order.
        let second = |d: &SMatrix<f64, 3, NA>| -> f64 {
            let at = |t: f64| u(&(x0 + d * t)).unwrap_or(f64::NAN);
            (-at(2.0 * h) + 16.0 * at(h) - 30.0 * u0 + 16.0 * at(-h) - at(-2.0 * h)) / (12.0 * h * h)
        };
        let unit = |k: usize| {
            let mut d = SMatrix::<f64, 3, NA>::zeros();
            d[(k % 3, k / 3)] = 1.0;
            d
        };
        let mut hessian = DMatrix::<f64>::zeros(dim, dim);
        for i in 0..dim {
            hessian[(i, i)] = second(&unit(i));
        }
        for i in 0..dim {
            for j in 0..i {
                let v = 0.5 * (second(&(unit(i) + unit(j))) - hessian[(i, i)] - hessian[(j, j)]);
                hessian[(i, j)] = v;
                hessian[(j, i)] = v;
            }
        }
        if hessian.iter().any(|v| !v.is_finite()) {
            return Err(ModesError::Failed(format!("the Cartesian Hessian is not finite at q = {:?}", q0.as_slice())));
        }
        let masses = molecule.masses();
        let sqrt_m: Vec<f64> = (0..dim).map(|k| masses[k / 3].sqrt()).collect();
        let weighted = DMatrix::from_fn(dim, dim, |i, j| hessian[(i, j)] / (sqrt_m[i] * sqrt_m[j]));

        // The external space: translations and rotations, mass-weighted, orthonormalised
        // (Gram–Schmidt; the rotation about a linear molecule's axis comes out as zero).
        let mut external: Vec<DVector<f64>> = Vec::with_capacity(6);
        let mut candidates: Vec<DVector<f64>> =
            (0..3).map(|a| DVector::from_fn(dim, |k, _| if k % 3 == a { sqrt_m[k] } else { 0.0 })).collect();
        for a in 0..3 {
            let e = Vector3::ith(a, 1.0);
            candidates.push(DVector::from_fn(dim, |k, _| {
                let r = e.cross(&Vector3::from(x0.column(k / 3)));
                sqrt_m[k] * r[k % 3]
            }));
        }
        let scale = candidates.iter().map(|v| v.norm()).fold(0.0, f64::max);
        for mut v in candidates {
            for e in &external {
                v -= e * e.dot(&v);
            }
            let norm = v.norm();
            if norm > 1e-6 * scale {
                external.push(v / norm);
            }
        }
        let linear = is_linear(&x0);
        let expected_external = if linear { 5 } else { 6 };
        if external.len() != expected_external.min(dim) {
            return Err(ModesError::Failed(format!(
                "{} translations and rotations are independent at this geometry, expected {expected_external}",
                external.len()
            )));
        }
        let mut projector = DMatrix::<f64>::identity(dim, dim);
        for e in &external {
            projector -= e * e.transpose();
        }
        let basis = projector.symmetric_eigen();
        let internal: Vec<usize> = (0..dim).filter(|&k| basis.eigenvalues[k] > 0.5).collect();
        let d = DMatrix::from_fn(dim, internal.len(), |r, c| basis.eigenvectors[(r, internal[c])]);
        let reduced = d.transpose() * &weighted * &d;
        let reduced =
            DMatrix::from_fn(reduced.nrows(), reduced.ncols(), |i, j| 0.5 * (reduced[(i, j)] + reduced[(j, i)]));
        let eig = reduced.symmetric_eigen();
        let mut order: Vec<usize> = (0..internal.len()).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        let mut omega = Vec::with_capacity(order.len());
        let mut vectors = Vec::with_capacity(order.len());
        for (mode, &k) in order.iter().enumerate() {
            let y = &d * eig.eigenvectors.column(k);
            let l = SMatrix::<f64, 3, NA>::from_fn(|a, i| y[3 * i + a] / sqrt_m[3 * i + a]);
            let lambda = eig.eigenvalues[k];
            if lambda <= 0.0 {
                let (atom, _) =
                    (0..NA).map(|i| (i, l.column(i).norm())).max_by(|a, b| a.1.total_cmp(&b.1)).unwrap_or((0, 0.0));
                return Err(ModesError::NotMinimum {
                    mode,
                    wavenumber: (-lambda).sqrt() * HARTREE_IN_WAVENUMBERS,
                    coordinates: format!("Cartesian displacements, most of atom {}", molecule.atoms()[atom].label),
                });
            }
            omega.push(lambda.sqrt());
            vectors.push(l);
        }
        let mut inertia = Matrix3::<f64>::zeros();
        for i in 0..NA {
            let r = Vector3::from(x0.column(i));
            inertia += masses[i] * (Matrix3::identity() * r.norm_squared() - r * r.transpose());
        }
        let e = inertia.symmetric_eigenvalues();
        let mut moments = [e[0], e[1], e[2]];
        moments.sort_by(f64::total_cmp);
        if linear {
            moments[0] = 0.0;
        }
        Ok(Self { positions: x0, u0, linear, hessian, omega, vectors, moments })
    }

    /// Harmonic wavenumbers in cm⁻¹, ascending.
    pub fn wavenumbers(&self) -> Vec<f64> {
        self.omega.iter().map(|w| w * HARTREE_IN_WAVENUMBERS).collect()
    }
}
