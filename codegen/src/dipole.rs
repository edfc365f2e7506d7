//! The dipole moment surface: from a definition's `[dipole]` table to the body-frame dipole
//! μ(q) in e·bohr and its q-derivatives, as expressions in the definition's graph.
//!
//! The components form is used as given (already converted to e·bohr by [`crate::definition`]);
//! the charges form becomes μ = Σ_i q_i(q) R_i(q) with the centred positions, so the dipole of
//! a neutral molecule does not depend on the origin and that of an ion is taken about the
//! centre of mass. Nothing here is built, and nothing is emitted, for a definition without a
//! `[dipole]` table.

use crate::definition::{Definition, DipoleDef};
use crate::diff::Differentiator;
use crate::expr::ExprId;

/// The dipole expressions of one molecule.
pub struct DipoleExprs {
    /// `[μx, μy, μz]` in the body frame, e·bohr.
    pub mu: [ExprId; 3],
    /// `jacobian[k][axis] = ∂μ_axis/∂q_k`, e·bohr per unit of q_k.
    pub jacobian: Vec<[ExprId; 3]>,
}

/// Builds μ(q) and ∂μ/∂q for `def`, given its centred positions (bohr), or `None` if the
/// definition has no dipole.
pub fn build(def: &mut Definition, centred: &[[ExprId; 3]]) -> Option<DipoleExprs> {
    let n = def.coordinates.len();
    let dipole = def.dipole.clone()?;
    let g = &mut def.graph;
    let mu = match dipole {
        DipoleDef::Components(mu) => mu,
        DipoleDef::Charges(charges) => {
            let mut mu = [g.zero(); 3];
            for (q, r) in charges.iter().zip(centred) {
                for axis in 0..3 {
                    let t = g.mul(*q, r[axis]);
                    mu[axis] = g.add(mu[axis], t);
                }
            }
            mu
        }
    };
    let mut diff = Differentiator::new();
    let jacobian = (0..n).map(|k| mu.map(|c| diff.derivative(g, c, k as u32))).collect();
    Some(DipoleExprs { mu, jacobian })
}
