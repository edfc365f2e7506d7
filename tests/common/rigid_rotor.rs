//! An atom and a rigid linear rotor in the lab frame, independent of rovib's coordinates,
//! body frame, kinetic matrices and charts: the reference for trajectories of an
//! atom + rigid-linear-molecule complex through its collinear geometries.
//!
//! State (12 components): the separation `R` from the rotor's centre of mass to the atom, its
//! momentum `P`, the rotor's unit axis `u` and its angular momentum `L` about its centre of mass
//! (`L · u = 0`). With `μ` the atom–rotor reduced mass and `I` the rotor's moment of inertia:
//! `Ṙ = P/μ`, `Ṗ = −∂U/∂R`, `u̇ = (L/I) × u`, `L̇ = u × (−∂U/∂u)` (the cross product drops the
//! force along `u`, which the rigid bond takes up). `U` is a sum of Lennard-Jones terms between
//! the atom and sites on the axis at signed offsets `c_s` from the rotor's centre of mass: the
//! site–atom vector is `d_s = R − c_s u`. Nothing has a singular configuration: a collinear
//! geometry (`R ∥ u`) is an ordinary point.
#![allow(dead_code)]

use std::convert::Infallible;

use rovib::runtime::frames::LabState;
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{SMatrix, Vector3};

/// A Lennard-Jones site on the rotor's axis.
#[derive(Copy, Clone, Debug)]
pub struct Site {
    /// Signed distance from the rotor's centre of mass along `u`, bohr.
    pub offset: f64,
    /// Well depth, hartree.
    pub eps: f64,
    /// Size, bohr.
    pub sigma: f64,
}

/// The atom (atom index `atom` of a [`LabState`]) and the rotor of atoms `rotor = [a, b]`
/// (`u` points from `b` to `a`), with the masses of the lab state's atoms (electron masses).
#[derive(Clone, Debug)]
pub struct AtomRotor<const NA: usize> {
    pub masses: [f64; NA],
    pub atom: usize,
    pub rotor: [usize; 2],
    /// The bond length, bohr.
    pub bond: f64,
    /// One site per rotor atom, in the order of `rotor`.
    pub sites: [Site; 2],
}

fn v(y: &[f64], k: usize) -> Vector3<f64> {
    Vector3::new(y[k], y[k + 1], y[k + 2])
}

fn put(y: &mut [f64], k: usize, x: &Vector3<f64>) {
    y[k..k + 3].copy_from_slice(x.as_slice());
}

impl<const NA: usize> AtomRotor<NA> {
    fn rotor_mass(&self) -> f64 {
        self.masses[self.rotor[0]] + self.masses[self.rotor[1]]
    }

    /// The atom–rotor reduced mass.
    pub fn mu(&self) -> f64 {
        let (ma, mr) = (self.masses[self.atom], self.rotor_mass());
        ma * mr / (ma + mr)
    }

    /// The rotor's moment of inertia about its centre of mass.
    pub fn inertia(&self) -> f64 {
        self.masses[self.rotor[0]] * self.masses[self.rotor[1]] / self.rotor_mass() * self.bond * self.bond
    }

    /// The offsets of the rotor atoms from its centre of mass along `u`.
    pub fn atom_offsets(&self) -> [f64; 2] {
        let m = self.rotor_mass();
        [self.bond * self.masses[self.rotor[1]] / m, -self.bond * self.masses[self.rotor[0]] / m]
    }

    /// `U`, `∂U/∂R` and `∂U/∂u` (u treated as a free vector).
    pub fn potential(&self, r: &Vector3<f64>, u: &Vector3<f64>) -> (f64, Vector3<f64>, Vector3<f64>) {
        let mut energy = 0.0;
        let (mut dr, mut du) = (Vector3::zeros(), Vector3::zeros());
        for s in &self.sites {
            let d = r - s.offset * u;
            let n = d.norm();
            let x6 = (s.sigma / n).powi(6);
            energy += 4.0 * s.eps * (x6 * x6 - x6);
            // dU/dn = 4 eps (-12 x6² + 6 x6) / n, along d/n.
            let g = d * (4.0 * s.eps * (6.0 * x6 - 12.0 * x6 * x6) / (n * n));
            dr += g;
            du -= s.offset * g;
        }
        (energy, dr, du)
    }

    /// `P²/2μ + L²/2I + U`.
    pub fn energy(&self, y: &[f64]) -> f64 {
        let (r, p, u, l) = (v(y, 0), v(y, 3), v(y, 6), v(y, 9));
        p.norm_squared() / (2.0 * self.mu()) + l.norm_squared() / (2.0 * self.inertia()) + self.potential(&r, &u).0
    }

    /// The total angular momentum about the centre of mass, `R × P + L`.
    pub fn angular_momentum(&self, y: &[f64]) -> Vector3<f64> {
        v(y, 0).cross(&v(y, 3)) + v(y, 9)
    }

    /// `L · u` and `|u| − 1`, which the equations keep at zero.
    pub fn constraint_residuals(&self, y: &[f64]) -> (f64, f64) {
        (v(y, 9).dot(&v(y, 6)), v(y, 6).norm() - 1.0)
    }

    /// The angle between `R` and the nearer direction of the axis (0 at a collinear geometry).
    pub fn angle_from_collinear(&self, y: &[f64]) -> f64 {
        let a = v(y, 0).angle(&v(y, 6));
        a.min(std::f64::consts::PI - a)
    }

    /// The state of a lab state (positions and velocities of every atom; the rotor must be
    /// rigid with this bond length to rounding).
    pub fn state_of_lab(&self, lab: &LabState<NA>) -> [f64; 12] {
        let [a, b] = self.rotor;
        let m = self.rotor_mass();
        let (ma, mb) = (self.masses[a], self.masses[b]);
        let x = |i: usize| Vector3::from(lab.positions.column(i));
        let w = |i: usize| Vector3::from(lab.velocities.column(i));
        let centre = (ma * x(a) + mb * x(b)) / m;
        let centre_velocity = (ma * w(a) + mb * w(b)) / m;
        let r = x(self.atom) - centre;
        let p = self.mu() * (w(self.atom) - centre_velocity);
        let axis = x(a) - x(b);
        let u = axis / axis.norm();
        let udot = (w(a) - w(b)) / axis.norm();
        let l = self.inertia() * u.cross(&udot);
        let mut y = [0.0; 12];
        put(&mut y, 0, &r);
        put(&mut y, 3, &p);
        put(&mut y, 6, &u);
        put(&mut y, 9, &l);
        y
    }

    /// The lab positions about the centre of mass (column `i` is atom `i`).
    pub fn positions(&self, y: &[f64]) -> SMatrix<f64, 3, NA> {
        let (r, u) = (v(y, 0), v(y, 6) / v(y, 6).norm());
        let (ma, mr) = (self.masses[self.atom], self.rotor_mass());
        let centre = -ma / (ma + mr) * r;
        let [ca, cb] = self.atom_offsets();
        let mut x = SMatrix::<f64, 3, NA>::zeros();
        x.set_column(self.atom, &(mr / (ma + mr) * r));
        x.set_column(self.rotor[0], &(centre + ca * u));
        x.set_column(self.rotor[1], &(centre + cb * u));
        x
    }
}

impl<const NA: usize> OdeSystem for AtomRotor<NA> {
    type Error = Infallible;

    fn dim(&self) -> usize {
        12
    }

    fn rhs(&mut self, _t: f64, y: &[f64], dydt: &mut [f64]) -> Result<(), Infallible> {
        let (r, p, u, l) = (v(y, 0), v(y, 3), v(y, 6), v(y, 9));
        let (_, du_dr, du_du) = self.potential(&r, &u);
        put(dydt, 0, &(p / self.mu()));
        put(dydt, 3, &(-du_dr));
        put(dydt, 6, &(l / self.inertia()).cross(&u));
        put(dydt, 9, &u.cross(&(-du_du)));
        Ok(())
    }
}
