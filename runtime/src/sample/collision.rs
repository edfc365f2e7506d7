//! Collision initial conditions (quasi-classical trajectories): two fragments of one molecule
//! definition, placed at a centre-of-mass separation `R0` with an impact parameter `b` and a
//! relative kinetic energy `E`, each fragment randomly oriented with its own rotation and (for a
//! diatomic) vibration.
//!
//! # The distributions
//!
//! * Impact parameter: `b²` uniform on `[b_lo², b_hi²]` of its stratum (one stratum `[0, b_max]`
//!   for plain sampling). Stratum `s` gets a fixed share of the trajectories, `n_s` of them,
//!   `n_s ≈ N·w_s/Σw` (the last stratum takes the remainder), so a cross section is
//!   `σ = Σ_s π (b_hi² − b_lo²) · (fraction in stratum s)`.
//! * Relative energy: fixed, or flux-weighted Maxwell–Boltzmann `P(E) = E e^(−E/kT)/(kT)²`
//!   (a Γ(2, kT) variate, `E = −kT ln(u₁ u₂)`; `⟨E⟩ = 2kT`).
//! * Rotation of a fragment with two or more atoms: thermal, `L` in the principal frame with
//!   `L_k ~ N(0, kT I_k)` for every non-zero principal moment (a linear fragment has no `L` along
//!   its axis; `⟨E_rot⟩ = kT` linear, `3kT/2` otherwise), or quasi-classical `|L| = √(J(J+1)) ħ`
//!   in a random direction perpendicular to the axis of a linear fragment (uniform on the
//!   sphere of a non-linear one, whose `K` is then not fixed). `ω = I⁺ L`.
//! * Vibration of a diatomic fragment, harmonic about its reference bond length with the force
//!   constant `k = U''(r)` of the molecule's potential along the bond (five-point finite
//!   difference, the other fragment far away): thermal (`Δr ~ N(0, kT/k)`, `ṙ ~ N(0, kT/μ)`) or
//!   quasi-classical `E = (v + ½) ħ ω`, `ω = √(k/μ)`, at a random phase.
//! * Orientation of each fragment uniform (Haar). Fragment B starts at `(0, b, −√(R0² − b²))`
//!   relative to A, moving along +z; the centre of mass is at rest at the origin.
//!
//! The lab-frame positions and velocities are fitted to the molecule's coordinates by
//! [`crate::frames::from_lab_body`]; a state the parametrisation cannot represent is an error.

use nalgebra::{Matrix3, SMatrix, SVector, SymmetricEigen, Vector3};
use rand::RngExt as _;
use rand_distr::StandardNormal;

use super::{BOLTZMANN, SampleError, TrajectoryRng, haar, stream, uniform_direction};
use crate::frames::{FitOptions, LabState, from_lab_body};
use crate::hamiltonian::fast::BodyState;
use crate::molecule::Molecule;

/// A band of impact parameters with its share of the trajectories.
#[derive(Clone, Debug, PartialEq)]
pub struct Stratum {
    /// Lower edge, bohr.
    pub low: f64,
    /// Upper edge, bohr.
    pub high: f64,
    /// Relative share of the trajectories (positive).
    pub weight: f64,
}

impl Stratum {
    /// The ring's area `π (b_hi² − b_lo²)`, bohr².
    pub fn area(&self) -> f64 {
        std::f64::consts::PI * (self.high * self.high - self.low * self.low)
    }
}

/// The relative translational energy.
#[derive(Clone, Debug, PartialEq)]
pub enum RelativeEnergy {
    /// Hartree.
    Fixed(f64),
    /// Flux-weighted Maxwell–Boltzmann at this temperature (kelvin).
    Thermal(f64),
}

/// A fragment's rotation.
#[derive(Clone, Debug, PartialEq)]
pub enum FragmentRotation {
    /// Not rotating.
    None,
    /// Thermal at this temperature (kelvin).
    Thermal(f64),
    /// Quasi-classical `|L| = √(J(J+1))` ħ.
    Quantum(u32),
}

/// A diatomic fragment's vibration.
#[derive(Clone, Debug, PartialEq)]
pub enum FragmentVibration {
    /// At the reference bond length, not vibrating.
    None,
    /// Thermal (harmonic) at this temperature (kelvin).
    Thermal(f64),
    /// Quasi-classical harmonic `E = (v + ½) ħω`.
    Quantum(u32),
}

/// Everything that defines a collision ensemble, in atomic units.
#[derive(Clone, Debug, PartialEq)]
pub struct CollisionSpec {
    /// Atom indices of fragment A and fragment B (disjoint, together every atom).
    pub fragments: [Vec<usize>; 2],
    /// The impact-parameter strata (one `[0, b_max]` of weight 1 for plain sampling).
    pub strata: Vec<Stratum>,
    /// The relative energy.
    pub energy: RelativeEnergy,
    /// Rotation of A and B.
    pub rotation: [FragmentRotation; 2],
    /// Vibration of A and B.
    pub vibration: [FragmentVibration; 2],
    /// Initial centre-of-mass separation, bohr.
    pub r0: f64,
    /// Number of trajectories (the strata's shares are fixed by it).
    pub trajectories: u64,
}

/// A fragment's atoms about its centre of mass and their velocities (lab orientation), bohr and
/// bohr per a.u. of time.
pub type FragmentAtoms = (Vec<Vector3<f64>>, Vec<Vector3<f64>>);

/// What was drawn for one trajectory besides its state.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Drawn {
    /// Impact parameter, bohr.
    pub b: f64,
    /// Stratum index.
    pub stratum: usize,
    /// Relative kinetic energy, hartree.
    pub energy: f64,
}

/// Fragment geometry helpers: centre of mass, inertia, rotational energy.
pub mod fragment {
    use super::*;

    /// Mass, centre-of-mass position and velocity of the atoms `atoms`.
    pub fn centre<const NA: usize>(
        lab: &LabState<NA>,
        masses: &[f64; NA],
        atoms: &[usize],
    ) -> (f64, Vector3<f64>, Vector3<f64>) {
        let mut m = 0.0;
        let mut x = Vector3::zeros();
        let mut v = Vector3::zeros();
        for &i in atoms {
            m += masses[i];
            x += masses[i] * lab.positions.column(i);
            v += masses[i] * lab.velocities.column(i);
        }
        (m, x / m, v / m)
    }

    /// Inertia tensor of points `y` (about the origin) with masses `m`.
    pub fn inertia(y: &[Vector3<f64>], m: &[f64]) -> Matrix3<f64> {
        let mut t = Matrix3::zeros();
        for (yi, &mi) in y.iter().zip(m) {
            t += mi * (Matrix3::identity() * yi.norm_squared() - yi * yi.transpose());
        }
        t
    }

    /// `I⁺ L`: the angular velocity of angular momentum `l` (the pseudo-inverse drops principal
    /// moments below 1e-10 of the largest: the axis of a linear fragment).
    pub fn angular_velocity(inertia: &Matrix3<f64>, l: &Vector3<f64>) -> Vector3<f64> {
        let e = SymmetricEigen::new(*inertia);
        let top = e.eigenvalues.amax();
        let mut w = Vector3::zeros();
        for k in 0..3 {
            let ik = e.eigenvalues[k];
            if top > 0.0 && ik > 1e-10 * top {
                let axis: Vector3<f64> = e.eigenvectors.column(k).into();
                w += axis * (axis.dot(l) / ik);
            }
        }
        w
    }

    /// The internal state of one fragment in a lab state: its angular momentum about its own
    /// centre of mass (ħ), rotational energy `½ L·I⁺L` and the rest of its internal kinetic
    /// energy (vibration), hartree.
    #[derive(Copy, Clone, Debug, PartialEq)]
    pub struct Internal {
        /// Mass.
        pub mass: f64,
        /// Centre of mass, bohr.
        pub position: Vector3<f64>,
        /// Its velocity.
        pub velocity: Vector3<f64>,
        /// Angular momentum about the centre of mass, ħ.
        pub l: Vector3<f64>,
        /// Rotational energy, hartree.
        pub e_rot: f64,
        /// Internal kinetic energy minus the rotational energy, hartree.
        pub t_vib: f64,
    }

    /// [`Internal`] of the atoms `atoms` of `lab`.
    pub fn internal<const NA: usize>(lab: &LabState<NA>, masses: &[f64; NA], atoms: &[usize]) -> Internal {
        let (mass, x, v) = centre(lab, masses, atoms);
        let mut l = Vector3::zeros();
        let mut t = 0.0;
        let mut inertia = Matrix3::zeros();
        for &i in atoms {
            let y: Vector3<f64> = lab.positions.column(i) - x;
            let u: Vector3<f64> = lab.velocities.column(i) - v;
            l += masses[i] * y.cross(&u);
            t += 0.5 * masses[i] * u.norm_squared();
            inertia += masses[i] * (Matrix3::identity() * y.norm_squared() - y * y.transpose());
        }
        let e_rot = 0.5 * l.dot(&angular_velocity(&inertia, &l));
        Internal { mass, position: x, velocity: v, l, e_rot, t_vib: t - e_rot }
    }
}

/// The collision sampler of one molecule.
pub struct Collision<'m, M, const N: usize, const NA: usize> {
    molecule: &'m M,
    spec: CollisionSpec,
    seed: u64,
    masses: [f64; NA],
    /// The reference geometry's atoms about each fragment's centre of mass.
    shapes: [Vec<Vector3<f64>>; 2],
    /// The reference internal coordinates (the fit's start).
    reference_q: SVector<f64, N>,
    /// Per fragment, the harmonic force constant along its bond (diatomics), hartree/bohr².
    force_constants: [Option<f64>; 2],
    /// Cumulative trajectory counts of the strata.
    bounds: Vec<u64>,
}

impl<'m, M: Molecule<N, NA>, const N: usize, const NA: usize> Collision<'m, M, N, NA> {
    /// Checks `spec` against the molecule and prepares the sampler.
    pub fn new(molecule: &'m M, spec: CollisionSpec, seed: u64) -> Result<Self, SampleError> {
        let bad = |s: String| Err(SampleError::Invalid(s));
        let masses = molecule.masses();
        let mut seen = [false; NA];
        for f in &spec.fragments {
            if f.is_empty() {
                return bad("a fragment has no atoms".into());
            }
            for &i in f {
                if i >= NA || seen[i] {
                    return bad(format!("atom {i} is in no fragment or in both"));
                }
                seen[i] = true;
            }
        }
        if seen.iter().any(|s| !s) {
            return bad("every atom must belong to one of the two fragments".into());
        }
        if !(spec.r0.is_finite() && spec.r0 > 0.0) {
            return bad(format!("the initial separation r0 = {} bohr is not positive", spec.r0));
        }
        if spec.strata.is_empty() {
            return bad("no impact-parameter strata".into());
        }
        for s in &spec.strata {
            if !(s.low >= 0.0 && s.high > s.low && s.high.is_finite() && s.weight > 0.0 && s.weight.is_finite()) {
                return bad(format!("the stratum [{}, {}] (weight {}) is not valid", s.low, s.high, s.weight));
            }
            if s.high >= spec.r0 {
                return bad(format!("an impact parameter up to {} bohr needs r0 above it, r0 = {}", s.high, spec.r0));
            }
        }
        let total: f64 = spec.strata.iter().map(|s| s.weight).sum();
        let mut bounds = Vec::new();
        let mut acc = 0.0;
        for (k, s) in spec.strata.iter().enumerate() {
            acc += s.weight;
            let end = if k + 1 == spec.strata.len() {
                spec.trajectories
            } else {
                ((spec.trajectories as f64) * acc / total).floor() as u64
            };
            let start = bounds.last().copied().unwrap_or(0);
            if end <= start {
                return bad(format!(
                    "stratum {k} gets no trajectory of the {}: raise trajectories or its weight",
                    spec.trajectories
                ));
            }
            bounds.push(end);
        }
        match &spec.energy {
            RelativeEnergy::Fixed(e) if !(e.is_finite() && *e > 0.0) => {
                return bad(format!("the relative energy {e} hartree is not positive"));
            }
            RelativeEnergy::Thermal(t) if !(t.is_finite() && *t > 0.0) => {
                return bad(format!("the temperature {t} K is not positive"));
            }
            _ => {}
        }
        let reference_q = molecule
            .reference_geometry()
            .ok_or_else(|| SampleError::Invalid(format!("{} has no reference geometry", molecule.name())))?;
        let mut r = SMatrix::<f64, 3, NA>::zeros();
        molecule.positions(&reference_q, &mut r);
        let shapes: [Vec<Vector3<f64>>; 2] = std::array::from_fn(|k| {
            let atoms = &spec.fragments[k];
            let m: f64 = atoms.iter().map(|&i| masses[i]).sum();
            let c: Vector3<f64> = atoms.iter().map(|&i| masses[i] * r.column(i)).sum::<Vector3<f64>>() / m;
            atoms.iter().map(|&i| r.column(i) - c).collect()
        });
        let mut sampler =
            Self { molecule, spec, seed, masses, shapes, reference_q, force_constants: [None, None], bounds };
        for k in 0..2 {
            let n = sampler.spec.fragments[k].len();
            if n == 1 && sampler.spec.rotation[k] != FragmentRotation::None {
                return bad(format!("fragment {} is one atom: it has no rotation", ["A", "B"][k]));
            }
            if sampler.spec.vibration[k] != FragmentVibration::None {
                if n != 2 {
                    return bad(format!(
                        "vibration is sampled for diatomic fragments only; fragment {} has {n} atoms",
                        ["A", "B"][k]
                    ));
                }
                sampler.force_constants[k] = Some(sampler.bond_force_constant(k)?);
            }
        }
        Ok(sampler)
    }

    /// The spec.
    pub fn spec(&self) -> &CollisionSpec {
        &self.spec
    }

    /// Fragment `k`'s atoms about its centre of mass in the reference geometry, bohr.
    pub fn reference_shape(&self, k: usize) -> &[Vector3<f64>] {
        &self.shapes[k]
    }

    /// The atom masses.
    pub fn masses(&self) -> &[f64; NA] {
        &self.masses
    }

    /// The stratum of trajectory `index`.
    pub fn stratum_of(&self, index: u64) -> usize {
        self.bounds.iter().position(|&b| index < b).unwrap_or(self.bounds.len() - 1)
    }

    /// Trajectories per stratum.
    pub fn stratum_counts(&self) -> Vec<u64> {
        let mut prev = 0;
        self.bounds
            .iter()
            .map(|&b| {
                let n = b - prev;
                prev = b;
                n
            })
            .collect()
    }

    /// The potential energy of lab positions `x` (fitted to q), hartree; None if they do not fit.
    pub fn potential_at(&self, x: &SMatrix<f64, 3, NA>) -> Option<f64> {
        let lab = LabState { positions: *x, velocities: SMatrix::zeros() };
        let options =
            FitOptions { initial_q: Some(self.reference_q), residual_tolerance: 1e-6, ..FitOptions::default() };
        from_lab_body(self.molecule, &lab, &options).ok().map(|(b, _, _)| self.molecule.potential(&b.q))
    }

    /// Positions with fragment `k`'s atoms at `shape` (about its centre of mass) and the other
    /// fragment in its reference shape, the centres `far` bohr apart along x.
    fn far_positions(&self, k: usize, shape: &[Vector3<f64>], far: f64) -> SMatrix<f64, 3, NA> {
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        for (j, &i) in self.spec.fragments[k].iter().enumerate() {
            x.set_column(i, &shape[j]);
        }
        let other = 1 - k;
        for (j, &i) in self.spec.fragments[other].iter().enumerate() {
            x.set_column(i, &(self.shapes[other][j] + Vector3::new(far, 0.0, 0.0)));
        }
        x
    }

    /// The potential energy of fragment `k` with its atoms at `shape` (about its centre of mass,
    /// any orientation) relative to its reference shape, with the other fragment in its reference
    /// shape at `4 r0`: the fragment's internal potential energy. Zero for a rigid fragment.
    pub fn fragment_potential(&self, k: usize, shape: &[Vector3<f64>]) -> Option<f64> {
        if shape.len() == 1 {
            return Some(0.0);
        }
        // Align the shape to the reference shape (Kabsch) so that only its deformation counts.
        let masses: Vec<f64> = self.spec.fragments[k].iter().map(|&i| self.masses[i]).collect();
        let mut c = Matrix3::zeros();
        for ((y, r), m) in shape.iter().zip(&self.shapes[k]).zip(&masses) {
            c += *m * r * y.transpose();
        }
        let svd = c.svd(true, true);
        let (u, vt) = (svd.u?, svd.v_t?);
        let mut d = Matrix3::identity();
        if (u * vt).determinant() < 0.0 {
            d[(2, 2)] = -1.0;
        }
        let rot = u * d * vt;
        let aligned: Vec<Vector3<f64>> = shape.iter().map(|y| rot * y).collect();
        let far = 4.0 * self.spec.r0;
        let u1 = self.potential_at(&self.far_positions(k, &aligned, far))?;
        let u0 = self.potential_at(&self.far_positions(k, &self.shapes[k], far))?;
        Some(u1 - u0)
    }

    /// `U''(r)` along the bond of diatomic fragment `k` at its reference length.
    fn bond_force_constant(&self, k: usize) -> Result<f64, SampleError> {
        let h = 1e-3;
        let shape = &self.shapes[k];
        let r_e = (shape[0] - shape[1]).norm();
        let at = |dr: f64| -> Result<f64, SampleError> {
            let s: Vec<Vector3<f64>> = shape.iter().map(|y| y * ((r_e + dr) / r_e)).collect();
            self.potential_at(&self.far_positions(k, &s, 4.0 * self.spec.r0)).ok_or_else(|| {
                SampleError::Invalid(format!(
                    "fragment {} cannot be stretched in {}'s coordinates (a rigid bond?): remove its vibration",
                    ["A", "B"][k],
                    self.molecule.name()
                ))
            })
        };
        let (m2, m1, z, p1, p2) = (at(-2.0 * h)?, at(-h)?, at(0.0)?, at(h)?, at(2.0 * h)?);
        let kf = (-p2 + 16.0 * p1 - 30.0 * z + 16.0 * m1 - m2) / (12.0 * h * h);
        if !(kf.is_finite() && kf > 0.0) {
            return Err(SampleError::Invalid(format!(
                "the bond of fragment {} has force constant {kf} hartree/bohr² at its reference length: not a minimum",
                ["A", "B"][k]
            )));
        }
        Ok(kf)
    }

    /// The harmonic force constant of diatomic fragment `k` (if its vibration is sampled).
    pub fn force_constant(&self, k: usize) -> Option<f64> {
        self.force_constants[k]
    }

    /// Draws fragment `k`: positions and velocities about its centre of mass, lab orientation.
    fn fragment(&self, k: usize, rng: &mut TrajectoryRng) -> FragmentAtoms {
        let atoms = &self.spec.fragments[k];
        let masses: Vec<f64> = atoms.iter().map(|&i| self.masses[i]).collect();
        let mut y = self.shapes[k].clone();
        let mut u = vec![Vector3::zeros(); y.len()];
        if let Some(kf) = self.force_constants[k] {
            let mu = masses[0] * masses[1] / (masses[0] + masses[1]);
            let omega = (kf / mu).sqrt();
            let (dr, rdot) = match self.spec.vibration[k] {
                FragmentVibration::Thermal(t) => {
                    let kt = BOLTZMANN * t;
                    let a: f64 = rng.sample(StandardNormal);
                    let b: f64 = rng.sample(StandardNormal);
                    (a * (kt / kf).sqrt(), b * (kt / mu).sqrt())
                }
                FragmentVibration::Quantum(v) => {
                    let e = (f64::from(v) + 0.5) * omega;
                    let amp = (2.0 * e / kf).sqrt();
                    let phase = std::f64::consts::TAU * rng.random::<f64>();
                    (amp * phase.cos(), -amp * omega * phase.sin())
                }
                FragmentVibration::None => (0.0, 0.0),
            };
            let r_e = (y[0] - y[1]).norm();
            for (yi, ui) in y.iter_mut().zip(u.iter_mut()) {
                *ui = *yi * (rdot / r_e);
                *yi *= (r_e + dr) / r_e;
            }
        }
        let rotation = haar(rng).to_rotation_matrix().into_inner();
        let inertia = fragment::inertia(&y, &masses);
        let l = match self.spec.rotation[k] {
            FragmentRotation::None => Vector3::zeros(),
            FragmentRotation::Thermal(t) => {
                let kt = BOLTZMANN * t;
                let e = SymmetricEigen::new(inertia);
                let top = e.eigenvalues.amax();
                let mut l = Vector3::zeros();
                for j in 0..3 {
                    let ij = e.eigenvalues[j];
                    if ij > 1e-10 * top {
                        let z: f64 = rng.sample(StandardNormal);
                        l += e.eigenvectors.column(j) * (z * (kt * ij).sqrt());
                    }
                }
                l
            }
            FragmentRotation::Quantum(j) => {
                let size = (f64::from(j) * (f64::from(j) + 1.0)).sqrt();
                let e = SymmetricEigen::new(inertia);
                let top = e.eigenvalues.amax();
                let small = e.eigenvalues.imin();
                let dir = uniform_direction(rng);
                if e.eigenvalues[small] <= 1e-10 * top {
                    // Linear: a direction perpendicular to the axis.
                    let axis: Vector3<f64> = e.eigenvectors.column(small).into();
                    let p = dir - axis * axis.dot(&dir);
                    let n = p.norm();
                    if n > 1e-12 { p * (size / n) } else { axis.cross(&Vector3::x()).normalize() * size }
                } else {
                    dir * size
                }
            }
        };
        let w = fragment::angular_velocity(&inertia, &l);
        for (yi, ui) in y.iter_mut().zip(u.iter_mut()) {
            *ui += w.cross(yi);
            *ui = rotation * *ui;
            *yi = rotation * *yi;
        }
        (y, u)
    }

    /// The lab state and what was drawn for trajectory `index`.
    pub fn draw_lab(&self, index: u64) -> (LabState<NA>, Drawn) {
        let mut rng = stream(self.seed, index);
        let stratum = self.stratum_of(index);
        let s = &self.spec.strata[stratum];
        let u: f64 = rng.random();
        let b = (s.low * s.low + u * (s.high * s.high - s.low * s.low)).sqrt();
        let energy = match self.spec.energy {
            RelativeEnergy::Fixed(e) => e,
            RelativeEnergy::Thermal(t) => {
                // Γ(2, kT): the sum of two exponential variates; 1 − u is in (0, 1].
                let (u1, u2): (f64, f64) = (1.0 - rng.random::<f64>(), 1.0 - rng.random::<f64>());
                -BOLTZMANN * t * (u1 * u2).ln()
            }
        };
        let (ya, ua) = self.fragment(0, &mut rng);
        let (yb, ub) = self.fragment(1, &mut rng);
        let drawn = Drawn { b, stratum, energy };
        (self.place(&[(ya, ua), (yb, ub)], b, energy), drawn)
    }

    /// Places the fragments (atoms about their centres, lab orientation) at separation r0 with
    /// impact parameter `b` and relative energy `energy`: B at `(0, b, −√(r0² − b²))` from A,
    /// moving along +z relative to A; the centre of mass at rest at the origin.
    pub fn place(&self, fragments: &[FragmentAtoms; 2], b: f64, energy: f64) -> LabState<NA> {
        let ma: f64 = self.spec.fragments[0].iter().map(|&i| self.masses[i]).sum();
        let mb: f64 = self.spec.fragments[1].iter().map(|&i| self.masses[i]).sum();
        let total = ma + mb;
        let mu = ma * mb / total;
        let r = Vector3::new(0.0, b, -(self.spec.r0 * self.spec.r0 - b * b).max(0.0).sqrt());
        let v = Vector3::new(0.0, 0.0, (2.0 * energy / mu).sqrt());
        let centres = [(-mb / total * r, -mb / total * v), (ma / total * r, ma / total * v)];
        let mut lab = LabState::<NA>::default();
        for k in 0..2 {
            for (j, &i) in self.spec.fragments[k].iter().enumerate() {
                lab.positions.set_column(i, &(centres[k].0 + fragments[k].0[j]));
                lab.velocities.set_column(i, &(centres[k].1 + fragments[k].1[j]));
            }
        }
        lab
    }

    /// The body state of a lab state (fitted to the molecule's coordinates).
    pub fn body_of(&self, lab: &LabState<NA>) -> Result<BodyState<N>, SampleError> {
        let options =
            FitOptions { initial_q: Some(self.reference_q), residual_tolerance: 1e-6, ..FitOptions::default() };
        let (body, _, report) = from_lab_body(self.molecule, lab, &options)
            .map_err(|e| SampleError::Invalid(format!("the collision geometry does not fit the molecule: {e}")))?;
        let kinetic = lab.internal_kinetic_energy(&self.masses);
        if report.discarded_kinetic_energy > 1e-9 * kinetic.max(1e-12) {
            return Err(SampleError::Invalid(format!(
                "{} hartree of the drawn kinetic energy moves coordinates the molecule holds fixed \
                 (a vibration of a rigid fragment?)",
                report.discarded_kinetic_energy
            )));
        }
        Ok(body)
    }

    /// The initial state and what was drawn for trajectory `index`.
    pub fn draw_detail(&self, index: u64) -> Result<(BodyState<N>, Drawn), SampleError> {
        let (lab, drawn) = self.draw_lab(index);
        Ok((self.body_of(&lab)?, drawn))
    }
}

impl<M: Molecule<N, NA> + Sync, const N: usize, const NA: usize> super::Sampler<N> for Collision<'_, M, N, NA> {
    fn draw(&self, index: u64) -> Result<BodyState<N>, SampleError> {
        self.draw_detail(index).map(|(b, _)| b)
    }
}
