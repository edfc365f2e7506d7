//! Final states of collisions: the channels of a lab state (relative translation, each
//! fragment's rotation and vibration), the deflection angle, the outcome, and their reduction
//! over an ensemble to cross sections and energy-transfer moments.
//!
//! # Definitions (atomic units)
//!
//! * `R = X_B − X_A`, `v = V_B − V_A` (centres of mass), `μ = m_A m_B / (m_A + m_B)`,
//!   `E_trans = ½ μ |v|²`.
//! * Fragment `k`: `L_k = Σ m_i y_i × u_i` about its centre of mass, `E_rot = ½ L·I⁺L` with its
//!   inertia tensor `I` (pseudo-inverse: no rotation about a linear fragment's axis),
//!   `E_vib = T_internal − E_rot + U_k`, where `U_k` is the molecule's potential with the
//!   fragment's shape and the other fragment in its reference shape at 4 r0, minus the same with
//!   both at their reference shapes (zero for an atom or a rigid fragment).
//! * Deflection `χ = arccos(v̂_initial · v̂_final)`, in [0, π].
//! * `ΔE = E_trans(final) − E_trans(initial)`: translational energy gained.
//! * Cross section of an outcome: `σ = Σ_s A_s n_s(outcome)/n_s` with `A_s = π (b_hi² − b_lo²)`
//!   and `n_s` the stratum's completed trajectories (one stratum: `π b_max² × fraction`);
//!   standard error `√(Σ_s A_s² p_s (1 − p_s)/n_s)`.
//! * Moments of `ΔE` over the inelastic trajectories, each stratum weighted by its area:
//!   `⟨ΔE⟩ = Σ_s (A_s/A) mean_s(ΔE)`, standard error `√(Σ_s (A_s/A)² var_s/n_s)`.

use crate::runtime::Molecule;
use crate::runtime::frames::LabState;
use crate::runtime::nalgebra::{SMatrix, Vector3};
use crate::runtime::sample::collision::{Collision, Stratum, fragment};

/// How a collision ended.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// R passed r_stop after the encounter, the fragments as they started (elastic or inelastic).
    Inelastic,
    /// R passed r_stop after the encounter, but the atoms are grouped otherwise (an atom is
    /// nearer another fragment's atom than every atom of its own, or a fragment's largest
    /// internal distance more than doubled).
    Reactive,
    /// Still inside r_stop (or not yet past the encounter) at run.end: a complex, unfinished.
    Complex,
}

impl Outcome {
    /// Every outcome, in the order of the outputs.
    pub const ALL: [Outcome; 3] = [Outcome::Inelastic, Outcome::Reactive, Outcome::Complex];

    /// As written in the outputs.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Inelastic => "inelastic",
            Outcome::Reactive => "reactive",
            Outcome::Complex => "complex",
        }
    }
}

/// One fragment's internal state.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct FragmentState {
    /// Rotational energy, hartree.
    pub e_rot: f64,
    /// Vibrational energy (kinetic and potential), hartree.
    pub e_vib: f64,
    /// |L| about its centre of mass, ħ.
    pub l: f64,
}

/// The channels of one lab state.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Channels {
    /// Centre-of-mass separation, bohr.
    pub r: f64,
    /// Relative velocity `V_B − V_A`, bohr per a.u. of time.
    pub v: Vector3<f64>,
    /// Relative translational energy, hartree.
    pub e_trans: f64,
    /// |orbital angular momentum| `|μ R × v|`, ħ.
    pub l_orbital: f64,
    /// Fragments A and B.
    pub fragments: [FragmentState; 2],
}

/// One completed collision.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Record {
    /// Trajectory index.
    pub index: u64,
    /// Impact-parameter stratum.
    pub stratum: usize,
    /// Impact parameter, bohr.
    pub b: f64,
    /// At t = 0.
    pub initial: Channels,
    /// At the last output.
    pub last: Channels,
    /// Deflection angle, rad.
    pub deflection: f64,
    /// How it ended.
    pub outcome: Outcome,
    /// Time with R below collision.lifetime_radius (linear in R between outputs), a.u.
    pub lifetime: f64,
    /// Time of the last output, a.u.
    pub t_end: f64,
    /// Smallest R at an output time, bohr.
    pub r_min: f64,
    /// H(end) − H(0), hartree.
    pub energy_change: f64,
    /// |L(end) − L(0)| of the lab-frame total angular momentum, ħ.
    pub angular_momentum_change: f64,
    /// |L(0)|, ħ.
    pub angular_momentum: f64,
}

impl Record {
    /// Translational energy gained, hartree.
    pub fn delta_e(&self) -> f64 {
        self.last.e_trans - self.initial.e_trans
    }
}

/// The centre-of-mass separation of the two fragments at positions `x`, bohr.
pub fn separation<const NA: usize>(x: &SMatrix<f64, 3, NA>, masses: &[f64; NA], fragments: &[Vec<usize>; 2]) -> f64 {
    let centre = |atoms: &[usize]| {
        let mut m = 0.0;
        let mut c = Vector3::zeros();
        for &i in atoms {
            m += masses[i];
            c += masses[i] * x.column(i);
        }
        c / m
    };
    (centre(&fragments[1]) - centre(&fragments[0])).norm()
}

/// The time, of an interval `dt` over which R goes linearly from `r0` to `r1`, with R below
/// `radius`.
pub fn time_below(r0: f64, r1: f64, dt: f64, radius: f64) -> f64 {
    match (r0 < radius, r1 < radius) {
        (true, true) => dt,
        (false, false) => 0.0,
        (true, false) => dt * (radius - r0) / (r1 - r0),
        (false, true) => dt * (radius - r1) / (r0 - r1),
    }
}

/// The channels of lab state `lab`.
pub fn channels<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    sampler: &Collision<'_, M, N, NA>,
    lab: &LabState<NA>,
    masses: &[f64; NA],
) -> Channels {
    let frags = &sampler.spec().fragments;
    let parts = [fragment::internal(lab, masses, &frags[0]), fragment::internal(lab, masses, &frags[1])];
    let mu = parts[0].mass * parts[1].mass / (parts[0].mass + parts[1].mass);
    let r = parts[1].position - parts[0].position;
    let v = parts[1].velocity - parts[0].velocity;
    let fragments = std::array::from_fn(|k| {
        let shape: Vec<Vector3<f64>> =
            frags[k].iter().map(|&i| Vector3::from(lab.positions.column(i)) - parts[k].position).collect();
        let u = sampler.fragment_potential(k, &shape).unwrap_or(f64::NAN);
        FragmentState { e_rot: parts[k].e_rot, e_vib: parts[k].t_vib + u, l: parts[k].l.norm() }
    });
    Channels { r: r.norm(), v, e_trans: 0.5 * mu * v.norm_squared(), l_orbital: (mu * r.cross(&v)).norm(), fragments }
}

/// The deflection angle between the initial and final relative velocities, rad.
pub fn deflection(initial: &Channels, last: &Channels) -> f64 {
    let c = initial.v.dot(&last.v) / (initial.v.norm() * last.v.norm());
    c.clamp(-1.0, 1.0).acos()
}

/// Whether the atoms of `lab` are grouped otherwise than the fragments (see [`Outcome::Reactive`]).
pub fn rearranged<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    sampler: &Collision<'_, M, N, NA>,
    lab: &LabState<NA>,
) -> bool {
    let frags = &sampler.spec().fragments;
    let owner = |i: usize| usize::from(frags[1].contains(&i));
    let x = &lab.positions;
    let largest = |pos: &dyn Fn(usize) -> Vector3<f64>, atoms: &[usize]| {
        let mut d: f64 = 0.0;
        for &i in atoms {
            for &j in atoms {
                d = d.max((pos(i) - pos(j)).norm());
            }
        }
        d
    };
    for k in 0..2 {
        if frags[k].len() < 2 {
            continue;
        }
        // The reference shape's largest internal distance.
        let d_ref = {
            let s = sampler.reference_shape(k);
            let mut d: f64 = 0.0;
            for a in s {
                for b in s {
                    d = d.max((a - b).norm());
                }
            }
            d
        };
        if largest(&|i| x.column(i).into(), &frags[k]) > 2.0 * d_ref {
            return true;
        }
        for &i in &frags[k] {
            let nearest = (0..NA)
                .filter(|&j| j != i)
                .min_by(|&a, &b| (x.column(i) - x.column(a)).norm().total_cmp(&(x.column(i) - x.column(b)).norm()));
            if let Some(j) = nearest
                && owner(j) != k
            {
                return true;
            }
        }
    }
    false
}

/// A value with its standard error.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Estimate {
    /// The value.
    pub value: f64,
    /// Its standard error.
    pub error: f64,
}

/// The ensemble's reduction.
#[derive(Clone, Debug, PartialEq)]
pub struct Summary {
    /// Completed trajectories per outcome (in [`Outcome::ALL`] order).
    pub counts: [u64; 3],
    /// Cross section per outcome, bohr².
    pub cross_sections: [Estimate; 3],
    /// `⟨ΔE⟩` and `⟨ΔE²⟩` over the inelastic trajectories (area-weighted), hartree and hartree².
    pub delta_e: Estimate,
    /// See `delta_e`.
    pub delta_e2: Estimate,
    /// Area-weighted means of the changes of each fragment's rotational and vibrational
    /// energies over the inelastic trajectories, hartree: `[A rot, A vib, B rot, B vib]`.
    pub fragment_changes: [Estimate; 4],
    /// Largest |H(end) − H(0)| and |ΔL| over the completed trajectories.
    pub max_energy_change: f64,
    /// See `max_energy_change`, ħ.
    pub max_angular_momentum_change: f64,
}

/// Per-stratum area-weighted mean of `f` over the records selected by `keep`.
fn weighted(
    records: &[Record],
    strata: &[Stratum],
    keep: impl Fn(&Record) -> bool,
    f: impl Fn(&Record) -> f64,
) -> Estimate {
    let total: f64 = strata.iter().map(Stratum::area).sum();
    let mut value = 0.0;
    let mut var = 0.0;
    let mut any = false;
    for (s, stratum) in strata.iter().enumerate() {
        let xs: Vec<f64> = records.iter().filter(|r| r.stratum == s && keep(r)).map(&f).collect();
        if xs.is_empty() {
            continue;
        }
        any = true;
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let v = if xs.len() > 1 { xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0) } else { 0.0 };
        let w = stratum.area() / total;
        value += w * mean;
        var += w * w * v / n;
    }
    if any { Estimate { value, error: var.sqrt() } } else { Estimate { value: f64::NAN, error: f64::NAN } }
}

/// Reduces the records of an ensemble sampled over `strata`.
pub fn summarise(records: &[Record], strata: &[Stratum], _stratified: bool) -> Summary {
    let mut counts = [0u64; 3];
    for r in records {
        counts[Outcome::ALL.iter().position(|o| *o == r.outcome).unwrap_or(2)] += 1;
    }
    let cross_sections = Outcome::ALL.map(|o| {
        let mut value = 0.0;
        let mut var = 0.0;
        for (s, stratum) in strata.iter().enumerate() {
            let n = records.iter().filter(|r| r.stratum == s).count() as f64;
            if n == 0.0 {
                continue;
            }
            let p = records.iter().filter(|r| r.stratum == s && r.outcome == o).count() as f64 / n;
            value += stratum.area() * p;
            var += stratum.area().powi(2) * p * (1.0 - p) / n;
        }
        Estimate { value, error: var.sqrt() }
    });
    let inelastic = |r: &Record| r.outcome == Outcome::Inelastic;
    let delta_e = weighted(records, strata, inelastic, Record::delta_e);
    let delta_e2 = weighted(records, strata, inelastic, |r| r.delta_e().powi(2));
    let fragment_changes = [
        weighted(records, strata, inelastic, |r| r.last.fragments[0].e_rot - r.initial.fragments[0].e_rot),
        weighted(records, strata, inelastic, |r| r.last.fragments[0].e_vib - r.initial.fragments[0].e_vib),
        weighted(records, strata, inelastic, |r| r.last.fragments[1].e_rot - r.initial.fragments[1].e_rot),
        weighted(records, strata, inelastic, |r| r.last.fragments[1].e_vib - r.initial.fragments[1].e_vib),
    ];
    Summary {
        counts,
        cross_sections,
        delta_e,
        delta_e2,
        fragment_changes,
        max_energy_change: records.iter().map(|r| r.energy_change.abs()).fold(0.0, f64::max),
        max_angular_momentum_change: records.iter().map(|r| r.angular_momentum_change).fold(0.0, f64::max),
    }
}
