//! Directional derivatives (forward tangents) and gradients (reverse adjoints) on the
//! expression graph, for the kinetic-energy gradient of large molecules.
//!
//! [`crate::diff::Differentiator`] differentiates with respect to one variable at a time: the
//! gradient of a scalar in `n` variables costs `n` derivative graphs, and `∂T/∂q` built that way
//! needs every second derivative `∂²r_i/∂q_j∂q_l` of the positions (`Σ_i n_i²` of them). Two
//! classical alternatives (Griewank and Walther, *Evaluating Derivatives*, 2nd ed., SIAM 2008,
//! chapters 3–4) cost a small multiple of the function itself instead:
//!
//! * [`tangent`]: the derivative along a direction, `Σ_k ṡ_k ∂e/∂x_k` with symbolic
//!   direction components `ṡ_k` (forward mode: one tangent node per node);
//! * [`gradient`]: every `∂e/∂x_k` of one scalar `e` at once (reverse mode: each node's adjoint
//!   `ē = ∂e/∂node` is pushed to its operands, `c̄ += ē · ∂node/∂c`, parents before children).
//!
//! Both apply the same chain rules as the one-variable differentiator
//! ([`crate::diff::chain_rule`]) and build their results with the graph's simplifying
//! constructors, so structural zeros stay zeros and shared subexpressions stay shared.

use std::collections::HashMap;

use crate::diff::chain_rule;
use crate::expr::{ExprId, Graph, Node};

/// The derivatives of `roots` along the direction whose component for variable `k` is
/// `seeds[&k]` (variables not in `seeds` have component zero).
pub fn tangent(g: &mut Graph, roots: &[ExprId], seeds: &HashMap<u32, ExprId>) -> Vec<ExprId> {
    let len = g.len();
    let reachable = g.reachable(roots);
    let mut dot: Vec<Option<ExprId>> = vec![None; len];
    let zero = g.zero();
    for i in 0..len {
        if !reachable[i] {
            continue;
        }
        let e = ExprId::from_index(i);
        let d = chain_rule(g, e, |c| dot[c.index()].unwrap_or(zero), |k| seeds.get(&k).copied().unwrap_or(zero));
        dot[i] = Some(d);
    }
    roots.iter().map(|r| dot[r.index()].unwrap_or(zero)).collect()
}

/// `∂root/∂x_k` for every variable `k` in `vars`, by one reverse sweep.
pub fn gradient(g: &mut Graph, root: ExprId, vars: &[u32]) -> Vec<ExprId> {
    let len = g.len();
    let reachable = g.reachable(&[root]);
    // Nodes that depend on one of `vars`: only their adjoints are needed.
    let mut active = vec![false; len];
    let mut var_node: HashMap<u32, usize> = HashMap::new();
    for i in 0..len {
        if !reachable[i] {
            continue;
        }
        active[i] = match g.nodes()[i] {
            Node::Var(k) => {
                var_node.insert(k, i);
                vars.contains(&k)
            }
            node => node.children().any(|c| active[c.index()]),
        };
    }
    let zero = g.zero();
    let mut adjoint: Vec<Option<ExprId>> = vec![None; len];
    if active[root.index()] {
        adjoint[root.index()] = Some(g.one());
    }
    for i in (0..len).rev() {
        let Some(bar) = adjoint[i] else { continue };
        if !active[i] || g.is_zero(bar) {
            continue;
        }
        let e = ExprId::from_index(i);
        // Each distinct operand once, in operand order (a branch `if(x < 0, -x, x)` has `x` twice,
        // apart).
        let mut children: Vec<ExprId> = Vec::new();
        for c in g.node(e).children().filter(|c| active[c.index()]) {
            if !children.contains(&c) {
                children.push(c);
            }
        }
        for c in children {
            // The chain rule with operand c's derivative set to the adjoint and every other
            // operand's to zero is bar · ∂e/∂c (both operands when they are the same node).
            let contribution = chain_rule(g, e, |x| if x == c { bar } else { zero }, |_| zero);
            adjoint[c.index()] = Some(match adjoint[c.index()] {
                Some(sum) => g.add(sum, contribution),
                None => contribution,
            });
        }
    }
    vars.iter().map(|k| var_node.get(k).and_then(|&i| adjoint[i]).unwrap_or(zero)).collect()
}
