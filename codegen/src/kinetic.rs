//! From body-frame positions to the kinetic matrices and every derivative the runtime needs.
//!
//! Given the positions `r_i(q)` of a [`Definition`] (as written, not centred), this builds, in
//! the definition's graph:
//!
//! * the centre of mass `c = Σ m_i r_i / M` and the centred positions `R_i = r_i − c`, as
//!   values: `c` is one shared node the generated code computes once, never substituted into
//!   anything symbolically;
//! * the raw derivatives `∂r_i/∂q_k`, which are structurally sparse for local (Z-matrix-like)
//!   coordinates: an atom's position depends only on the coordinates between it and the
//!   body frame's origin; `∂c/∂q_k = Σ m_i ∂r_i/∂q_k / M`; and `∂R_i/∂q_k = ∂r_i/∂q_k − ∂c/∂q_k`
//!   (dense, for `positions_jacobian` only);
//! * `a`, `A`, `I` from the sparse raw derivatives, with the centre of mass applied once per
//!   entry instead of inside every atom's term (`docs/src/reference/equations.md`, section 2, "Sparse
//!   assembly"):
//!
//!   ```text
//!   a_jk = Σ_i m_i ∂r_i/∂q_j · ∂r_i/∂q_k − M ∂c/∂q_j · ∂c/∂q_k
//!   A_·k = Σ_i m_i R_i × ∂r_i/∂q_k                          (Σ_i m_i R_i = 0)
//!   I    = Σ_i m_i (|R_i|² 1 − R_i R_iᵀ)
//!   ```
//!
//!   where the sums run only over the atoms whose `∂r_i/∂q_k` is not a structural zero;
//! * the kinetic energy `T = ½ Σ_i m_i |u_i|²` with the body-frame atom velocities
//!   `u_i = ω × R_i + Σ_j ∂r_i/∂q_j q̇_j − Σ_j ∂c/∂q_j q̇_j`, and its q-gradient at fixed
//!   (ω, q̇), built directly as
//!
//!   ```text
//!   ∂T/∂q_l = Σ_i m_i u_i · (ω × ∂r_i/∂q_l + Σ_j ∂²r_i/∂q_j∂q_l q̇_j)    (Σ_i m_i u_i = 0)
//!   ```
//!
//!   again over the atoms that depend on `q_l`, with each second derivative built once for
//!   `j ≤ l` (the symbolic derivative of a shared first derivative);
//! * `U(q)` and `∂U/∂q`;
//! * only if asked for ([`Options::kinetic_jacobian`]), `∂a/∂q`, `∂A/∂q`, `∂I/∂q` symbolically;
//!   by default the reference path gets them from the runtime (`Kinematics::kinetic_jacobian`'s
//!   default, from the generated `∂T/∂q`), since the production path never needs them.
//!
//! The cost of the generated production code is then about `Σ_i n_i² + n²` operations (`n_i`
//! the coordinates atom i depends on) instead of `NA · n²` (dense centred derivatives), and
//! the optional `kinetic_jacobian` adds `n³`-order code.

use std::collections::HashMap;

use crate::adjoint;
use crate::definition::Definition;
use crate::diff::Differentiator;
use crate::expr::{ExprId, Graph};
use crate::units::DALTON_IN_ELECTRON_MASSES;

/// What to generate beyond the production path, and how.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Options {
    /// Generate `kinetic_jacobian` (∂a/∂q, ∂A/∂q, ∂I/∂q) symbolically; `n(n² + 3n + 9)`
    /// outputs, by far the largest function for large molecules. Off by default: the runtime's
    /// default method computes the same matrices from the generated `∂T/∂q`.
    pub kinetic_jacobian: bool,
    /// How `∂T/∂q` is built (default: whichever makes the smaller production function).
    pub kinetic_gradient: GradientMethod,
    /// From this many internal coordinates on, the centre-of-mass term of `a` (a dense
    /// `n × n` rank-3 update) is applied by the runtime in a loop rather than emitted as
    /// `n(n + 1)/2` expressions ([`RunTimeCentreOfMass`]). Default [`RUN_TIME_CENTRE_OF_MASS_FROM`].
    pub run_time_centre_of_mass_from: usize,
}

/// The default of [`Options::run_time_centre_of_mass_from`]: every shipped molecule up to
/// every shipped molecule (ethane, 18 coordinates, is the largest) keeps the expanded form, which
/// measured faster for ethane; propane (27) and larger use the loop.
pub const RUN_TIME_CENTRE_OF_MASS_FROM: usize = 24;

impl Default for Options {
    fn default() -> Self {
        Self {
            kinetic_jacobian: false,
            kinetic_gradient: GradientMethod::Auto,
            run_time_centre_of_mass_from: RUN_TIME_CENTRE_OF_MASS_FROM,
        }
    }
}

/// How the generated `∂T/∂q` is built (both give the same numbers up to rounding).
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum GradientMethod {
    /// Whichever of the two below gives fewer operations in the fused production function
    /// (`kinetic_and_gradient`); ties keep [`GradientMethod::Direct`].
    #[default]
    Auto,
    /// From the explicit second derivatives of the positions (`Σ_i n_i²` of them).
    Direct,
    /// By a directional derivative of the positions along q̇ and one reverse sweep over `T`.
    Reverse,
}

/// Every expression the generated code evaluates, for one molecule.
pub struct KineticExprs {
    /// Number of internal coordinates.
    pub n: usize,
    /// Centred positions in bohr: `positions[atom][axis]`.
    pub positions: Vec<[ExprId; 3]>,
    /// `jacobian[k][atom][axis] = ∂R/∂q_k` (centred).
    pub jacobian: Vec<Vec<[ExprId; 3]>>,
    /// The kinetic matrices.
    pub kinetic: KineticSet,
    /// `kinetic_jacobian[k]`: the derivatives of the kinetic matrices along `q_k`, if generated.
    pub kinetic_jacobian: Option<Vec<KineticSet>>,
    /// The kinetic energy as a function of q, ω (variables n..n+3) and q̇ (variables n+3..2n+3).
    pub kinetic_energy: ExprId,
    /// `∂T/∂q_k` at fixed ω and q̇.
    pub kinetic_gradient: Vec<ExprId>,
    /// How `kinetic_gradient` was built ([`GradientMethod::Direct`] or
    /// [`GradientMethod::Reverse`], never `Auto`).
    pub gradient_method: GradientMethod,
    /// The potential in hartree.
    pub potential: ExprId,
    /// `∂U/∂q_k`.
    pub potential_gradient: Vec<ExprId>,
    /// (atom, coordinate) pairs whose raw position derivative is not a structural zero.
    pub nonzero_derivatives: usize,
    /// For large molecules ([`Options::run_time_centre_of_mass_from`]), what the production
    /// functions emit instead of `kinetic.a`: the centre-of-mass term of `a` is then applied at
    /// run time.
    pub centre_of_mass_at_run_time: Option<RunTimeCentreOfMass>,
}

/// `a` without its centre-of-mass term, and what that term is made of:
/// `a_jk = sparse_jk − M ∂c/∂q_j · ∂c/∂q_k`, a dense rank-3 update that the runtime applies in a
/// loop (`rovib_runtime::assembly::remove_centre_of_mass`) instead of `n(n + 1)/2` expanded
/// expressions.
#[derive(Clone, Debug)]
pub struct RunTimeCentreOfMass {
    /// `Σ_i m_i ∂r_i/∂q_j · ∂r_i/∂q_k` (symmetric, structurally sparse).
    pub a: Vec<Vec<ExprId>>,
    /// `∂c/∂q_k`, the centre of mass's derivatives.
    pub dcom: Vec<[ExprId; 3]>,
    /// The total mass `M` in electron masses.
    pub total: f64,
}

/// `a` (n × n, row-major), `A` (3 × n), `I` (3 × 3), or one derivative of each.
#[derive(Clone, Debug)]
pub struct KineticSet {
    /// `a[j][k]`.
    pub a: Vec<Vec<ExprId>>,
    /// `coriolis[axis][k]`.
    pub coriolis: [Vec<ExprId>; 3],
    /// `inertia[axis][axis]`.
    pub inertia: [[ExprId; 3]; 3],
}

/// The local variables of generated code that hold ω (graph variables n..n+3).
pub const OMEGA_NAMES: [&str; 3] = ["omega_x", "omega_y", "omega_z"];

/// Builds every expression for `def` into its graph.
pub fn build(def: &mut Definition, options: &Options) -> KineticExprs {
    let n = def.coordinates.len();
    let masses: Vec<f64> = def.atoms.iter().map(|a| a.mass_da * DALTON_IN_ELECTRON_MASSES).collect();
    let total: f64 = masses.iter().sum();
    let na = masses.len();
    let g = &mut def.graph;
    let mut diff = Differentiator::new();

    // Raw derivatives and which atoms depend on which coordinates.
    let raw = def.positions.clone();
    let dr: Vec<Vec<[ExprId; 3]>> =
        (0..n).map(|k| raw.iter().map(|r| r.map(|c| diff.derivative(g, c, k as u32))).collect()).collect();
    let depends: Vec<Vec<bool>> =
        (0..n).map(|k| (0..na).map(|i| dr[k][i].iter().any(|&c| !g.is_zero(c))).collect()).collect();
    // Coordinates of each atom, in order.
    let support: Vec<Vec<usize>> = (0..na).map(|i| (0..n).filter(|&k| depends[k][i]).collect()).collect();
    let nonzero_derivatives = support.iter().map(Vec::len).sum();

    // Centre of mass and its derivatives: shared values, applied once.
    let weights: Vec<f64> = masses.iter().map(|m| m / total).collect();
    let com = weighted_sum(g, raw.iter().zip(&weights).map(|(r, &w)| (*r, w)));
    let positions: Vec<[ExprId; 3]> = raw.iter().map(|r| [0, 1, 2].map(|axis| g.sub(r[axis], com[axis]))).collect();
    let dcom: Vec<[ExprId; 3]> =
        (0..n).map(|k| weighted_sum(g, (0..na).filter(|&i| depends[k][i]).map(|i| (dr[k][i], weights[i])))).collect();
    let jacobian: Vec<Vec<[ExprId; 3]>> =
        (0..n).map(|k| dr[k].iter().map(|d| [0, 1, 2].map(|axis| g.sub(d[axis], dcom[k][axis]))).collect()).collect();

    let (kinetic, sparse_a) = kinetic_set(g, &masses, total, &positions, &dr, &dcom, &support);
    let centre_of_mass_at_run_time = (n >= options.run_time_centre_of_mass_from).then(|| RunTimeCentreOfMass {
        a: sparse_a,
        dcom: dcom.clone(),
        total,
    });
    let kinetic_jacobian = options.kinetic_jacobian.then(|| {
        (0..n)
            .map(|l| {
                let l = l as u32;
                KineticSet {
                    a: kinetic.a.iter().map(|row| row.iter().map(|&e| diff.derivative(g, e, l)).collect()).collect(),
                    coriolis: kinetic
                        .coriolis
                        .clone()
                        .map(|row| row.iter().map(|&e| diff.derivative(g, e, l)).collect()),
                    inertia: kinetic.inertia.map(|row| row.map(|e| diff.derivative(g, e, l))),
                }
            })
            .collect()
    });

    // Velocity variables come after the coordinates, in this order.
    // Their graph names are not identifiers, so no coordinate name can alias them (a coordinate
    // called `omega_x` must stay a variable of its own).
    let omega: Vec<ExprId> = ["ω_x", "ω_y", "ω_z"].iter().map(|name| g.var(name)).collect();
    let omega = [omega[0], omega[1], omega[2]];
    let qdot: Vec<ExprId> = def.coordinates.iter().map(|c| g.var(&format!("q̇_{}", c.name))).collect();
    assert_eq!(g.var_count(), 2 * n + 3, "velocity variables are new variables");

    let direct = direct_gradient(g, &mut diff, &masses, &positions, &dr, &dcom, &support, omega, &qdot);
    let reverse = adjoint_gradient(g, &masses, &weights, &raw, &positions, omega, &qdot);
    let emitted_a = centre_of_mass_at_run_time.as_ref().map_or(&kinetic.a, |c| &c.a);
    let kinetic_roots: Vec<ExprId> = emitted_a
        .iter()
        .flatten()
        .chain(centre_of_mass_at_run_time.iter().flat_map(|c| c.dcom.iter().flatten()))
        .chain(kinetic.coriolis.iter().flatten())
        .chain(kinetic.inertia.iter().flatten())
        .copied()
        .collect();
    // The fused production function evaluates the kinetic matrices, T and ∂T/∂q: count it with
    // each gradient and keep the smaller (ties keep the direct method).
    let cost = |g: &Graph, (t, grad): &(ExprId, Vec<ExprId>)| {
        let mut roots = kinetic_roots.clone();
        roots.extend(grad.iter().copied());
        roots.push(*t);
        crate::emit::operations(g, &roots)
    };
    let method = match options.kinetic_gradient {
        GradientMethod::Auto if cost(g, &reverse) < cost(g, &direct) => GradientMethod::Reverse,
        GradientMethod::Auto => GradientMethod::Direct,
        chosen => chosen,
    };
    let (kinetic_energy, kinetic_gradient) = if method == GradientMethod::Reverse { reverse } else { direct };

    let potential = def.potential;
    let potential_gradient = (0..n).map(|k| diff.derivative(g, potential, k as u32)).collect();

    KineticExprs {
        n,
        positions,
        jacobian,
        kinetic,
        kinetic_jacobian,
        kinetic_energy,
        kinetic_gradient,
        gradient_method: method,
        centre_of_mass_at_run_time,
        potential,
        potential_gradient,
        nonzero_derivatives,
    }
}

/// `(T, ∂T/∂q)` with every second derivative of the positions built explicitly: `u_i` from the
/// sparse first derivatives and `∂T/∂q_l = Σ_i m_i u_i · ∂u_i/∂q_l` over the atoms that depend
/// on `q_l`, `Σ_i n_i²` second derivatives in all. Cheapest for small molecules.
fn direct_gradient(
    g: &mut Graph,
    diff: &mut Differentiator,
    masses: &[f64],
    positions: &[[ExprId; 3]],
    dr: &[Vec<[ExprId; 3]>],
    dcom: &[[ExprId; 3]],
    support: &[Vec<usize>],
    omega: [ExprId; 3],
    qdot: &[ExprId],
) -> (ExprId, Vec<ExprId>) {
    let (n, na) = (qdot.len(), masses.len());
    // u_i = ω × R_i + Σ_j ∂r_i/∂q_j q̇_j − Σ_j ∂c/∂q_j q̇_j, the body-frame velocity of atom i.
    let mut com_velocity = [g.zero(); 3];
    for (k, &qd) in qdot.iter().enumerate() {
        for axis in 0..3 {
            let t = g.mul(dcom[k][axis], qd);
            com_velocity[axis] = g.add(com_velocity[axis], t);
        }
    }
    let mut velocities = Vec::with_capacity(na);
    let mut kinetic_energy = g.zero();
    for (i, r) in positions.iter().enumerate() {
        let mut u = cross(g, omega, *r);
        for &j in &support[i] {
            for axis in 0..3 {
                let t = g.mul(dr[j][i][axis], qdot[j]);
                u[axis] = g.add(u[axis], t);
            }
        }
        for axis in 0..3 {
            u[axis] = g.sub(u[axis], com_velocity[axis]);
        }
        let u2 = dot(g, u, u);
        let m = g.constant(0.5 * masses[i]);
        let term = g.mul(m, u2);
        kinetic_energy = g.add(kinetic_energy, term);
        velocities.push(u);
    }
    // ∂T/∂q_l = Σ_i m_i u_i · ∂u_i/∂q_l over the atoms that depend on q_l; the centre-of-mass
    // part of ∂u_i/∂q_l drops out because Σ_i m_i u_i = 0.
    let mut kinetic_gradient = vec![g.zero(); n];
    for i in 0..na {
        for &l in &support[i] {
            let mut du = cross(g, omega, dr[l][i]);
            for &j in &support[i] {
                // ∂²r_i/∂q_j∂q_l, built once per unordered pair (the derivative of the
                // lower-numbered first derivative), so both orders share it.
                let (lo, hi) = if j <= l { (j, l) } else { (l, j) };
                for axis in 0..3 {
                    let d2 = diff.derivative(g, dr[lo][i][axis], hi as u32);
                    let t = g.mul(d2, qdot[j]);
                    du[axis] = g.add(du[axis], t);
                }
            }
            let p = dot(g, velocities[i], du);
            let m = g.constant(masses[i]);
            let t = g.mul(m, p);
            kinetic_gradient[l] = g.add(kinetic_gradient[l], t);
        }
    }

    (kinetic_energy, kinetic_gradient)
}

/// `(T, ∂T/∂q)` by forward and reverse differentiation ([`crate::adjoint`]): the atom
/// velocities `v_i = Σ_j ∂r_i/∂q_j q̇_j` as one directional derivative of the raw positions
/// along q̇, `u_i = ω × R_i + v_i − Σ_j (m_j/M) v_j`, `T = ½ Σ_i m_i |u_i|²`, and the whole
/// gradient of that `T` in q by one reverse sweep. Its cost is a small multiple of the
/// positions' and does not grow with the number of second derivatives, which wins for large
/// molecules.
fn adjoint_gradient(
    g: &mut Graph,
    masses: &[f64],
    weights: &[f64],
    raw: &[[ExprId; 3]],
    positions: &[[ExprId; 3]],
    omega: [ExprId; 3],
    qdot: &[ExprId],
) -> (ExprId, Vec<ExprId>) {
    let n = qdot.len();
    let seeds: HashMap<u32, ExprId> = (0..n).map(|k| (k as u32, qdot[k])).collect();
    let flat: Vec<ExprId> = raw.iter().flatten().copied().collect();
    let v = adjoint::tangent(g, &flat, &seeds);
    let velocities: Vec<[ExprId; 3]> = v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    let com_velocity = weighted_sum(g, velocities.iter().zip(weights).map(|(v, &w)| (*v, w)));
    let mut kinetic_energy = g.zero();
    for (i, r) in positions.iter().enumerate() {
        let mut u = cross(g, omega, *r);
        for axis in 0..3 {
            let relative = g.sub(velocities[i][axis], com_velocity[axis]);
            u[axis] = g.add(u[axis], relative);
        }
        let u2 = dot(g, u, u);
        let m = g.constant(0.5 * masses[i]);
        let term = g.mul(m, u2);
        kinetic_energy = g.add(kinetic_energy, term);
    }
    let vars: Vec<u32> = (0..n as u32).collect();
    let gradient = adjoint::gradient(g, kinetic_energy, &vars);
    (kinetic_energy, gradient)
}

/// `Σ w v` over weighted vectors.
fn weighted_sum(g: &mut Graph, terms: impl Iterator<Item = ([ExprId; 3], f64)>) -> [ExprId; 3] {
    let mut s = [g.zero(); 3];
    for (v, w) in terms {
        let w = g.constant(w);
        for axis in 0..3 {
            let t = g.mul(w, v[axis]);
            s[axis] = g.add(s[axis], t);
        }
    }
    s
}

fn dot(g: &mut Graph, u: [ExprId; 3], v: [ExprId; 3]) -> ExprId {
    let mut s = g.mul(u[0], v[0]);
    for axis in 1..3 {
        let t = g.mul(u[axis], v[axis]);
        s = g.add(s, t);
    }
    s
}

fn cross(g: &mut Graph, u: [ExprId; 3], v: [ExprId; 3]) -> [ExprId; 3] {
    [(1, 2), (2, 0), (0, 1)].map(|(i, j)| {
        let l = g.mul(u[i], v[j]);
        let r = g.mul(u[j], v[i]);
        g.sub(l, r)
    })
}

/// `a`, `A` and `I` (eq. 3 of the seed) from the centred positions `r`, the raw derivatives
/// `dr` with their atom supports, and the centre of mass's derivatives `dcom`.
fn kinetic_set(
    g: &mut Graph,
    masses: &[f64],
    total: f64,
    r: &[[ExprId; 3]],
    dr: &[Vec<[ExprId; 3]>],
    dcom: &[[ExprId; 3]],
    support: &[Vec<usize>],
) -> (KineticSet, Vec<Vec<ExprId>>) {
    let n = dr.len();
    // a_jk = Σ_i m_i ∂r_i/∂q_j · ∂r_i/∂q_k − M ∂c/∂q_j · ∂c/∂q_k, accumulated atom by atom over
    // the pairs (j, k) both in the atom's support.
    let mut sums = vec![vec![g.zero(); n]; n];
    for (i, &m) in masses.iter().enumerate() {
        let m = g.constant(m);
        for (x, &j) in support[i].iter().enumerate() {
            for &k in &support[i][x..] {
                let d = dot(g, dr[j][i], dr[k][i]);
                let t = g.mul(m, d);
                sums[j][k] = g.add(sums[j][k], t);
            }
        }
    }
    let mut sparse_a = vec![vec![g.zero(); n]; n];
    for j in 0..n {
        for k in j..n {
            sparse_a[j][k] = sums[j][k];
            sparse_a[k][j] = sums[j][k];
        }
    }
    let mut a = vec![vec![g.zero(); n]; n];
    let total = g.constant(total);
    for j in 0..n {
        for k in j..n {
            let d = dot(g, dcom[j], dcom[k]);
            let c = g.mul(total, d);
            let s = g.sub(sums[j][k], c);
            a[j][k] = s;
            a[k][j] = s;
        }
    }
    let mut coriolis: [Vec<ExprId>; 3] = [vec![g.zero(); n], vec![g.zero(); n], vec![g.zero(); n]];
    for (i, &m) in masses.iter().enumerate() {
        let m = g.constant(m);
        for &k in &support[i] {
            let c = cross(g, r[i], dr[k][i]);
            for axis in 0..3 {
                let t = g.mul(m, c[axis]);
                coriolis[axis][k] = g.add(coriolis[axis][k], t);
            }
        }
    }
    let mut inertia = [[g.zero(); 3]; 3];
    for p in 0..3 {
        for q in p..3 {
            let mut s = g.zero();
            for (i, &m) in masses.iter().enumerate() {
                // I_pq = Σ m (δ_pq |R|² − R_p R_q); on the diagonal |R|² − R_p² is the sum of the
                // other two squares, which is what we build to avoid cancellation.
                let term = if p == q {
                    let others: Vec<usize> = (0..3).filter(|&x| x != p).collect();
                    let a2 = g.powi(r[i][others[0]], 2);
                    let b2 = g.powi(r[i][others[1]], 2);
                    g.add(a2, b2)
                } else {
                    let prod = g.mul(r[i][p], r[i][q]);
                    g.neg(prod)
                };
                let m = g.constant(m);
                let t = g.mul(m, term);
                s = g.add(s, t);
            }
            inertia[p][q] = s;
            inertia[q][p] = s;
        }
    }
    (KineticSet { a, coriolis, inertia }, sparse_a)
}
