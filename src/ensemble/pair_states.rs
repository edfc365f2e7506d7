//! Pair states: each sampled state of a pair ensemble classified as bound, metastable or free;
//! counts, fractions and means per class; the dipole correlation per class; canonical sampling
//! restricted to `H_rel < E_max`; the dimer equilibrium constant.
//!
//! # Definitions
//!
//! The scene's `[pairs]` table names two groups of atoms (the monomers, A and B) and the
//! coordinate `distance` that separates them. With `m_A`, `m_B` the groups' masses,
//! `μ = m_A m_B / (m_A + m_B)`, `R` and `Ṙ` the vector between the groups' centres of mass and its
//! rate of change (from the body-frame positions `x_i(q)` and velocities
//! `ẋ_i = ω × x_i + Σ_k ∂x_i/∂q_k q̇_k`, `(ω, q̇) = M⁻¹ (J, p)`), and `L = μ R × Ṙ`:
//!
//! ```text
//! V(q)   = U(q) − U(q | distance = R_far)             the interaction energy
//! H_rel  = ½ μ |Ṙ|² + V(q)                             the energy of relative motion
//! U_eff(r) = U(q | distance = r) − U(q | distance = R_far) + |L|² / (2 μ r²)
//! ```
//!
//! `U(q | distance = r)` is the potential at the state's own other coordinates with the distance
//! coordinate set to r; `R_far` is `[pairs] far`, by default the upper limit of the distance
//! coordinate in the sampled region (the dissociation limit is the potential there, at the
//! state's own monomer geometry and orientation). The class of a state:
//!
//! - **bound**: `H_rel < 0`;
//! - **metastable**: `H_rel ≥ 0`, and `U_eff` rises above `H_rel` somewhere between the state's
//!   distance and `R_far` (the pair is inside the centrifugal barrier of its own `L`);
//! - **free**: otherwise.
//!
//! For an atom–atom pair this is the classic division of Stogryn and Hirschfelder (1959) with
//! `H_rel` the energy of the relative motion; for a molecule–atom pair `H_rel` leaves out the
//! monomers' rotation and vibration, and `U_eff` is scanned along the distance coordinate at
//! fixed angles ([`SCAN_POINTS`] points, uniform in r).
//!
//! # Dimer constant
//!
//! With `Z` the region's configurational integral (`Sampler::configurational_integral`), `f_b`
//! the bound fraction and `Z_A Z_B` the monomers' configurational integrals (`[pairs]
//! monomer_integral`, the same measure and energy zero as the complex's potential, whose limit at
//! infinite separation is `U_A + U_B`): `K_c = f_b Z / (Z_A Z_B)` (bohr³, per molecule; ×
//! 1.4818e-25 for cm³/molecule) and `K_p = K_c / kT` (atm⁻¹). For an atom–atom pair,
//! `Z_A Z_B = 1`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use serde::{Deserialize, Serialize};
use serde_json::json;
use toml::Spanned;

use super::quantity::Quantity;
use super::runner::Plan;
use crate::output::OutputFile;
use crate::runtime::HamiltonianError;
use crate::runtime::Molecule;
use crate::runtime::diagnostic::FileError;
use crate::runtime::ensemble::Moments;
use crate::runtime::hamiltonian::BodyState;
use crate::runtime::hamiltonian::MetricFactor;
use crate::runtime::molecule::KineticMatrices;
use crate::runtime::nalgebra::{SMatrix, SVector, Vector3};
use crate::runtime::sample::{BOLTZMANN, SampleError, Sampler, Spec};
use crate::runtime::spectrum::Spectrum;
use crate::runtime::surface::Dipole;
use crate::scene::Scene;

/// Points of the scan of `U_eff` from a state's distance to `R_far`.
pub const SCAN_POINTS: usize = 256;

/// Proposals a restricted sampler draws for one state before it gives up.
pub const MAX_ATTEMPTS: u64 = 1 << 20;

/// One bohr, cm.
pub const BOHR_CM: f64 = 5.291_772_109_03e-9;

/// The Boltzmann constant, J/K, and one atmosphere, Pa.
const BOLTZMANN_SI: f64 = 1.380_649e-23;
const ATMOSPHERE_PA: f64 = 101_325.0;

/// The classes, in the order of every per-class output.
pub const CLASSES: [&str; 3] = ["bound", "metastable", "free"];

/// The class of a pair state: an index into [`CLASSES`].
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Class {
    /// `H_rel < 0`.
    Bound = 0,
    /// `H_rel ≥ 0` inside the centrifugal barrier.
    Metastable = 1,
    /// Otherwise.
    Free = 2,
}

/// The relative motion of one state.
#[derive(Copy, Clone, Debug)]
pub struct Relative {
    /// `H_rel`, hartree.
    pub energy: f64,
    /// `|L|`, ħ.
    pub angular_momentum: f64,
    /// The distance coordinate, bohr.
    pub distance: f64,
    /// The class.
    pub class: Class,
}

// ---------------------------------------------------------------------------------------------
// The scene table.

/// The `[pairs]` table as written (names unbound), with places.
#[derive(Clone, Debug)]
pub struct PairScene {
    monomers: Vec<Vec<Spanned<String>>>,
    distance: Spanned<String>,
    far: Option<Spanned<f64>>,
    max_energy: Option<Spanned<f64>>,
    monomer_integral: Option<Spanned<f64>>,
}

const HELP: &str = "[pairs] takes monomers (two lists of atom labels), distance (the coordinate separating them), \
                    far (scene length unit), max_energy (hartree) and monomer_integral (bohr^(3 atoms - 6)); see \
                    docs/src/reference/ensemble.md";

/// Parses `[pairs]` of the scene (None: no table).
pub fn parse_pairs(scene: &Scene) -> Result<Option<PairScene>, FileError> {
    let src = &scene.source();
    let raw = scene.tables.pairs.clone().map_err(|e| crate::scene::toml_error(src, &e, HELP))?;
    let Some(table) = raw.pairs else { return Ok(None) };
    let t = table.into_inner();
    let positive = |v: &Option<Spanned<f64>>, key: &str, help: &str| -> Result<(), FileError> {
        match v {
            Some(x) if !(x.get_ref().is_finite() && *x.get_ref() > 0.0) => Err(src.error(
                x.span(),
                format!("`pairs.{key}` must be a positive finite number, got {}", x.get_ref()),
                help.to_owned(),
            )),
            _ => Ok(()),
        }
    };
    positive(&t.far, "far", "give the distance at which the monomers count as separated, in the scene's length unit")?;
    positive(
        &t.monomer_integral,
        "monomer_integral",
        "give Z_A Z_B, the monomers' configurational integrals (bohr^(3 atoms - 6); 1 for two atoms)",
    )?;
    if let Some(e) = &t.max_energy
        && !e.get_ref().is_finite()
    {
        return Err(src.error(
            e.span(),
            "`pairs.max_energy` must be finite",
            "give E_max in hartree, e.g. 0 for bound dimers",
        ));
    }
    if t.monomers.get_ref().len() != 2 || t.monomers.get_ref().iter().any(Vec::is_empty) {
        return Err(src.error(
            t.monomers.span(),
            "`pairs.monomers` must be two non-empty lists of atom labels",
            "write e.g. monomers = [[\"C\", \"O1\", \"O2\"], [\"Ar\"]]",
        ));
    }
    Ok(Some(PairScene {
        monomers: t.monomers.into_inner(),
        distance: t.distance,
        far: t.far,
        max_energy: t.max_energy,
        monomer_integral: t.monomer_integral,
    }))
}

/// `[pairs]` bound to a molecule, atomic units.
#[derive(Clone, Debug, PartialEq)]
pub struct PairStates {
    /// Atom indices of each monomer.
    pub monomers: [Vec<usize>; 2],
    /// The distance coordinate's index.
    pub distance: usize,
    /// `R_far`, bohr.
    pub far: f64,
    /// Restricted sampling: only states with `H_rel < max_energy` (hartree).
    pub max_energy: Option<f64>,
    /// `Z_A Z_B`, bohr^(3 atoms − 6).
    pub monomer_integral: Option<f64>,
    /// The temperature of a thermal ensemble, K.
    pub temperature: Option<f64>,
}

impl PairScene {
    /// Binds the table to molecule `m` and the ensemble's sampling `spec` (None for a method that
    /// is not one of the runtime's [`Spec`]s); every name and value is checked at its place.
    pub fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        scene: &Scene,
        spec: Option<&Spec<N>>,
    ) -> Result<PairStates, FileError> {
        let src = scene.source();
        let atoms = m.atoms();
        let mut monomers: [Vec<usize>; 2] = [Vec::new(), Vec::new()];
        for (g, list) in self.monomers.iter().enumerate() {
            for label in list {
                let i = atoms.iter().position(|a| a.label == label.get_ref()).ok_or_else(|| {
                    let names: Vec<&str> = atoms.iter().map(|a| a.label).collect();
                    src.error(
                        label.span(),
                        format!("{} has no atom `{}`", m.name(), label.get_ref()),
                        format!("the atoms are {}", names.join(", ")),
                    )
                })?;
                if monomers.iter().any(|g| g.contains(&i)) {
                    return Err(src.error(
                        label.span(),
                        format!("atom `{}` is named twice in `pairs.monomers`", label.get_ref()),
                        "name each atom in one monomer at most",
                    ));
                }
                monomers[g].push(i);
            }
        }
        let coords = m.coordinates();
        let distance = coords.iter().position(|c| c.name == self.distance.get_ref()).ok_or_else(|| {
            let names: Vec<&str> = coords.iter().map(|c| c.name).collect();
            src.error(
                self.distance.span(),
                format!("{} has no coordinate `{}`", m.name(), self.distance.get_ref()),
                format!("the coordinates are {}", names.join(", ")),
            )
        })?;
        let (region, temperature) = match spec {
            Some(Spec::Thermal { region, temperature }) => (Some(region), Some(*temperature)),
            Some(Spec::Microcanonical { region, .. }) => (Some(region), None),
            _ => (None, None),
        };
        let scale = scene.units.coordinate_to_au(coords[distance].unit, 1.0);
        let far = match (&self.far, region.and_then(|r| r.limits[distance])) {
            (Some(f), _) => {
                let v = f.get_ref() * scale;
                let (lo, hi) = coords[distance].range;
                if !(v > lo && v <= hi) {
                    return Err(src.error(
                        f.span(),
                        format!("`pairs.far` = {} is outside the range of `{}`", f.get_ref(), coords[distance].name),
                        "give a distance inside the coordinate's range",
                    ));
                }
                v
            }
            (None, Some((_, hi))) => hi,
            (None, None) => {
                return Err(src.error(
                    self.distance.span(),
                    format!("no far distance for `{}`: the sampled region does not limit it", self.distance.get_ref()),
                    "add far = ... (scene length unit) to [pairs], or limits for the distance to the region",
                ));
            }
        };
        if let Some(e) = &self.max_energy
            && temperature.is_none()
        {
            return Err(src.error(
                e.span(),
                "`pairs.max_energy` restricts a thermal ensemble, and this one is not thermal",
                "use method = \"thermal\", or remove max_energy",
            ));
        }
        if let Some(e) = &self.monomer_integral
            && temperature.is_none()
        {
            return Err(src.error(
                e.span(),
                "`pairs.monomer_integral` gives the dimer constant of a thermal ensemble, and this one is not thermal",
                "use method = \"thermal\", or remove monomer_integral",
            ));
        }
        Ok(PairStates {
            monomers,
            distance,
            far,
            max_energy: self.max_energy.as_ref().map(|e| *e.get_ref()),
            monomer_integral: self.monomer_integral.as_ref().map(|e| *e.get_ref()),
            temperature,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Classification.

/// Why a state's relative motion cannot be classified.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ClassifyError {
    /// The velocities are not defined: the metric cannot be factored at the state's geometry.
    #[error(transparent)]
    Metric(#[from] HamiltonianError),
    /// The energy or angular momentum of the relative motion is not finite.
    #[error("the energy of relative motion is not finite ({energy}, |L| = {angular_momentum})")]
    NonFinite {
        /// The energy of relative motion, hartree.
        energy: f64,
        /// |L| of the relative motion, ħ.
        angular_momentum: f64,
    },
}

impl PairStates {
    /// The relative motion and class of `s`; an error when the velocities are not defined.
    pub fn classify<M, const N: usize, const NA: usize>(
        &self,
        m: &M,
        s: &BodyState<N>,
    ) -> Result<Relative, ClassifyError>
    where
        M: Molecule<N, NA> + ?Sized,
    {
        let mut kin = KineticMatrices::default();
        m.kinetic(&s.q, &mut kin);
        let (omega, qdot) = MetricFactor::new(&kin, &s.q)?.solve(&s.j, &s.p);
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        m.positions(&s.q, &mut x);
        let mut dx = [SMatrix::<f64, 3, NA>::zeros(); N];
        m.positions_jacobian(&s.q, &mut dx);
        let masses = m.masses();
        let mut centre = [Vector3::zeros(); 2];
        let mut velocity = [Vector3::zeros(); 2];
        let mut mass = [0.0; 2];
        for (g, atoms) in self.monomers.iter().enumerate() {
            for &i in atoms {
                let xi: Vector3<f64> = x.column(i).into();
                let mut vi = omega.cross(&xi);
                for (k, d) in dx.iter().enumerate() {
                    vi += d.column(i) * qdot[k];
                }
                centre[g] += masses[i] * xi;
                velocity[g] += masses[i] * vi;
                mass[g] += masses[i];
            }
            centre[g] /= mass[g];
            velocity[g] /= mass[g];
        }
        let mu = mass[0] * mass[1] / (mass[0] + mass[1]);
        let (r, v) = (centre[1] - centre[0], velocity[1] - velocity[0]);
        let l = mu * r.cross(&v).norm();
        let at = |d: f64| {
            let mut q: SVector<f64, N> = s.q;
            q[self.distance] = d;
            m.potential(&q)
        };
        let limit = at(self.far);
        let energy = 0.5 * mu * v.norm_squared() + m.potential(&s.q) - limit;
        if !(energy.is_finite() && l.is_finite()) {
            return Err(ClassifyError::NonFinite { energy, angular_momentum: l });
        }
        let d0 = s.q[self.distance];
        let class = if energy < 0.0 {
            Class::Bound
        } else {
            let barrier = (1..=SCAN_POINTS).any(|i| {
                let r = d0 + (self.far - d0) * i as f64 / SCAN_POINTS as f64;
                r > 0.0 && at(r) - limit + l * l / (2.0 * mu * r * r) > energy
            });
            if barrier && d0 < self.far { Class::Metastable } else { Class::Free }
        };
        Ok(Relative { energy, angular_momentum: l, distance: d0, class })
    }
}

// ---------------------------------------------------------------------------------------------
// Restricted sampling.

/// Canonical sampling restricted to `H_rel < E_max` by rejection: proposal `a` of state `index`
/// is the inner sampler's state `index + a · 2⁴⁰`.
pub struct Restricted<'a, M, const N: usize> {
    inner: &'a dyn Sampler<N>,
    molecule: &'a M,
    pairs: &'a PairStates,
    max_energy: f64,
    proposals: AtomicU64,
    accepted: AtomicU64,
}

impl<'a, M, const N: usize> Restricted<'a, M, N> {
    /// The restriction of `inner` to `H_rel < max_energy`.
    pub fn new(inner: &'a dyn Sampler<N>, molecule: &'a M, pairs: &'a PairStates, max_energy: f64) -> Self {
        Self { inner, molecule, pairs, max_energy, proposals: AtomicU64::new(0), accepted: AtomicU64::new(0) }
    }

    /// The state and the proposals it took.
    pub fn draw_counted<const NA: usize>(&self, index: u64) -> Result<(BodyState<N>, u64), SampleError>
    where
        M: Molecule<N, NA> + Sync,
    {
        for a in 0..MAX_ATTEMPTS {
            let s = self.inner.draw(index.wrapping_add(a << 40))?;
            match self.pairs.classify(self.molecule, &s) {
                Ok(r) if r.energy < self.max_energy => return Ok((s, a + 1)),
                _ => {}
            }
        }
        Err(SampleError::Invalid(format!(
            "no state with H_rel < {} hartree in {MAX_ATTEMPTS} proposals: raise pairs.max_energy",
            self.max_energy
        )))
    }
}

/// The restricted sampler for the ensemble (the molecule type fixed).
pub struct RestrictedSampler<'a, M, const N: usize, const NA: usize>(pub Restricted<'a, M, N>);

impl<M, const N: usize, const NA: usize> Sampler<N> for RestrictedSampler<'_, M, N, NA>
where
    M: Molecule<N, NA> + Sync,
{
    fn draw(&self, index: u64) -> Result<BodyState<N>, SampleError> {
        let (s, tries) = self.0.draw_counted(index)?;
        self.0.proposals.fetch_add(tries, Ordering::Relaxed);
        self.0.accepted.fetch_add(1, Ordering::Relaxed);
        Ok(s)
    }

    /// The inner sampler's (the whole region's) integral.
    fn configurational_integral(&self) -> Option<(f64, f64)> {
        self.0.inner.configurational_integral()
    }
}

// ---------------------------------------------------------------------------------------------
// The census of the sampled states.

/// Counts and means per class over the sampled states.
#[derive(Clone, Debug, Default)]
pub struct Census {
    /// States per class.
    pub counts: [u64; 3],
    /// `H_rel` per class, hartree.
    pub energy: [Moments; 3],
    /// `|L|` per class, ħ.
    pub angular_momentum: [Moments; 3],
    /// The distance coordinate per class, bohr.
    pub distance: [Moments; 3],
    /// `|μ|²` per class, (e·bohr)² (a molecule with a dipole).
    pub dipole_squared: [Moments; 3],
    /// `H_rel` over every state.
    pub energy_all: Moments,
    /// States not drawn or not classified.
    pub left_out: u64,
    /// Restricted sampling: `(E_max, proposals, accepted)`.
    pub restriction: Option<(f64, u64, u64)>,
    /// `(ln Z, relative standard error)` of the region.
    pub integral: Option<(f64, f64)>,
}

impl Census {
    /// States classified.
    pub fn total(&self) -> u64 {
        self.counts.iter().sum()
    }

    /// `(fraction, standard error)` of class `c` among the classified states.
    pub fn fraction(&self, c: usize) -> (f64, f64) {
        let n = self.total() as f64;
        let f = self.counts[c] as f64 / n;
        (f, (f * (1.0 - f) / n).sqrt())
    }

    /// The acceptance of the restriction and its standard error (1, 0 without one).
    pub fn acceptance(&self) -> (f64, f64) {
        match self.restriction {
            Some((_, tries, ok)) if tries > 0 => {
                let a = ok as f64 / tries as f64;
                (a, (a * (1.0 - a) / tries as f64).sqrt())
            }
            _ => (1.0, 0.0),
        }
    }

    /// The fraction of the whole region's canonical distribution that is bound, with its standard
    /// error: the bound fraction of the states times the acceptance; None when a restriction
    /// below 0 rejects bound states.
    pub fn bound_fraction_of_region(&self) -> Option<(f64, f64)> {
        if matches!(self.restriction, Some((e, _, _)) if e < 0.0) {
            return None;
        }
        let (f, sf) = self.fraction(0);
        let (a, sa) = self.acceptance();
        let x = f * a;
        Some((x, x * ((sf / f.max(f64::MIN_POSITIVE)).powi(2) + (sa / a).powi(2)).sqrt()))
    }

    /// `(K_c, standard error)` in bohr³: `f_b Z / (Z_A Z_B)`.
    pub fn dimer_constant(&self, monomer_integral: f64) -> Option<(f64, f64)> {
        let (f, sf) = self.bound_fraction_of_region()?;
        let (log_z, rel) = self.integral?;
        let k = f * log_z.exp() / monomer_integral;
        Some((k, k * ((sf / f.max(f64::MIN_POSITIVE)).powi(2) + rel * rel).sqrt()))
    }
}

/// Classifies the states `0..n` of `sampler` (the ensemble's initial states).
pub fn census<M, const N: usize, const NA: usize>(
    m: &M,
    pairs: &PairStates,
    sampler: &dyn Sampler<N>,
    restricted: Option<&Restricted<'_, M, N>>,
    n: u64,
) -> Census
where
    M: Molecule<N, NA> + Sync,
{
    let mut c = Census { integral: sampler.configurational_integral(), ..Census::default() };
    let (mut tries, mut ok) = (0u64, 0u64);
    let mut mu = Vector3::zeros();
    for index in 0..n {
        let drawn = match restricted {
            Some(r) => r.draw_counted(index).map(|(s, t)| {
                tries += t;
                ok += 1;
                s
            }),
            None => sampler.draw(index),
        };
        let Ok(s) = drawn else {
            c.left_out += 1;
            continue;
        };
        let Ok(rel) = pairs.classify(m, &s) else {
            c.left_out += 1;
            continue;
        };
        let k = rel.class as usize;
        c.counts[k] += 1;
        c.energy[k].add(rel.energy);
        c.energy_all.add(rel.energy);
        c.angular_momentum[k].add(rel.angular_momentum);
        c.distance[k].add(rel.distance);
        if let Some(dipole) = m.dipole() {
            dipole.moment(&s.q, &mut mu);
            c.dipole_squared[k].add(mu.norm_squared());
        }
    }
    c.restriction = restricted.map(|r| (r.max_energy, tries, ok));
    c
}

// ---------------------------------------------------------------------------------------------
// The dipole correlation per class.

/// Per class, the moments of the class's contribution to `C(τ) = ⟨μ(0)·μ(τ)⟩` (the product for
/// a trajectory of the class, 0 for the others) per lag: the three sum to the total C.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ClassCorrelations {
    /// `[class][lag]`, lags from −T to T; empty until the first trajectory.
    pub lags: Vec<Vec<Moments>>,
    /// Completed trajectories whose state could not be classified (in no class).
    pub unclassified: u64,
}

impl ClassCorrelations {
    /// Merges `other` (the trajectories after this one's) in.
    pub fn merge(&mut self, other: &ClassCorrelations) {
        self.unclassified += other.unclassified;
        if other.lags.is_empty() {
            return;
        }
        if self.lags.is_empty() {
            self.lags = other.lags.clone();
            return;
        }
        for (a, b) in self.lags.iter_mut().zip(&other.lags) {
            for (x, y) in a.iter_mut().zip(b) {
                x.merge(y);
            }
        }
    }
}

/// Folds one completed pair-estimator trajectory (forward `kf`, backward `kb` outputs) of state
/// `drawn` into the per-class correlations, when the plan classifies pairs and correlates the
/// lab-frame dipole.
#[allow(clippy::too_many_arguments)]
pub fn fold<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    drawn: &BodyState<N>,
    acc: &mut ClassCorrelations,
    forward: &[f64],
    kf: usize,
    backward: &[f64],
    kb: usize,
) where
    M: Molecule<N, NA>,
{
    let Some(pairs) = &plan.pairs else { return };
    let Some(axes) = dipole_columns(plan) else { return };
    let lags = plan.correlation_lags();
    if lags == 0 || kf == 0 {
        return;
    }
    let Ok(rel) = pairs.classify(plan.molecule, drawn) else {
        acc.unclassified += 1;
        return;
    };
    if acc.lags.is_empty() {
        acc.lags = vec![vec![Moments::new(); 2 * lags - 1]; 3];
    }
    let nq = plan.quantities.len();
    let dot = |a: &[f64], k: usize| axes.iter().map(|&qi| forward[qi] * a[k * nq + qi]).sum::<f64>();
    for (class, c) in acc.lags.iter_mut().enumerate() {
        let on = if class == rel.class as usize { 1.0 } else { 0.0 };
        for k in 0..lags {
            let f = if k < kf { dot(forward, k) } else { 0.0 };
            c[lags - 1 + k].add(on * f);
            if k > 0 {
                let b = if k < kb { dot(backward, k) } else { 0.0 };
                c[lags - 1 - k].add(on * b);
            }
        }
    }
}

/// The quantity indices of `mu_x`, `mu_y`, `mu_z`, if all three are observed.
fn dipole_columns<M, const N: usize, const NA: usize>(plan: &Plan<'_, M, N, NA>) -> Option<[usize; 3]> {
    let find = |axis| plan.quantities.iter().position(|q| *q == Quantity::LabDipole(axis));
    Some([find(0)?, find(1)?, find(2)?])
}

// ---------------------------------------------------------------------------------------------
// Outputs.

/// The per-class spectra: the cosine transform of each class's windowed, even contribution.
fn class_spectra<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    acc: &ClassCorrelations,
) -> Vec<Spectrum> {
    let lags = plan.correlation_lags();
    acc.lags
        .iter()
        .map(|c| {
            let even: Vec<f64> = (0..lags)
                .map(|k| 0.5 * (c[lags - 1 + k].mean() + c[lags - 1 - k].mean()) * super::pair::flat_top(k, lags))
                .collect();
            Spectrum::from_correlation(&even, plan.interval, plan.spectrum.max_wavenumber, super::spectrum::PADDING)
        })
        .collect()
}

/// Writes `pair_states.csv` and, with per-class correlations, `correlations_by_state.csv` and
/// `spectrum_by_state.csv`.
pub fn write<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    census: &Census,
    acc: &ClassCorrelations,
    time_unit: (&str, f64),
    dir: &Path,
) -> Result<Vec<PathBuf>, crate::Error> {
    let mut files = Vec::new();
    let mut f = OutputFile::create(dir, "pair_states.csv")?;
    f.line(
        "class,count,fraction,fraction_stderr,H_rel_mean_hartree,H_rel_stderr_hartree,L_mean_hbar,L_stderr_hbar,\
         distance_mean_bohr,distance_stderr_bohr,mu2_mean_(e*bohr)^2,mu2_stderr_(e*bohr)^2",
    )?;
    for (c, name) in CLASSES.iter().enumerate() {
        let (fr, se) = census.fraction(c);
        let m = |x: &Moments| format!("{:?},{:?}", x.mean(), x.standard_error());
        f.line(&format!(
            "{name},{},{fr:?},{se:?},{},{},{},{}",
            census.counts[c],
            m(&census.energy[c]),
            m(&census.angular_momentum[c]),
            m(&census.distance[c]),
            m(&census.dipole_squared[c])
        ))?;
    }
    f.flush()?;
    files.push(f.path().to_owned());
    if acc.lags.is_empty() {
        return Ok(files);
    }
    let lags = plan.correlation_lags();
    let (tu, ts) = time_unit;
    let mut f = OutputFile::create(dir, "correlations_by_state.csv")?;
    let mut header = vec![format!("tau_{tu}")];
    for name in CLASSES {
        header.push(format!("C_{name}_(e*bohr)^2"));
        header.push(format!("C_{name}_stderr_(e*bohr)^2"));
    }
    f.line(&header.join(","))?;
    for i in 0..2 * lags - 1 {
        let tau = (i as f64 - (lags - 1) as f64) * plan.interval / ts;
        let mut row = format!("{tau:?}");
        for c in &acc.lags {
            row.push_str(&format!(",{:?},{:?}", c[i].mean(), c[i].standard_error()));
        }
        f.line(&row)?;
    }
    f.flush()?;
    files.push(f.path().to_owned());
    let spectra = class_spectra(plan, acc);
    let mut f = OutputFile::create(dir, "spectrum_by_state.csv")?;
    let mut header = vec!["wavenumber_cm-1".to_owned()];
    for name in CLASSES {
        header.push(format!("lineshape_{name}_e2bohr2_per_hartree"));
    }
    f.line(&header.join(","))?;
    for (j, nu) in spectra[0].wavenumber.iter().enumerate() {
        let mut row = format!("{nu:?}");
        for s in &spectra {
            row.push_str(&format!(",{:?}", s.lineshape.get(j).copied().unwrap_or(f64::NAN)));
        }
        f.line(&row)?;
    }
    f.flush()?;
    files.push(f.path().to_owned());
    Ok(files)
}

/// The summary.json block.
pub fn summary(pairs: &PairStates, census: &Census, acc: &ClassCorrelations) -> serde_json::Value {
    let finite = |x: f64| x.is_finite().then_some(x);
    let classes: serde_json::Map<String, serde_json::Value> = CLASSES
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let (f, se) = census.fraction(c);
            (
                (*name).to_owned(),
                json!({
                    "count": census.counts[c],
                    "fraction": finite(f),
                    "fraction_stderr": finite(se),
                    "H_rel_mean_hartree": finite(census.energy[c].mean()),
                    "H_rel_stderr_hartree": finite(census.energy[c].standard_error()),
                    "M0_phase_space": finite(census.dipole_squared[c].mean()),
                    "M0_phase_space_stderr": finite(census.dipole_squared[c].standard_error()),
                }),
            )
        })
        .collect();
    let (a, sa) = census.acceptance();
    let kt_atm_cm3 = pairs.temperature.map(|t| BOLTZMANN_SI * t / ATMOSPHERE_PA * 1e6);
    let constant = pairs.monomer_integral.and_then(|z| census.dimer_constant(z)).map(|(k, se)| {
        let cm3 = BOHR_CM.powi(3);
        json!({
            "K_c_bohr3": k,
            "K_c_stderr_bohr3": se,
            "K_c_cm3_per_molecule": k * cm3,
            "K_c_stderr_cm3_per_molecule": se * cm3,
            "K_p_atm-1": kt_atm_cm3.map(|kt| k * cm3 / kt),
            "K_p_stderr_atm-1": kt_atm_cm3.map(|kt| se * cm3 / kt),
            "monomer_integral": pairs.monomer_integral,
            "definition": "K_c = f_bound Z / (Z_A Z_B), f_bound the bound fraction of the region's canonical distribution (times the acceptance of a restriction), Z the configurational integral; K_p = K_c / kT",
        })
    });
    json!({
        "definition": "H_rel = mu |dR/dt|^2 / 2 + U(q) - U(q | distance = far); bound: H_rel < 0; metastable: H_rel >= 0 and U_eff(r) = U(q | distance = r) - U(q | distance = far) + L^2/(2 mu r^2) exceeds H_rel for some r between the state's distance and far; free: otherwise",
        "far_bohr": pairs.far,
        "states": census.total(),
        "left_out": census.left_out,
        "classes": classes,
        "H_rel_mean_hartree": finite(census.energy_all.mean()),
        "H_rel_stderr_hartree": finite(census.energy_all.standard_error()),
        "restriction": census.restriction.map(|(e, tries, ok)| json!({
            "max_energy_hartree": e,
            "proposals": tries,
            "accepted": ok,
            "acceptance": a,
            "acceptance_stderr": sa,
        })),
        "bound_fraction_of_region": census.bound_fraction_of_region().map(|(f, s)| json!({"fraction": f, "stderr": s})),
        "dimer_constant": constant,
        "correlations_unclassified": acc.unclassified,
        "kT_hartree": pairs.temperature.map(|t| BOLTZMANN * t),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_non_finite_relative_motion_says_its_numbers() {
        let e = ClassifyError::NonFinite { energy: f64::INFINITY, angular_momentum: 2.5 };
        assert_eq!(e.to_string(), "the energy of relative motion is not finite (inf, |L| = 2.5)");
    }
}
