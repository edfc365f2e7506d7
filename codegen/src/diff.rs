//! Symbolic differentiation on the expression graph.
//!
//! [`Differentiator`] applies the chain rule node by node and memoises `(node, variable)` pairs,
//! so a derivative of a shared subexpression is built once and is itself shared. Derivatives are
//! built with the graph's simplifying constructors: a node that does not depend on the variable
//! has derivative 0, and the zero propagates, so a derivative known to be zero is the constant 0
//! (a structural zero the emitter writes no code for).

use std::collections::HashMap;

use crate::expr::{ExprId, Func, Graph, Node};

/// Builds and memoises derivatives in one graph.
#[derive(Default)]
pub struct Differentiator {
    memo: HashMap<(ExprId, u32), ExprId>,
}

impl Differentiator {
    /// A differentiator with an empty memo.
    pub fn new() -> Self {
        Self::default()
    }

    /// `∂e/∂x_var` where `var` is a variable number of `g`.
    pub fn derivative(&mut self, g: &mut Graph, e: ExprId, var: u32) -> ExprId {
        // Work list instead of recursion: derivative chains of large molecules are deep.
        let mut stack = vec![e];
        while let Some(&top) = stack.last() {
            if self.memo.contains_key(&(top, var)) {
                stack.pop();
                continue;
            }
            let pending: Vec<ExprId> = g.node(top).children().filter(|c| !self.memo.contains_key(&(*c, var))).collect();
            if pending.is_empty() {
                let memo = &self.memo;
                let (zero, one) = (g.zero(), g.one());
                let d = chain_rule(g, top, |c| memo[&(c, var)], |k| if k == var { one } else { zero });
                self.memo.insert((top, var), d);
                stack.pop();
            } else {
                stack.extend(pending);
            }
        }
        self.memo[&(e, var)]
    }
}

/// One step of the chain rule for node `e`: its derivative, given its operands' derivatives
/// `d(operand)` and, for a variable node, `dvar(variable)`. Differentiating with respect to one
/// variable, `dvar` is 1 for it and 0 for the rest; along a direction ([`crate::adjoint`]) it
/// is the direction's component.
pub fn chain_rule(g: &mut Graph, e: ExprId, d: impl Fn(ExprId) -> ExprId, dvar: impl Fn(u32) -> ExprId) -> ExprId {
    {
        let node = g.node(e);
        if !matches!(node, Node::Var(_)) && node.children().all(|c| g.is_zero(d(c))) {
            // Nothing below depends on the variable: a structural zero, with no garbage nodes.
            return g.zero();
        }
        match node {
            Node::Const(_) => g.zero(),
            Node::Var(k) => dvar(k),
            Node::Neg(a) => g.neg(d(a)),
            Node::Add(a, b) => g.add(d(a), d(b)),
            Node::Sub(a, b) => g.sub(d(a), d(b)),
            Node::Mul(a, b) => {
                let l = g.mul(d(a), b);
                let r = g.mul(a, d(b));
                g.add(l, r)
            }
            Node::Div(a, b) => {
                // (a/b)' = a'/b − (a/b)·(b'/b), reusing the quotient node itself.
                let l = g.div(d(a), b);
                let db_over_b = g.div(d(b), b);
                let r = g.mul(e, db_over_b);
                g.sub(l, r)
            }
            Node::Powi(a, n) => {
                let n_c = g.constant(f64::from(n));
                let p = g.powi(a, n - 1);
                let np = g.mul(n_c, p);
                g.mul(np, d(a))
            }
            Node::Powf(a, b) => {
                // (a^b)' = a^b · (b'·ln a + b·a'/a)
                let ln_a = g.call(Func::Ln, a);
                let t1 = g.mul(d(b), ln_a);
                let da_over_a = g.div(d(a), a);
                let t2 = g.mul(b, da_over_a);
                let s = g.add(t1, t2);
                g.mul(e, s)
            }
            Node::Call(f, a) => {
                let da = d(a);
                if g.is_zero(da) {
                    return g.zero();
                }
                let outer = match f {
                    Func::Sin => g.call(Func::Cos, a),
                    Func::Cos => {
                        let s = g.call(Func::Sin, a);
                        g.neg(s)
                    }
                    Func::Tan => {
                        // 1 + tan², reusing tan(a).
                        let t2 = g.powi(e, 2);
                        let one = g.one();
                        g.add(one, t2)
                    }
                    Func::Asin | Func::Acos => {
                        let one = g.one();
                        let a2 = g.powi(a, 2);
                        let m = g.sub(one, a2);
                        let s = g.call(Func::Sqrt, m);
                        let r = g.div(one, s);
                        if f == Func::Asin { r } else { g.neg(r) }
                    }
                    Func::Atan => {
                        let one = g.one();
                        let a2 = g.powi(a, 2);
                        let m = g.add(one, a2);
                        g.div(one, m)
                    }
                    Func::Exp => e,
                    Func::Ln => return g.div(da, a),
                    Func::Sqrt => {
                        // a' / (2 √a), reusing √a.
                        let q = g.div(da, e);
                        let half = g.constant(0.5);
                        return g.mul(half, q);
                    }
                    Func::Sinh => g.call(Func::Cosh, a),
                    Func::Cosh => g.call(Func::Sinh, a),
                    Func::Erf => {
                        // 2/√π · exp(−a²)
                        let a2 = g.powi(a, 2);
                        let m = g.neg(a2);
                        let e = g.call(Func::Exp, m);
                        let c = g.constant(std::f64::consts::FRAC_2_SQRT_PI);
                        g.mul(c, e)
                    }
                    Func::Tanh => {
                        let one = g.one();
                        let t2 = g.powi(e, 2);
                        g.sub(one, t2)
                    }
                };
                g.mul(outer, da)
            }
            Node::Select(cmp, x, y, a, b) => {
                // By branch: the derivative of the branch chosen.
                g.select(cmp, x, y, d(a), d(b))
            }
            Node::Atan2(y, x) => {
                // atan2(y, x)' = (x·y' − y·x') / (x² + y²)
                let xdy = g.mul(x, d(y));
                let ydx = g.mul(y, d(x));
                let num = g.sub(xdy, ydx);
                if g.is_zero(num) {
                    return g.zero();
                }
                let x2 = g.powi(x, 2);
                let y2 = g.powi(y, 2);
                let den = g.add(x2, y2);
                g.div(num, den)
            }
        }
    }
}
