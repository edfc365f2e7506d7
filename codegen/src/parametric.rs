//! The potential with its parameters as run-time inputs: the definition's potential expression
//! built again with every `[potential.parameters]` entry a graph variable instead of a constant,
//! and its gradient in q. The generated `potential_with` and `potential_gradient_with` take the
//! parameters' values in a slice (in the definition's order, `Molecule::parameters`), so that a
//! scene can change them without rebuilding; `potential` and `potential_gradient` keep the
//! compiled-in values folded into constants.

use crate::definition::Definition;
use crate::diff::Differentiator;
use crate::expr::ExprId;
use crate::parse::{Scope, parse_expression};

/// The parametric potential of a definition with parameters.
pub struct ParametricExprs {
    /// U(q, params) in hartree.
    pub potential: ExprId,
    /// ∂U/∂q_k.
    pub gradient: Vec<ExprId>,
    /// The graph variable of parameter 0; parameter i is `first_var + i`.
    pub first_var: u32,
}

/// Builds the parametric potential (call after every other variable of the graph exists, so
/// that the parameters' variables come last). `None` if the definition has no parameters (or,
/// which cannot happen for a validated definition, its potential no longer parses).
pub fn build(def: &mut Definition) -> Option<ParametricExprs> {
    if def.parameters.is_empty() {
        return None;
    }
    let mut names = def.potential_scope.clone();
    let first_var = def.graph.var_count() as u32;
    for (i, (name, _)) in def.parameters.iter().enumerate() {
        let v = def.graph.var(&format!("param{i}"));
        names.insert(name.clone(), v);
    }
    let scope = Scope { names: &names, context: "the potential", library: &def.library, named: true };
    let u = parse_expression(&mut def.graph, &def.potential_text, &scope).ok()?;
    let scale = def.graph.constant(def.energy_unit.in_hartree());
    let potential = def.graph.mul(scale, u);
    let mut diff = Differentiator::new();
    let gradient = (0..def.coordinates.len()).map(|k| diff.derivative(&mut def.graph, potential, k as u32)).collect();
    Some(ParametricExprs { potential, gradient, first_var })
}
