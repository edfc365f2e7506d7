//! The lab-frame rigid chart: a complex of rigid linear fragments and single atoms (an atom and
//! a rigid diatomic or linear triatomic, two linear rotors) in lab-frame variables that have no
//! singular configuration, for molecules that have no Cartesian chart (a rigid complex has
//! fewer than 3N − 6 coordinates, and a definition by explicit positions has no closed-form
//! `q(x)`). [`crate::charts`] integrates here where the internal chart's metric degenerates
//! (the whole complex linear).
//!
//! # State layout
//!
//! Body by body in [`RigidLayout`] order, about the centre of mass of the whole (at rest): a
//! fragment of mass `M` and moment of inertia `I` has `[c (3), P (3), u (3), L (3)]`, its centre
//! of mass, momentum, unit axis and angular momentum about `c` (`L ⟂ u`); a single atom of mass
//! `m` has `[x (3), p (3)]`. Atom `i` of a fragment sits at `x_i = c + s_i u` (`s_i` its signed
//! offset along the axis). The equations:
//!
//! ```text
//! ċ = P/M,  Ṗ = Σ f_i,  u̇ = (L/I) × u,  L̇ = u × Σ s_i f_i;    ẋ = p/m,  ṗ = f
//! ```
//!
//! with `f_i = −∂U/∂x_i`. `u × Σ s_i f_i` is the torque about `c` without its component along
//! `u`; `|u| = 1` and `L · u = 0` are kept by the equations (not renormalised).
//!
//! # The force of a potential over internal coordinates
//!
//! Each evaluation fits `(R, q)` to the positions (Kabsch rotation of `R_i(q)` from the previous
//! evaluation's `q`, then Gauss–Newton on the rotation and `q` with the kinetic metric `M` as
//! the normal matrix, solved by its pseudo-inverse), then takes the mass-weighted field of
//! `(ω, q̇) = M⁺ (0, ∂U/∂q)`: `∂U/∂x_i = m_i R (ω × R_i + Σ_k ∂R_i/∂q_k q̇_k)`. Its
//! projections onto every rotation and every coordinate displacement are `(0, ∂U/∂q)`, so
//! the force and torque on every body are exact; at an exactly linear complex the direction
//! the metric loses (turning the atom about the common axis) carries no force, which is the
//! limit of the regular case for a potential smooth in the positions.

use nalgebra::{Matrix3, Rotation3, SMatrix, SVector, Vector3};

use crate::frames::{FrameError, LabState, nearest_rotation, projections};
use crate::hamiltonian::{BodyState, MetricFactor};
use crate::integrate::OdeSystem;
use crate::molecule::{KineticMatrices, Molecule};
use nalgebra::UnitQuaternion;

/// The largest `3 + N` (rotations and coordinates) the chart's fit and force solve handle.
pub const MAX_DIM: usize = 16;

/// Relative eigenvalue of the kinetic metric below which its direction counts as null in the
/// fit and the force solve.
const NULL_EIGENVALUE: f64 = 1e-15;

/// Gauss–Newton steps of the position fit at most.
const FIT_ITERATIONS: usize = 30;

/// RMS position step (bohr) at which the fit has converged.
const FIT_STEP: f64 = 1e-13;

/// RMS position residual (bohr) above which a fit counts as failed.
const FIT_RESIDUAL: f64 = 1e-9;

/// Why the rigid chart's right-hand side stopped.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RigidError {
    /// Not an error: the internal chart is regular (every relative pivot above the threshold)
    /// here, so the run switches back to it.
    #[error("the internal-coordinate chart is regular again (relative pivots above {threshold:e})")]
    Regular {
        /// The threshold.
        threshold: f64,
    },
    /// The positions could not be fitted by the molecule's geometry.
    #[error(
        "the rigid chart's positions do not fit molecule {molecule}'s geometry (RMS residual {residual:e} bohr after \
         {iterations} Gauss-Newton steps, q = {q:?})"
    )]
    Fit {
        /// The molecule.
        molecule: &'static str,
        /// RMS residual, bohr.
        residual: f64,
        /// Steps taken.
        iterations: usize,
        /// The last `q`.
        q: Vec<f64>,
    },
    /// A force, position or velocity is not finite.
    #[error("the rigid chart's {quantity} is not finite at q = {q:?}")]
    NonFinite {
        /// What.
        quantity: &'static str,
        /// The fitted `q`.
        q: Vec<f64>,
    },
}

/// One body of a [`RigidLayout`]: a rigid linear fragment or a single atom.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidBody {
    /// Its atoms and their signed offsets from its centre of mass along its axis (bohr; one
    /// atom with offset 0 for a single atom).
    pub atoms: Vec<(usize, f64)>,
    /// Mass.
    pub mass: f64,
    /// Moment of inertia about the centre of mass perpendicular to the axis (0 for an atom).
    pub inertia: f64,
    /// First component in the flat state.
    pub offset: usize,
}

impl RigidBody {
    /// Whether this is a fragment (else a single atom).
    pub fn is_fragment(&self) -> bool {
        self.atoms.len() > 1
    }
}

/// Which atoms of a molecule form rigid linear fragments and which are single atoms.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidLayout {
    /// The bodies, in the order of their first atoms.
    pub bodies: Vec<RigidBody>,
    /// Components of the flat state.
    pub dim: usize,
}

/// Geometries at which [`RigidLayout::detect`] compares distances.
const SAMPLES: usize = 5;

impl RigidLayout {
    /// The layout of `molecule` found from its geometry: at the reference geometry and four
    /// displaced ones (every coordinate moved by up to 0.1, inside its range), atom pairs whose
    /// distance is the same to 1e-9 relative are rigidly joined; each connected group of two or
    /// more atoms must be joined pairwise and lie on a line (to 1e-9 bohr) at every sample, and
    /// the complex must need exactly its coordinates and the six of the whole: `3·bodies +
    /// 2·fragments = N + 6`, with at least one fragment (a molecule of free atoms only has the
    /// Cartesian chart). `None` if the molecule is not of this form (or has no reference
    /// geometry, or `3 + N > MAX_DIM`).
    pub fn detect<M: Molecule<N, NA> + ?Sized, const N: usize, const NA: usize>(molecule: &M) -> Option<Self> {
        if 3 + N > MAX_DIM || NA < 2 {
            return None;
        }
        let q0 = molecule.reference_geometry()?;
        let coords = molecule.coordinates();
        let mut samples = [SMatrix::<f64, 3, NA>::zeros(); SAMPLES];
        for (s, x) in samples.iter_mut().enumerate() {
            let mut q = q0;
            for k in 0..N {
                if s == 0 {
                    break;
                }
                let d = 0.1 * (1.3 * (s * (k + 2)) as f64 + 0.4).sin();
                q[k] = if coords[k].contains(q0[k] + d) {
                    q0[k] + d
                } else if coords[k].contains(q0[k] - d) {
                    q0[k] - d
                } else {
                    q0[k]
                };
            }
            molecule.positions(&q, x);
            if !x.iter().all(|v| v.is_finite()) {
                return None;
            }
        }
        let dist = |x: &SMatrix<f64, 3, NA>, i: usize, j: usize| (x.column(i) - x.column(j)).norm();
        let rigid = |i: usize, j: usize| {
            let d0 = dist(&samples[0], i, j);
            samples.iter().all(|x| (dist(x, i, j) - d0).abs() <= 1e-9 * d0.max(1.0))
        };
        // Connected groups under "rigidly joined" (union-find on NA atoms).
        let mut group: [usize; NA] = core::array::from_fn(|i| i);
        fn root<const NA: usize>(g: &mut [usize; NA], mut i: usize) -> usize {
            while g[i] != i {
                g[i] = g[g[i]];
                i = g[i];
            }
            i
        }
        for i in 0..NA {
            for j in i + 1..NA {
                if rigid(i, j) {
                    let (a, b) = (root(&mut group, i), root(&mut group, j));
                    group[a.max(b)] = a.min(b);
                }
            }
        }
        let masses = molecule.masses();
        let mut bodies: Vec<RigidBody> = Vec::new();
        let mut offset = 0;
        let mut fragments = 0;
        for first in 0..NA {
            if root(&mut group, first) != first {
                continue;
            }
            let members: Vec<usize> = (0..NA).filter(|&i| root(&mut group, i) == first).collect();
            let mass: f64 = members.iter().map(|&i| masses[i]).sum();
            if members.len() == 1 {
                bodies.push(RigidBody { atoms: vec![(first, 0.0)], mass, inertia: 0.0, offset });
                offset += 6;
                continue;
            }
            // Joined pairwise and on a line at every sample.
            for (a, &i) in members.iter().enumerate() {
                for &j in &members[a + 1..] {
                    if !rigid(i, j) {
                        return None;
                    }
                }
            }
            let last = *members.last().expect("two or more members");
            let mut atoms = Vec::with_capacity(members.len());
            for (s, x) in samples.iter().enumerate() {
                let centre: Vector3<f64> =
                    members.iter().map(|&i| x.column(i) * masses[i]).sum::<Vector3<f64>>() / mass;
                let axis = x.column(first) - x.column(last);
                let u = axis / axis.norm();
                for &i in &members {
                    let d = x.column(i) - centre;
                    let along = d.dot(&u);
                    if (d - u * along).norm() > 1e-9 || !along.is_finite() {
                        return None;
                    }
                    if s == 0 {
                        atoms.push((i, along));
                    }
                }
            }
            let inertia = atoms.iter().map(|&(i, s)| masses[i] * s * s).sum();
            bodies.push(RigidBody { atoms, mass, inertia, offset });
            offset += 12;
            fragments += 1;
        }
        if fragments == 0 || bodies.len() < 2 || 3 * bodies.len() + 2 * fragments != N + 6 {
            return None;
        }
        Some(Self { bodies, dim: offset })
    }

    /// The flat state of a lab state about the centre of mass (exact for positions and
    /// velocities of rigid fragments; `u` normalised here).
    pub fn flat<const NA: usize>(&self, masses: &[f64; NA], lab: &LabState<NA>, y: &mut [f64]) {
        let x = |i: usize| Vector3::from(lab.positions.column(i));
        let v = |i: usize| Vector3::from(lab.velocities.column(i));
        for b in &self.bodies {
            let o = b.offset;
            if !b.is_fragment() {
                let i = b.atoms[0].0;
                put(y, o, &x(i));
                put(y, o + 3, &(v(i) * masses[i]));
                continue;
            }
            let c: Vector3<f64> = b.atoms.iter().map(|&(i, _)| x(i) * masses[i]).sum::<Vector3<f64>>() / b.mass;
            let w: Vector3<f64> = b.atoms.iter().map(|&(i, _)| v(i) * masses[i]).sum::<Vector3<f64>>() / b.mass;
            let u: Vector3<f64> = b.atoms.iter().map(|&(i, s)| (x(i) - c) * (masses[i] * s)).sum::<Vector3<f64>>();
            let u = u / u.norm();
            let l: Vector3<f64> = b.atoms.iter().map(|&(i, _)| (x(i) - c).cross(&(v(i) - w)) * masses[i]).sum();
            put(y, o, &c);
            put(y, o + 3, &(w * b.mass));
            put(y, o + 6, &u);
            put(y, o + 9, &l);
        }
    }

    /// The positions of a flat state (column `i` is atom `i`), with each fragment's axis taken
    /// as `u/|u|`: the integrator's intermediate stages leave `|u| = 1` by their local error
    /// (the equations keep it, a Runge–Kutta stage does not), and the fit of the molecule's
    /// geometry needs the fragments' own lengths. The state itself is not changed.
    pub fn positions<const NA: usize>(&self, y: &[f64]) -> SMatrix<f64, 3, NA> {
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        for b in &self.bodies {
            let c = v3(y, b.offset);
            if b.is_fragment() {
                let u = v3(y, b.offset + 6);
                let u = u / u.norm();
                for &(i, s) in &b.atoms {
                    x.set_column(i, &(c + u * s));
                }
            } else {
                x.set_column(b.atoms[0].0, &c);
            }
        }
        x
    }

    /// The lab state (positions and velocities of every atom) of a flat state.
    pub fn lab<const NA: usize>(&self, masses: &[f64; NA], y: &[f64]) -> LabState<NA> {
        let positions = self.positions(y);
        let mut velocities = SMatrix::<f64, 3, NA>::zeros();
        for b in &self.bodies {
            let o = b.offset;
            if b.is_fragment() {
                let (w, u, l) = (v3(y, o + 3) / b.mass, v3(y, o + 6), v3(y, o + 9));
                let omega = l / b.inertia;
                for &(i, s) in &b.atoms {
                    velocities.set_column(i, &(w + omega.cross(&u) * s));
                }
            } else {
                let i = b.atoms[0].0;
                velocities.set_column(i, &(v3(y, o + 3) / masses[i]));
            }
        }
        LabState { positions, velocities }
    }

    /// The kinetic energy `Σ P²/2M + L²/2I + Σ p²/2m`.
    pub fn kinetic_energy(&self, y: &[f64]) -> f64 {
        self.bodies
            .iter()
            .map(|b| {
                let t = v3(y, b.offset + 3).norm_squared() / (2.0 * b.mass);
                if b.is_fragment() { t + v3(y, b.offset + 9).norm_squared() / (2.0 * b.inertia) } else { t }
            })
            .sum()
    }

    /// The angular momentum about the origin, `Σ c × P + L + Σ x × p`.
    pub fn angular_momentum(&self, y: &[f64]) -> Vector3<f64> {
        self.bodies
            .iter()
            .map(|b| {
                let l = v3(y, b.offset).cross(&v3(y, b.offset + 3));
                if b.is_fragment() { l + v3(y, b.offset + 9) } else { l }
            })
            .sum()
    }

    /// The largest `|L·u|` and `||u| − 1|` over the fragments.
    pub fn constraint_residual(&self, y: &[f64]) -> f64 {
        self.bodies
            .iter()
            .filter(|b| b.is_fragment())
            .map(|b| {
                let (u, l) = (v3(y, b.offset + 6), v3(y, b.offset + 9));
                (l.dot(&u)).abs().max((u.norm() - 1.0).abs())
            })
            .fold(0.0, f64::max)
    }
}

fn v3(y: &[f64], k: usize) -> Vector3<f64> {
    Vector3::new(y[k], y[k + 1], y[k + 2])
}

fn put(y: &mut [f64], k: usize, x: &Vector3<f64>) {
    y[k..k + 3].copy_from_slice(x.as_slice());
}

/// The result of the position fit: rotation, `q`, `R_i(q)`, `∂R_i/∂q` and the kinetic matrices
/// at `q`.
struct Fit<const N: usize, const NA: usize> {
    rotation: Matrix3<f64>,
    q: SVector<f64, N>,
    r: SMatrix<f64, 3, NA>,
    dr: [SMatrix<f64, 3, NA>; N],
    kinetic: KineticMatrices<N>,
}

/// The metric `[[I, A], [Aᵀ, a]]` of `k` into the top-left `(3 + N)²` block of `m`.
fn metric_into<const N: usize>(k: &KineticMatrices<N>, m: &mut [[f64; MAX_DIM]; MAX_DIM]) {
    for r in 0..3 + N {
        for c in 0..3 + N {
            m[r][c] = match (r < 3, c < 3) {
                (true, true) => k.inertia[(r, c)],
                (true, false) => k.coriolis[(r, c - 3)],
                (false, true) => k.coriolis[(c, r - 3)],
                (false, false) => k.a[(r - 3, c - 3)],
            };
        }
    }
}

/// The minimum-norm least-squares solution of `a x = b` for the symmetric positive
/// semi-definite top-left `d × d` block of `a` (destroyed), by cyclic Jacobi rotations:
/// eigen-directions with eigenvalue below [`NULL_EIGENVALUE`] times the largest count as null.
/// No allocation.
fn pseudo_solve(a: &mut [[f64; MAX_DIM]; MAX_DIM], d: usize, b: &[f64], x: &mut [f64]) {
    let mut v = [[0.0; MAX_DIM]; MAX_DIM];
    for (i, row) in v.iter_mut().enumerate().take(d) {
        row[i] = 1.0;
    }
    for _ in 0..50 {
        let mut off = 0.0;
        let mut diag = 0.0;
        for p in 0..d {
            diag += a[p][p] * a[p][p];
            for q in p + 1..d {
                off += a[p][q] * a[p][q];
            }
        }
        if off <= 1e-32 * diag {
            break;
        }
        for p in 0..d {
            for q in p + 1..d {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for row in a.iter_mut().take(d) {
                    let (kp, kq) = (row[p], row[q]);
                    row[p] = c * kp - s * kq;
                    row[q] = s * kp + c * kq;
                }
                for k in 0..d {
                    let (pk, qk) = (a[p][k], a[q][k]);
                    a[p][k] = c * pk - s * qk;
                    a[q][k] = s * pk + c * qk;
                }
                for row in v.iter_mut().take(d) {
                    let (kp, kq) = (row[p], row[q]);
                    row[p] = c * kp - s * kq;
                    row[q] = s * kp + c * kq;
                }
            }
        }
    }
    let largest = (0..d).map(|k| a[k][k].abs()).fold(0.0, f64::max);
    x[..d].fill(0.0);
    for k in 0..d {
        if a[k][k] <= NULL_EIGENVALUE * largest {
            continue;
        }
        let coefficient = (0..d).map(|i| v[i][k] * b[i]).sum::<f64>() / a[k][k];
        for i in 0..d {
            x[i] += coefficient * v[i][k];
        }
    }
}

/// Newton's equations of a rigid complex in the rigid chart (module documentation).
#[derive(Debug)]
pub struct RigidSystem<'a, M: ?Sized, const N: usize, const NA: usize> {
    molecule: &'a M,
    layout: RigidLayout,
    masses: [f64; NA],
    /// As [`crate::cartesian_system::CartesianSystem::with_return_pivot`].
    return_pivot: Option<f64>,
    check_after: f64,
    /// The start of the next position fit (the last fitted `q`).
    last_q: SVector<f64, N>,
}

impl<M: ?Sized, const N: usize, const NA: usize> Clone for RigidSystem<'_, M, N, NA> {
    fn clone(&self) -> Self {
        Self { layout: self.layout.clone(), ..*self }
    }
}

impl<'a, M, const N: usize, const NA: usize> RigidSystem<'a, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    /// The rigid chart of `molecule`, if it is a complex of rigid linear fragments and atoms
    /// ([`RigidLayout::detect`]).
    pub fn new(molecule: &'a M) -> Option<Self> {
        let layout = RigidLayout::detect(molecule)?;
        let last_q = molecule.reference_geometry()?;
        Some(Self {
            molecule,
            layout,
            masses: molecule.masses(),
            return_pivot: None,
            check_after: f64::NEG_INFINITY,
            last_q,
        })
    }

    /// The same system, failing with [`RigidError::Regular`] wherever the internal chart's
    /// relative pivots all exceed `pivot` (how the switch back is detected).
    pub fn with_return_pivot(mut self, pivot: f64) -> Self {
        self.return_pivot = Some(pivot);
        self
    }

    /// Makes the return test apply only to evaluations at times after `t`.
    pub fn check_after(&mut self, t: f64) {
        self.check_after = t;
    }

    /// The molecule.
    pub fn molecule(&self) -> &'a M {
        self.molecule
    }

    /// Starts the next position fit from `q`.
    pub fn set_near(&mut self, q: &SVector<f64, N>) {
        self.last_q = *q;
    }

    /// The layout.
    pub fn layout(&self) -> &RigidLayout {
        &self.layout
    }

    /// The molecule's masses.
    pub fn masses(&self) -> &[f64; NA] {
        &self.masses
    }

    /// The flat state of a body-formulation state (centre of mass at rest at the origin), also
    /// at a singular geometry (through the metric's pseudo-inverse).
    pub fn flat_of_body(&self, body: &BodyState<N>, y: &mut [f64]) -> Result<(), FrameError> {
        let lab = crate::frames::lab_of_body_any(self.molecule, body, &crate::frames::CentreOfMass::default())?;
        self.layout.flat(&self.masses, &lab, y);
        Ok(())
    }

    /// The body-formulation state of a flat state: the fitted `q` and orientation from
    /// [`RigidSystem::set_near`]'s `q`, `J = Σ m_i R_i × w_i` and `p_k = Σ m_i ∂R_i/∂q_k · w_i`
    /// with `w_i` the body-frame velocities (defined at every geometry).
    pub fn body_of_flat(&mut self, y: &[f64]) -> Result<BodyState<N>, RigidError> {
        let lab = self.layout.lab(&self.masses, y);
        let fit = self.fit(&lab.positions)?;
        let mut w = lab.velocities;
        let total: f64 = self.masses.iter().sum();
        let v: Vector3<f64> = (0..NA).map(|i| lab.velocities.column(i) * self.masses[i]).sum::<Vector3<f64>>() / total;
        for i in 0..NA {
            w.set_column(i, &(fit.rotation.transpose() * (lab.velocities.column(i) - v)));
        }
        let (j, p) = projections(&self.masses, &fit.r, &fit.dr, &w);
        let orientation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(fit.rotation));
        let body = BodyState { q: fit.q, p, orientation, j };
        if !body.q.iter().chain(body.p.iter()).chain(body.j.iter()).all(|x| x.is_finite()) {
            return Err(RigidError::NonFinite { quantity: "body state", q: fit.q.iter().copied().collect() });
        }
        Ok(body)
    }

    /// `H = T + U(q)` of a flat state, hartree.
    pub fn energy(&mut self, y: &[f64]) -> Result<f64, RigidError> {
        let x = self.layout.positions::<NA>(y);
        let fit = self.fit(&x)?;
        Ok(self.layout.kinetic_energy(y) + self.molecule.potential(&fit.q))
    }

    /// Kabsch rotation of `R_i(last q)` onto the positions about their centre of mass, then
    /// Gauss–Newton in the rotation and `q` (module documentation). Updates the last `q`.
    fn fit(&mut self, x: &SMatrix<f64, 3, NA>) -> Result<Fit<N, NA>, RigidError> {
        let m = &self.masses;
        let total: f64 = m.iter().sum();
        let centre: Vector3<f64> = (0..NA).map(|i| x.column(i) * m[i]).sum::<Vector3<f64>>() / total;
        let mut y = *x;
        for i in 0..NA {
            y.set_column(i, &(x.column(i) - centre));
        }
        let mut q = self.last_q;
        let mut r = SMatrix::<f64, 3, NA>::zeros();
        self.molecule.positions(&q, &mut r);
        let mut c = Matrix3::zeros();
        for i in 0..NA {
            c += y.column(i) * r.column(i).transpose() * m[i];
        }
        let non_finite =
            |quantity, q: &SVector<f64, N>| RigidError::NonFinite { quantity, q: q.iter().copied().collect() };
        let mut rotation = nearest_rotation(&c).ok_or_else(|| non_finite("kabsch rotation", &q))?;
        let mut kinetic = KineticMatrices::<N>::default();
        let mut dr = [SMatrix::<f64, 3, NA>::zeros(); N];
        let mut a = [[0.0; MAX_DIM]; MAX_DIM];
        let (mut b, mut step) = ([0.0; MAX_DIM], [0.0; MAX_DIM]);
        let mut iterations = 0;
        let mut converged = false;
        let mut residual = f64::INFINITY;
        while iterations <= FIT_ITERATIONS {
            self.molecule.positions(&q, &mut r);
            self.molecule.positions_jacobian(&q, &mut dr);
            self.molecule.kinetic(&q, &mut kinetic);
            let e = rotation.transpose() * y - r;
            residual = ((0..NA).map(|i| m[i] * e.column(i).norm_squared()).sum::<f64>() / total).sqrt();
            if converged || !residual.is_finite() {
                break;
            }
            let (b_rot, b_vib) = projections(m, &r, &dr, &e);
            b[..3].copy_from_slice(b_rot.as_slice());
            b[3..3 + N].copy_from_slice(b_vib.as_slice());
            metric_into(&kinetic, &mut a);
            pseudo_solve(&mut a, 3 + N, &b, &mut step);
            let moved = ((0..3 + N).map(|k| step[k] * b[k]).sum::<f64>().max(0.0) / total).sqrt();
            let d_theta = Vector3::new(step[0], step[1], step[2]);
            rotation = nearest_rotation(&(rotation * Rotation3::new(d_theta).into_inner()))
                .ok_or_else(|| non_finite("rotation of the fit", &q))?;
            for k in 0..N {
                q[k] += step[3 + k];
            }
            converged = moved <= FIT_STEP || !moved.is_finite();
            iterations += 1;
        }
        if residual.is_nan() || residual > FIT_RESIDUAL {
            return Err(RigidError::Fit {
                molecule: self.molecule.name(),
                residual,
                iterations,
                q: q.iter().copied().collect(),
            });
        }
        self.last_q = q;
        Ok(Fit { rotation, q, r, dr, kinetic })
    }

    /// `∂U/∂x` (lab frame, column `i` is atom `i`) at the positions `x` (module documentation),
    /// and the fitted kinetic matrices.
    pub fn gradient(
        &mut self,
        x: &SMatrix<f64, 3, NA>,
    ) -> Result<(SMatrix<f64, 3, NA>, KineticMatrices<N>), RigidError> {
        let fit = self.fit(x)?;
        let mut g = SVector::<f64, N>::zeros();
        self.molecule.potential_gradient(&fit.q, &mut g);
        let mut a = [[0.0; MAX_DIM]; MAX_DIM];
        let (mut b, mut s) = ([0.0; MAX_DIM], [0.0; MAX_DIM]);
        b[3..3 + N].copy_from_slice(g.as_slice());
        metric_into(&fit.kinetic, &mut a);
        pseudo_solve(&mut a, 3 + N, &b, &mut s);
        let omega = Vector3::new(s[0], s[1], s[2]);
        let mut grad = SMatrix::<f64, 3, NA>::zeros();
        for i in 0..NA {
            let mut w: Vector3<f64> = omega.cross(&Vector3::from(fit.r.column(i)));
            for k in 0..N {
                w += fit.dr[k].column(i) * s[3 + k];
            }
            grad.set_column(i, &(fit.rotation * w * self.masses[i]));
        }
        if !grad.iter().all(|v| v.is_finite()) {
            return Err(RigidError::NonFinite { quantity: "potential gradient", q: fit.q.iter().copied().collect() });
        }
        Ok((grad, fit.kinetic))
    }
}

impl<M, const N: usize, const NA: usize> OdeSystem for RigidSystem<'_, M, N, NA>
where
    M: Molecule<N, NA> + ?Sized,
{
    type Error = RigidError;

    fn dim(&self) -> usize {
        self.layout.dim
    }

    fn rhs(&mut self, t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), RigidError> {
        let x = self.layout.positions::<NA>(y);
        let (grad, kinetic) = self.gradient(&x)?;
        if let Some(threshold) = self.return_pivot
            && t > self.check_after
            && MetricFactor::is_regular(&kinetic, threshold)
        {
            return Err(RigidError::Regular { threshold });
        }
        for b in &self.layout.bodies {
            let o = b.offset;
            if b.is_fragment() {
                let (u, l) = (v3(y, o + 6), v3(y, o + 9));
                let mut force = Vector3::zeros();
                let mut moment = Vector3::zeros();
                for &(i, s) in &b.atoms {
                    let f = -Vector3::from(grad.column(i));
                    force += f;
                    moment += f * s;
                }
                put(dydt, o, &(v3(y, o + 3) / b.mass));
                put(dydt, o + 3, &force);
                put(dydt, o + 6, &(l / b.inertia).cross(&u));
                put(dydt, o + 9, &u.cross(&moment));
            } else {
                let i = b.atoms[0].0;
                put(dydt, o, &(v3(y, o + 3) / self.masses[i]));
                put(dydt, o + 3, &(-Vector3::from(grad.column(i))));
            }
        }
        Ok(())
    }
}
