//! From body-frame positions to the kinetic matrices and every derivative the runtime needs.
//!
//! Given the positions `R_i(q)` of a [`Definition`], this builds, in the definition's graph:
//!
//! * the centred positions `R_i − Σ_j m_j R_j / M` (the shift is symbolic, so the generated
//!   positions satisfy `Σ m_i R_i = 0` for every q);
//! * `∂R_i/∂q_k`;
//! * `a_jk = Σ_i m_i ∂R_i/∂q_j · ∂R_i/∂q_k`, `A_jk = Σ_i m_i [R_i × ∂R_i/∂q_k]_j`,
//!   `I = Σ_i m_i (|R_i|² 1 − R_i R_iᵀ)` and their derivatives along every `q_k`;
//! * the kinetic energy `T = ½ Σ_i m_i |ω × R_i + Σ_j ∂R_i/∂q_j q̇_j|²` as a function of q, ω and
//!   q̇, and its q-gradient at fixed (ω, q̇), which gives `∂H/∂q` without differentiating any
//!   inverse matrix;
//! * `U(q)` and `∂U/∂q`.
//!
//! Sums are built as sums (not expanded), so the generated code evaluates the kinetic matrices
//! the way one would by hand, and hash-consing shares `R_i` and `∂R_i/∂q_k` among all of them.

use crate::definition::Definition;
use crate::diff::Differentiator;
use crate::expr::{ExprId, Graph};
use crate::units::DALTON_IN_ELECTRON_MASSES;

/// Every expression the generated code evaluates, for one molecule.
pub struct KineticExprs {
    /// Number of internal coordinates.
    pub n: usize,
    /// Centred positions in bohr: `positions[atom][axis]`.
    pub positions: Vec<[ExprId; 3]>,
    /// `jacobian[k][atom][axis] = ∂R/∂q_k`.
    pub jacobian: Vec<Vec<[ExprId; 3]>>,
    /// The kinetic matrices.
    pub kinetic: KineticSet,
    /// `kinetic_jacobian[k]`: the derivatives of the kinetic matrices along `q_k`.
    pub kinetic_jacobian: Vec<KineticSet>,
    /// The kinetic energy as a function of q, ω (variables n..n+3) and q̇ (variables n+3..2n+3).
    pub kinetic_energy: ExprId,
    /// `∂T/∂q_k` at fixed ω and q̇.
    pub kinetic_gradient: Vec<ExprId>,
    /// The potential in hartree.
    pub potential: ExprId,
    /// `∂U/∂q_k`.
    pub potential_gradient: Vec<ExprId>,
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
pub fn build(def: &mut Definition) -> KineticExprs {
    let n = def.coordinates.len();
    let masses: Vec<f64> = def.atoms.iter().map(|a| a.mass_da * DALTON_IN_ELECTRON_MASSES).collect();
    let g = &mut def.graph;
    let mut diff = Differentiator::new();

    let positions = centred(g, &def.positions, &masses);
    let jacobian: Vec<Vec<[ExprId; 3]>> =
        (0..n).map(|k| positions.iter().map(|r| r.map(|c| diff.derivative(g, c, k as u32))).collect()).collect();

    let kinetic = kinetic_set(g, &masses, &positions, &jacobian);
    let kinetic_jacobian = (0..n)
        .map(|l| {
            let l = l as u32;
            KineticSet {
                a: kinetic.a.iter().map(|row| row.iter().map(|&e| diff.derivative(g, e, l)).collect()).collect(),
                coriolis: kinetic.coriolis.clone().map(|row| row.iter().map(|&e| diff.derivative(g, e, l)).collect()),
                inertia: kinetic.inertia.map(|row| row.map(|e| diff.derivative(g, e, l))),
            }
        })
        .collect();

    // Velocity variables come after the coordinates, in this order.
    // Their graph names are not identifiers, so no coordinate name can alias them (a coordinate
    // called `omega_x` must stay a variable of its own).
    let omega: Vec<ExprId> = ["ω_x", "ω_y", "ω_z"].iter().map(|name| g.var(name)).collect();
    let qdot: Vec<ExprId> = def.coordinates.iter().map(|c| g.var(&format!("q̇_{}", c.name))).collect();
    assert_eq!(g.var_count(), 2 * n + 3, "velocity variables are new variables");
    let mut kinetic_energy = g.zero();
    for (i, r) in positions.iter().enumerate() {
        // u_i = ω × R_i + Σ_j ∂R_i/∂q_j q̇_j, the body-frame velocity of atom i.
        let mut u = cross(g, [omega[0], omega[1], omega[2]], *r);
        for (j, &qd) in qdot.iter().enumerate() {
            for axis in 0..3 {
                let t = g.mul(jacobian[j][i][axis], qd);
                u[axis] = g.add(u[axis], t);
            }
        }
        let u2 = dot(g, u, u);
        let m = g.constant(0.5 * masses[i]);
        let term = g.mul(m, u2);
        kinetic_energy = g.add(kinetic_energy, term);
    }
    let kinetic_gradient = (0..n).map(|k| diff.derivative(g, kinetic_energy, k as u32)).collect();

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
        potential,
        potential_gradient,
    }
}

/// Shifts the positions so that the centre of mass is at the origin.
fn centred(g: &mut Graph, positions: &[[ExprId; 3]], masses: &[f64]) -> Vec<[ExprId; 3]> {
    let total: f64 = masses.iter().sum();
    let mut com = [g.zero(); 3];
    for (r, &m) in positions.iter().zip(masses) {
        for axis in 0..3 {
            let w = g.constant(m / total);
            let t = g.mul(w, r[axis]);
            com[axis] = g.add(com[axis], t);
        }
    }
    positions.iter().map(|r| [0, 1, 2].map(|axis| g.sub(r[axis], com[axis]))).collect()
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

/// `a`, `A` and `I` from the positions and their jacobian (eq. 3 of the seed).
fn kinetic_set(g: &mut Graph, masses: &[f64], r: &[[ExprId; 3]], dr: &[Vec<[ExprId; 3]>]) -> KineticSet {
    let n = dr.len();
    let mut a = vec![vec![g.zero(); n]; n];
    for j in 0..n {
        for k in j..n {
            let mut s = g.zero();
            for (i, &m) in masses.iter().enumerate() {
                let d = dot(g, dr[j][i], dr[k][i]);
                let m = g.constant(m);
                let t = g.mul(m, d);
                s = g.add(s, t);
            }
            a[j][k] = s;
            a[k][j] = s;
        }
    }
    let mut coriolis: [Vec<ExprId>; 3] = [vec![g.zero(); n], vec![g.zero(); n], vec![g.zero(); n]];
    for k in 0..n {
        let mut s = [g.zero(); 3];
        for (i, &m) in masses.iter().enumerate() {
            let c = cross(g, r[i], dr[k][i]);
            let m = g.constant(m);
            for axis in 0..3 {
                let t = g.mul(m, c[axis]);
                s[axis] = g.add(s[axis], t);
            }
        }
        for axis in 0..3 {
            coriolis[axis][k] = s[axis];
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
    KineticSet { a, coriolis, inertia }
}
