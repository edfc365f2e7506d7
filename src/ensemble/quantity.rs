//! The quantities an ensemble can average, histogram and correlate, evaluated from the state at
//! an output time. All in atomic units.

use crate::runtime::Molecule;
use crate::runtime::hamiltonian::fast::BodyState;
use crate::runtime::nalgebra::{Matrix3, Vector3};

/// One observable of a trajectory at an output time.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// Internal coordinate `k` (bohr or rad), named as in the molecule.
    Coordinate(usize),
    /// Its conjugate momentum `p_NAME` (ħ/bohr or ħ).
    Momentum(usize),
    /// Kinetic energy `T = H − U`, hartree.
    Kinetic,
    /// Potential energy `U`, hartree.
    Potential,
    /// Total energy `H`, hartree.
    Total,
    /// `|J|`, ħ.
    AngularMomentum,
    /// Body-frame `J` component 0, 1, 2 (`Jx`, `Jy`, `Jz`), ħ.
    BodyJ(usize),
    /// Lab-frame angular momentum component `L = R J` (`Lx`, `Ly`, `Lz`), ħ.
    LabL(usize),
    /// Lab-frame dipole moment component `μ_lab = R μ(q)` (`mu_x`, `mu_y`, `mu_z`), e·bohr;
    /// only for a molecule with a dipole surface.
    LabDipole(usize),
}

const DIPOLE: [(&str, Quantity); 3] =
    [("mu_x", Quantity::LabDipole(0)), ("mu_y", Quantity::LabDipole(1)), ("mu_z", Quantity::LabDipole(2))];

const FIXED: [(&str, Quantity); 10] = [
    ("T", Quantity::Kinetic),
    ("U", Quantity::Potential),
    ("H", Quantity::Total),
    ("J", Quantity::AngularMomentum),
    ("Jx", Quantity::BodyJ(0)),
    ("Jy", Quantity::BodyJ(1)),
    ("Jz", Quantity::BodyJ(2)),
    ("Lx", Quantity::LabL(0)),
    ("Ly", Quantity::LabL(1)),
    ("Lz", Quantity::LabL(2)),
];

impl Quantity {
    /// The quantity called `name` for molecule `m`.
    pub fn parse<M: Molecule<N, NA>, const N: usize, const NA: usize>(name: &str, m: &M) -> Option<Self> {
        let coords = m.coordinates();
        if let Some(k) = coords.iter().position(|c| c.name == name) {
            return Some(Quantity::Coordinate(k));
        }
        if let Some(rest) = name.strip_prefix("p_")
            && let Some(k) = coords.iter().position(|c| c.name == rest)
        {
            return Some(Quantity::Momentum(k));
        }
        if m.has_dipole()
            && let Some((_, q)) = DIPOLE.iter().find(|(n, _)| *n == name)
        {
            return Some(*q);
        }
        FIXED.iter().find(|(n, _)| *n == name).map(|(_, q)| *q)
    }

    /// Every name [`Quantity::parse`] accepts for `m`.
    pub fn names<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M) -> Vec<String> {
        let coords = m.coordinates();
        let mut names: Vec<String> = coords.iter().map(|c| c.name.to_owned()).collect();
        names.extend(coords.iter().map(|c| format!("p_{}", c.name)));
        names.extend(FIXED.iter().map(|(n, _)| (*n).to_owned()));
        if m.has_dipole() {
            names.extend(DIPOLE.iter().map(|(n, _)| (*n).to_owned()));
        }
        names
    }

    /// The names of the quantities that are not coordinates or momenta (a definition may not
    /// give a coordinate one of them, see rovib-codegen's `RESERVED_QUANTITY_NAMES`).
    pub fn reserved_names() -> Vec<&'static str> {
        FIXED.iter().chain(DIPOLE.iter()).map(|(n, _)| *n).collect()
    }

    /// What an ensemble averages when the scene does not say: every coordinate, T, U, H, |J|.
    pub fn default_set<M: Molecule<N, NA>, const N: usize, const NA: usize>() -> Vec<Self> {
        let mut q: Vec<Quantity> = (0..N).map(Quantity::Coordinate).collect();
        q.extend([Quantity::Kinetic, Quantity::Potential, Quantity::Total, Quantity::AngularMomentum]);
        q
    }

    /// The name, as in scenes and column headers.
    pub fn name<M: Molecule<N, NA>, const N: usize, const NA: usize>(&self, m: &M) -> String {
        match self {
            Quantity::Coordinate(k) => m.coordinates()[*k].name.to_owned(),
            Quantity::Momentum(k) => format!("p_{}", m.coordinates()[*k].name),
            other => FIXED
                .iter()
                .chain(DIPOLE.iter())
                .find(|(_, q)| q == other)
                .map(|(n, _)| (*n).to_owned())
                .unwrap_or_default(),
        }
    }

    /// The atomic unit it is written in: `bohr`, `rad`, `hbar/bohr`, `hbar`, `hartree`.
    pub fn unit<M: Molecule<N, NA>, const N: usize, const NA: usize>(&self, m: &M) -> &'static str {
        use crate::runtime::units::CoordinateUnit;
        let length = |k: usize| matches!(m.coordinates()[k].unit, CoordinateUnit::Length(_));
        match self {
            Quantity::Coordinate(k) => {
                if length(*k) {
                    "bohr"
                } else {
                    "rad"
                }
            }
            Quantity::Momentum(k) => {
                if length(*k) {
                    "hbar/bohr"
                } else {
                    "hbar"
                }
            }
            Quantity::Kinetic | Quantity::Potential | Quantity::Total => "hartree",
            Quantity::AngularMomentum | Quantity::BodyJ(_) | Quantity::LabL(_) => "hbar",
            Quantity::LabDipole(_) => "e*bohr",
        }
    }

    /// Whether evaluating it needs `U` (one potential evaluation per output time).
    pub fn needs_potential(&self) -> bool {
        matches!(self, Quantity::Kinetic | Quantity::Potential)
    }

    /// Whether evaluating it needs the dipole μ(q) (one dipole evaluation per output time).
    pub fn needs_dipole(&self) -> bool {
        matches!(self, Quantity::LabDipole(_))
    }

    /// Its value in state `s` with total energy `h`, potential `u` (NaN if not computed),
    /// body → lab rotation `rotation` and lab-frame dipole `mu_lab` (NaN if not computed).
    #[inline]
    pub fn value<const N: usize>(
        &self,
        s: &BodyState<N>,
        h: f64,
        u: f64,
        rotation: &Matrix3<f64>,
        mu_lab: &Vector3<f64>,
    ) -> f64 {
        match self {
            Quantity::Coordinate(k) => s.q[*k],
            Quantity::Momentum(k) => s.p[*k],
            Quantity::Kinetic => h - u,
            Quantity::Potential => u,
            Quantity::Total => h,
            Quantity::AngularMomentum => s.j.norm(),
            Quantity::BodyJ(i) => s.j[*i],
            Quantity::LabL(i) => (rotation * s.j)[*i],
            Quantity::LabDipole(i) => mu_lab[*i],
        }
    }
}
