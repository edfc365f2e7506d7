//! Hand-written test molecules and helpers shared by the integration tests.
//!
//! The code generator is written concurrently, so these molecules implement
//! [`Molecule`] by hand: a bent triatomic XY2 (water) in valence coordinates and a rigid
//! asymmetric top. Their kinetic matrices and derivatives are computed directly from the
//! positions and their analytic first and second q-derivatives by the sums of the seed's
//! eq. (3), independently of the code under test.

// Each test binary uses a different subset of these helpers.
#![allow(dead_code)]

use rovib_runtime::molecule::{Atom, Coordinate, Kinematics, KineticMatrices, Molecule};
use rovib_runtime::nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use rovib_runtime::units::{AngleUnit, CoordinateUnit, DALTON_IN_ELECTRON_MASSES, LengthUnit};

/// Mass of ¹⁶O in daltons.
pub const O_DA: f64 = 15.994_914_619_57;
/// Mass of ¹H in daltons.
pub const H_DA: f64 = 1.007_825_032_23;
/// Mass of ¹⁴N in daltons.
pub const N_DA: f64 = 14.003_074_004_43;
/// Mass of ¹²C in daltons.
pub const C_DA: f64 = 12.0;

fn atom(label: &'static str, element: &'static str, mass_da: f64) -> Atom {
    Atom { label, element, mass_da, mass: mass_da * DALTON_IN_ELECTRON_MASSES }
}

/// Positions (centre of mass at the origin) with their first and second q-derivatives.
pub struct PositionDerivatives<const N: usize, const NA: usize> {
    /// `R_i`.
    pub r: SMatrix<f64, 3, NA>,
    /// `∂R_i/∂q_k`.
    pub dr: [SMatrix<f64, 3, NA>; N],
    /// `∂²R_i/∂q_j∂q_k`.
    pub d2r: [[SMatrix<f64, 3, NA>; N]; N],
}

impl<const N: usize, const NA: usize> PositionDerivatives<N, NA> {
    /// Shifts raw positions (and derivatives) so that the centre of mass is at the origin:
    /// subtracting the mass-weighted mean is linear, so it applies to each derivative too.
    pub fn centred(
        masses: &[f64; NA],
        r: SMatrix<f64, 3, NA>,
        dr: [SMatrix<f64, 3, NA>; N],
        d2r: [[SMatrix<f64, 3, NA>; N]; N],
    ) -> Self {
        let total: f64 = masses.iter().sum();
        let centre = |m: &SMatrix<f64, 3, NA>| {
            let mut com = Vector3::zeros();
            for i in 0..NA {
                com += m.column(i) * masses[i];
            }
            let com = com / total;
            let mut out = *m;
            for i in 0..NA {
                let c = out.column(i) - com;
                out.set_column(i, &c);
            }
            out
        };
        Self { r: centre(&r), dr: dr.map(|d| centre(&d)), d2r: d2r.map(|row| row.map(|d| centre(&d))) }
    }

    /// `a`, `A`, `I` by the sums of eq. (3).
    pub fn kinetic(&self, masses: &[f64; NA]) -> KineticMatrices<N> {
        let mut k = KineticMatrices::default();
        for i in 0..NA {
            let m = masses[i];
            let r: Vector3<f64> = self.r.column(i).into();
            k.inertia += (Matrix3::identity() * r.norm_squared() - r * r.transpose()) * m;
            for l in 0..N {
                let drl: Vector3<f64> = self.dr[l].column(i).into();
                let c = r.cross(&drl) * m;
                for row in 0..3 {
                    k.coriolis[(row, l)] += c[row];
                }
                for jj in 0..N {
                    k.a[(jj, l)] += m * self.dr[jj].column(i).dot(&drl);
                }
            }
        }
        k
    }

    /// `∂a/∂q_k`, `∂A/∂q_k`, `∂I/∂q_k` by differentiating the sums of eq. (3) analytically.
    pub fn kinetic_jacobian(&self, masses: &[f64; NA]) -> [KineticMatrices<N>; N] {
        core::array::from_fn(|k| {
            let mut d = KineticMatrices::default();
            for i in 0..NA {
                let m = masses[i];
                let r: Vector3<f64> = self.r.column(i).into();
                let drk: Vector3<f64> = self.dr[k].column(i).into();
                d.inertia +=
                    (Matrix3::identity() * (2.0 * r.dot(&drk)) - drk * r.transpose() - r * drk.transpose()) * m;
                for l in 0..N {
                    let drl: Vector3<f64> = self.dr[l].column(i).into();
                    let d2lk: Vector3<f64> = self.d2r[l][k].column(i).into();
                    let c = (drk.cross(&drl) + r.cross(&d2lk)) * m;
                    for row in 0..3 {
                        d.coriolis[(row, l)] += c[row];
                    }
                    for jj in 0..N {
                        let drj: Vector3<f64> = self.dr[jj].column(i).into();
                        let d2jk: Vector3<f64> = self.d2r[jj][k].column(i).into();
                        d.a[(jj, l)] += m * (d2jk.dot(&drl) + drj.dot(&d2lk));
                    }
                }
            }
            d
        })
    }

    /// `T = ½ Σ m_i |ω × R_i + Σ_j ∂R_i/∂q_j q̇_j|²` and its q-gradient at fixed ω, q̇.
    pub fn kinetic_energy_gradient(
        &self,
        masses: &[f64; NA],
        omega: &Vector3<f64>,
        qdot: &SVector<f64, N>,
        grad: &mut SVector<f64, N>,
    ) -> f64 {
        grad.fill(0.0);
        let mut t = 0.0;
        for i in 0..NA {
            let m = masses[i];
            let r: Vector3<f64> = self.r.column(i).into();
            let mut v = omega.cross(&r);
            for j in 0..N {
                v += self.dr[j].column(i) * qdot[j];
            }
            t += 0.5 * m * v.norm_squared();
            for k in 0..N {
                let drk: Vector3<f64> = self.dr[k].column(i).into();
                let mut dv = omega.cross(&drk);
                for j in 0..N {
                    dv += self.d2r[j][k].column(i) * qdot[j];
                }
                grad[k] += m * v.dot(&dv);
            }
        }
        t
    }
}

/// Bent triatomic XY2 (H₂¹⁶O) in valence coordinates `q = (r1, r2, α)`: X at the origin,
/// `Y1 = r1 (sin α/2, 0, cos α/2)`, `Y2 = r2 (−sin α/2, 0, cos α/2)`, then shifted to the centre
/// of mass. Potential: two Morse stretches, a harmonic bend and bilinear couplings.
#[derive(Copy, Clone, Debug, Default)]
pub struct Water;

impl Water {
    /// Morse depth (hartree).
    pub const D: f64 = 0.2;
    /// Morse range parameter (1/bohr).
    pub const BETA: f64 = 1.2;
    /// Equilibrium bond length (bohr).
    pub const RE: f64 = 1.81;
    /// Bending force constant (hartree/rad²).
    pub const K_BEND: f64 = 0.16;
    /// Equilibrium angle (rad).
    pub const ALPHA_E: f64 = 1.824;
    /// Stretch–stretch coupling (hartree/bohr²).
    pub const F_RR: f64 = 0.01;
    /// Stretch–bend coupling (hartree/(bohr rad)).
    pub const F_RA: f64 = 0.02;

    /// Mass of the central atom X (O), electron masses.
    pub fn m_x() -> f64 {
        O_DA * DALTON_IN_ELECTRON_MASSES
    }

    /// Mass of an outer atom Y (H), electron masses.
    pub fn m_y() -> f64 {
        H_DA * DALTON_IN_ELECTRON_MASSES
    }

    /// Positions with analytic first and second derivatives.
    pub fn derivatives(&self, q: &SVector<f64, 3>) -> PositionDerivatives<3, 3> {
        let (r1, r2, alpha) = (q[0], q[1], q[2]);
        let (s, c) = (0.5 * alpha).sin_cos();
        let col =
            |x0: Vector3<f64>, y1: Vector3<f64>, y2: Vector3<f64>| SMatrix::<f64, 3, 3>::from_columns(&[x0, y1, y2]);
        let z = Vector3::zeros();
        let u1 = Vector3::new(s, 0.0, c);
        let u2 = Vector3::new(-s, 0.0, c);
        // d(u1)/dα and d(u2)/dα, and their second derivatives.
        let du1 = Vector3::new(0.5 * c, 0.0, -0.5 * s);
        let du2 = Vector3::new(-0.5 * c, 0.0, -0.5 * s);
        let d2u1 = Vector3::new(-0.25 * s, 0.0, -0.25 * c);
        let d2u2 = Vector3::new(0.25 * s, 0.0, -0.25 * c);

        let r = col(z, u1 * r1, u2 * r2);
        let dr = [col(z, u1, z), col(z, z, u2), col(z, du1 * r1, du2 * r2)];
        let zero = SMatrix::<f64, 3, 3>::zeros();
        let d_r1_alpha = col(z, du1, z);
        let d_r2_alpha = col(z, z, du2);
        let d2r = [
            [zero, zero, d_r1_alpha],
            [zero, zero, d_r2_alpha],
            [d_r1_alpha, d_r2_alpha, col(z, d2u1 * r1, d2u2 * r2)],
        ];
        PositionDerivatives::centred(&self.masses(), r, dr, d2r)
    }
}

impl Kinematics<3, 3> for Water {
    fn name(&self) -> &'static str {
        "water-test"
    }

    fn source(&self) -> &'static str {
        "runtime/tests/common/mod.rs"
    }

    fn atoms(&self) -> [Atom; 3] {
        [atom("O", "O", O_DA), atom("H1", "H", H_DA), atom("H2", "H", H_DA)]
    }

    fn coordinates(&self) -> [Coordinate; 3] {
        let bohr = CoordinateUnit::Length(LengthUnit::Bohr);
        [
            Coordinate { name: "r1", unit: bohr, reference: Some(Self::RE), range: (0.0, f64::INFINITY) },
            Coordinate { name: "r2", unit: bohr, reference: Some(Self::RE), range: (0.0, f64::INFINITY) },
            Coordinate {
                name: "alpha",
                unit: CoordinateUnit::Angle(AngleUnit::Rad),
                reference: Some(Self::ALPHA_E),
                range: (0.0, std::f64::consts::PI),
            },
        ]
    }

    fn positions(&self, q: &SVector<f64, 3>, r: &mut SMatrix<f64, 3, 3>) {
        *r = self.derivatives(q).r;
    }

    fn positions_jacobian(&self, q: &SVector<f64, 3>, dr: &mut [SMatrix<f64, 3, 3>; 3]) {
        *dr = self.derivatives(q).dr;
    }

    fn kinetic(&self, q: &SVector<f64, 3>, k: &mut KineticMatrices<3>) {
        *k = self.derivatives(q).kinetic(&self.masses());
    }

    fn kinetic_jacobian(&self, q: &SVector<f64, 3>, dk: &mut [KineticMatrices<3>; 3]) {
        *dk = self.derivatives(q).kinetic_jacobian(&self.masses());
    }

    fn kinetic_energy_gradient(
        &self,
        q: &SVector<f64, 3>,
        omega: &Vector3<f64>,
        qdot: &SVector<f64, 3>,
        grad: &mut SVector<f64, 3>,
    ) -> f64 {
        self.derivatives(q).kinetic_energy_gradient(&self.masses(), omega, qdot, grad)
    }
}

impl Molecule<3, 3> for Water {
    fn potential(&self, q: &SVector<f64, 3>) -> f64 {
        let mut g = SVector::zeros();
        self.potential_gradient(q, &mut g)
    }

    fn potential_gradient(&self, q: &SVector<f64, 3>, grad: &mut SVector<f64, 3>) -> f64 {
        let (x1, x2, y) = (q[0] - Self::RE, q[1] - Self::RE, q[2] - Self::ALPHA_E);
        let morse = |x: f64| {
            let e = (-Self::BETA * x).exp();
            (Self::D * (1.0 - e) * (1.0 - e), 2.0 * Self::D * Self::BETA * e * (1.0 - e))
        };
        let (u1, g1) = morse(x1);
        let (u2, g2) = morse(x2);
        let u = u1 + u2 + 0.5 * Self::K_BEND * y * y + Self::F_RR * x1 * x2 + Self::F_RA * (x1 + x2) * y;
        grad[0] = g1 + Self::F_RR * x2 + Self::F_RA * y;
        grad[1] = g2 + Self::F_RR * x1 + Self::F_RA * y;
        grad[2] = Self::K_BEND * y + Self::F_RA * (x1 + x2);
        u
    }
}

/// A rigid asymmetric top (N = 0): C, N, O at fixed positions of a scalene triangle.
#[derive(Copy, Clone, Debug, Default)]
pub struct RigidTop;

impl RigidTop {
    /// A constant potential energy (hartree), so that H ≠ T is visible.
    pub const U0: f64 = -0.125;

    /// The fixed positions, centred.
    pub fn derivatives(&self) -> PositionDerivatives<0, 3> {
        let r = SMatrix::<f64, 3, 3>::from_columns(&[
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(2.2, 0.3, -0.1),
            Vector3::new(-0.7, 2.5, 0.4),
        ]);
        PositionDerivatives::centred(&self.masses(), r, [], [])
    }
}

impl Kinematics<0, 3> for RigidTop {
    fn name(&self) -> &'static str {
        "rigid-top-test"
    }

    fn source(&self) -> &'static str {
        "runtime/tests/common/mod.rs"
    }

    fn atoms(&self) -> [Atom; 3] {
        [atom("C", "C", C_DA), atom("N", "N", N_DA), atom("O", "O", O_DA)]
    }

    fn coordinates(&self) -> [Coordinate; 0] {
        []
    }

    fn positions(&self, _q: &SVector<f64, 0>, r: &mut SMatrix<f64, 3, 3>) {
        *r = self.derivatives().r;
    }

    fn positions_jacobian(&self, _q: &SVector<f64, 0>, _dr: &mut [SMatrix<f64, 3, 3>; 0]) {}

    fn kinetic(&self, _q: &SVector<f64, 0>, k: &mut KineticMatrices<0>) {
        *k = self.derivatives().kinetic(&self.masses());
    }

    fn kinetic_jacobian(&self, _q: &SVector<f64, 0>, _dk: &mut [KineticMatrices<0>; 0]) {}

    fn kinetic_energy_gradient(
        &self,
        _q: &SVector<f64, 0>,
        omega: &Vector3<f64>,
        qdot: &SVector<f64, 0>,
        grad: &mut SVector<f64, 0>,
    ) -> f64 {
        self.derivatives().kinetic_energy_gradient(&self.masses(), omega, qdot, grad)
    }
}

impl Molecule<0, 3> for RigidTop {
    fn potential(&self, _q: &SVector<f64, 0>) -> f64 {
        Self::U0
    }

    fn potential_gradient(&self, _q: &SVector<f64, 0>, _grad: &mut SVector<f64, 0>) -> f64 {
        Self::U0
    }
}

// Each test binary uses a different subset of these.
#[allow(unused_imports)]
pub use rovib_testkit::{Rng, derivative};

/// A random water geometry around equilibrium: `r ∈ [1.5, 2.3]` bohr, `α ∈ [1.4, 2.5]` rad.
pub fn random_water_q(rng: &mut Rng) -> SVector<f64, 3> {
    SVector::<f64, 3>::new(rng.uniform(1.5, 2.3), rng.uniform(1.5, 2.3), rng.uniform(1.4, 2.5))
}

/// Random generic Euler angles, with θ kept away from 0 and π (`sin θ > 0.3`).
pub fn random_euler(rng: &mut Rng) -> Vector3<f64> {
    use core::f64::consts::PI;
    Vector3::new(rng.uniform(-PI, PI), rng.uniform(0.31, PI - 0.31), rng.uniform(-PI, PI))
}

/// A random vector with components in `[-s, s)`.
pub fn random_vector<const D: usize>(rng: &mut Rng, s: f64) -> SVector<f64, D> {
    SVector::from_fn(|_, _| rng.uniform(-s, s))
}
