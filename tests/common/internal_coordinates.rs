//! Internal coordinates computed from lab-frame Cartesian positions with nothing but distances,
//! bond angles and dihedral angles: the independent side of the Cartesian cross-check.
//!
//! This shares no code with the generated kinetic matrices: the cross-check integrates Newton's
//! equations for the atoms with forces `−∂U(q(x))/∂x`, where `q(x)` is computed here and its
//! x-derivative comes from forward-mode automatic differentiation ([`Dual`]), and `∂U/∂q` from
//! the molecule's potential (the one thing both sides must share: they simulate the same
//! potential).
#![allow(dead_code)]

use std::ops::{Add, Div, Mul, Neg, Sub};

/// The arithmetic the coordinate functions need, for `f64` and for [`Dual`].
pub trait Real:
    Copy + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self> + Neg<Output = Self>
{
    fn from_f64(x: f64) -> Self;
    fn value(self) -> f64;
    fn sqrt(self) -> Self;
    fn atan2(self, x: Self) -> Self;
}

impl Real for f64 {
    fn from_f64(x: f64) -> Self {
        x
    }
    fn value(self) -> f64 {
        self
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    fn atan2(self, x: Self) -> Self {
        f64::atan2(self, x)
    }
}

/// A number with one directional derivative: `v + d ε`, ε² = 0.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Dual {
    pub v: f64,
    pub d: f64,
}

impl Add for Dual {
    type Output = Dual;
    fn add(self, o: Dual) -> Dual {
        Dual { v: self.v + o.v, d: self.d + o.d }
    }
}
impl Sub for Dual {
    type Output = Dual;
    fn sub(self, o: Dual) -> Dual {
        Dual { v: self.v - o.v, d: self.d - o.d }
    }
}
impl Mul for Dual {
    type Output = Dual;
    fn mul(self, o: Dual) -> Dual {
        Dual { v: self.v * o.v, d: self.d * o.v + self.v * o.d }
    }
}
impl Div for Dual {
    type Output = Dual;
    fn div(self, o: Dual) -> Dual {
        Dual { v: self.v / o.v, d: (self.d * o.v - self.v * o.d) / (o.v * o.v) }
    }
}
impl Neg for Dual {
    type Output = Dual;
    fn neg(self) -> Dual {
        Dual { v: -self.v, d: -self.d }
    }
}
impl Real for Dual {
    fn from_f64(x: f64) -> Self {
        Dual { v: x, d: 0.0 }
    }
    fn value(self) -> f64 {
        self.v
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        Dual { v: s, d: self.d / (2.0 * s) }
    }
    fn atan2(self, x: Self) -> Self {
        let r2 = self.v * self.v + x.v * x.v;
        Dual { v: self.v.atan2(x.v), d: (x.v * self.d - self.v * x.d) / r2 }
    }
}

/// A 3-vector of [`Real`]s.
pub type V3<T> = [T; 3];

pub fn sub<T: Real>(a: V3<T>, b: V3<T>) -> V3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn dot<T: Real>(a: V3<T>, b: V3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross<T: Real>(a: V3<T>, b: V3<T>) -> V3<T> {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub fn norm<T: Real>(a: V3<T>) -> T {
    dot(a, a).sqrt()
}

/// The distance |a − b|.
pub fn distance<T: Real>(a: V3<T>, b: V3<T>) -> T {
    norm(sub(a, b))
}

/// The angle a–b–c at vertex b, in [0, π], as atan2(|u × v|, u · v), which stays accurate near
/// 0 and π where acos does not.
pub fn angle<T: Real>(a: V3<T>, b: V3<T>, c: V3<T>) -> T {
    let (u, v) = (sub(a, b), sub(c, b));
    norm(cross(u, v)).atan2(dot(u, v))
}

/// The dihedral angle a–b–c–d in (−π, π] (IUPAC sign: positive when, looking along b → c, the
/// bond b–a turns clockwise onto the bond c–d). Example: a = x̂, b = 0, c = ẑ, d = ẑ + ŷ gives
/// +π/2 (checked by `dihedral_sign_follows_iupac` in `tests/cartesian.rs`).
pub fn dihedral<T: Real>(a: V3<T>, b: V3<T>, c: V3<T>, d: V3<T>) -> T {
    let (b1, b2, b3) = (sub(b, a), sub(c, b), sub(d, c));
    let y = norm(b2) * dot(b1, cross(b2, b3));
    let x = dot(cross(b1, b2), cross(b2, b3));
    y.atan2(x)
}

/// Water: (r1, r2, α) = (|H1 − O|, |H2 − O|, ∠H1–O–H2), atoms in the order O, H1, H2.
pub fn h2o<T: Real>(x: &[V3<T>]) -> Vec<T> {
    vec![distance(x[1], x[0]), distance(x[2], x[0]), angle(x[1], x[0], x[2])]
}

/// Every atom position's derivative of every coordinate: `jac[k][i][axis] = ∂q_k/∂x_{i,axis}`,
/// by forward-mode differentiation, one direction at a time.
pub fn jacobian(x: &[[f64; 3]], q_of_x: impl Fn(&[V3<Dual>]) -> Vec<Dual>) -> (Vec<f64>, Vec<Vec<[f64; 3]>>) {
    let n_atoms = x.len();
    let lift = |seed: Option<(usize, usize)>| -> Vec<V3<Dual>> {
        (0..n_atoms)
            .map(|i| [0, 1, 2].map(|a| Dual { v: x[i][a], d: if seed == Some((i, a)) { 1.0 } else { 0.0 } }))
            .collect()
    };
    let q: Vec<f64> = q_of_x(&lift(None)).iter().map(|d| d.v).collect();
    let mut jac = vec![vec![[0.0; 3]; n_atoms]; q.len()];
    for i in 0..n_atoms {
        for a in 0..3 {
            for (k, dq) in q_of_x(&lift(Some((i, a)))).iter().enumerate() {
                jac[k][i][a] = dq.d;
            }
        }
    }
    (q, jac)
}

/// Carbon dioxide: (r1, r2, α) = (|O1 − C|, |O2 − C|, ∠O1–C–O2), atoms in the order C, O1, O2.
/// α is in [0, π]; the linear equilibrium is α = π.
pub fn co2<T: Real>(x: &[V3<T>]) -> Vec<T> {
    vec![distance(x[1], x[0]), distance(x[2], x[0]), angle(x[1], x[0], x[2])]
}

/// Hydrogen peroxide: (r_OO, r1, r2, θ1, θ2, τ) = (|O2 − O1|, |H1 − O1|, |H2 − O2|,
/// ∠O2–O1–H1, ∠O1–O2–H2, dihedral H1–O1–O2–H2 with the IUPAC sign), atoms in the order
/// O1, O2, H1, H2.
pub fn h2o2<T: Real>(x: &[V3<T>]) -> Vec<T> {
    vec![
        distance(x[1], x[0]),
        distance(x[2], x[0]),
        distance(x[3], x[1]),
        angle(x[1], x[0], x[2]),
        angle(x[0], x[1], x[3]),
        dihedral(x[2], x[0], x[1], x[3]),
    ]
}

/// Ammonia: (r1, r2, r3, α12, α13, α23) with ri = |Hi − N| and αij = ∠Hi–N–Hj, atoms in the
/// order N, H1, H2, H3. Which side of the plane N, H1, H2 the atom H3 is on is not a
/// coordinate: the molecule's parametrization fixes it (one umbrella side).
pub fn nh3<T: Real>(x: &[V3<T>]) -> Vec<T> {
    vec![
        distance(x[1], x[0]),
        distance(x[2], x[0]),
        distance(x[3], x[0]),
        angle(x[1], x[0], x[2]),
        angle(x[1], x[0], x[3]),
        angle(x[2], x[0], x[3]),
    ]
}

/// Methane: (r1, r2, r3, r4, α12, α13, α23, α14, α24) with ri = |Hi − C| and αij = ∠Hi–C–Hj,
/// atoms in the order C, H1, H2, H3, H4. The sixth angle α34 is not a coordinate (it depends on
/// the others); the handedness of the labelled geometry is fixed by the parametrization.
pub fn ch4<T: Real>(x: &[V3<T>]) -> Vec<T> {
    let c = x[0];
    vec![
        distance(x[1], c),
        distance(x[2], c),
        distance(x[3], c),
        distance(x[4], c),
        angle(x[1], c, x[2]),
        angle(x[1], c, x[3]),
        angle(x[2], c, x[3]),
        angle(x[1], c, x[4]),
        angle(x[2], c, x[4]),
    ]
}

/// Hydrogen cyanide: (r_CH, r_CN, α) = (|C − H|, |N − C|, ∠H–C–N), atoms in the order H, C, N;
/// linear at α = π.
pub fn hcn<T: Real>(x: &[V3<T>]) -> Vec<T> {
    vec![distance(x[1], x[0]), distance(x[2], x[1]), angle(x[0], x[1], x[2])]
}

/// Ethane: (r_C1C2, then for each H its r, its H–C–C angle and, for all but H1a, the dihedral
/// H1a–C1–C2–H mapped to [0, 2π) (the definition's staggered reference has azimuths 60°–300°,
/// away from that cut)), atoms in the order C1, C2, H1a, H1b, H1c, H2a, H2b, H2c, coordinates in
/// the definition's order (r, a, d per hydrogen).
pub fn ethane<T: Real>(x: &[V3<T>]) -> Vec<T> {
    let (c1, c2, h1a) = (x[0], x[1], x[2]);
    let mut q = vec![distance(c2, c1)];
    for (k, &h) in x[2..].iter().enumerate() {
        let (c, other) = if k < 3 { (c1, c2) } else { (c2, c1) };
        q.push(distance(h, c));
        q.push(angle(h, c, other));
        if k > 0 {
            let d = dihedral(h1a, c1, c2, h);
            q.push(if d.value() < 0.0 { d + T::from_f64(2.0 * std::f64::consts::PI) } else { d });
        }
    }
    q
}
