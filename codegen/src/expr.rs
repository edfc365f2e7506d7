//! The expression graph: a hash-consed DAG of scalar expressions with simplifying constructors.
//!
//! Every expression the generator handles (positions, kinetic matrices, their derivatives, the
//! potential) lives in one [`Graph`] per molecule. Nodes are stored in a `Vec` and named by an
//! [`ExprId`]; a memo table maps each node to its id, so building the same node twice returns the
//! same id (structural sharing, "hash-consing"). Common subexpressions are therefore shared by
//! construction, and the emitter only has to decide which shared nodes get a `let`.
//!
//! # Invariant: children before parents
//!
//! A node's operands always have smaller ids than the node itself, because a node can only be
//! built from ids that already exist. So the id order is a topological order, and evaluating or
//! emitting nodes in increasing id order never meets an operand that is not yet computed. For
//! example, building `sin(x) * x` gives
//!
//! ```text
//! e0 = Var(x)
//! e1 = sin(e0)
//! e2 = e0 * e1      (operands e0, e1 < e2)
//! ```
//!
//! [`Graph::push`] checks the invariant with `debug_assert!`.
//!
//! # Simplification
//!
//! The constructors ([`Graph::add`], [`Graph::mul`], ...) rewrite as they build. Every rewrite
//! keeps the value, up to rounding, at every point where the original expression evaluates to a
//! finite number; it never turns a finite result into NaN or infinity. The rewrites are:
//! constant folding (only when the folded value is finite), identities for 0 and 1 (`x + 0`,
//! `x * 1`, `x * 0 = 0` and `x − x = 0` for finite `x`, `0 / x = 0` and `x / x = 1` where the
//! quotient is finite), collection of like terms (`c·x + d·x = (c + d)·x`), collection of
//! integer powers (`x · x = x²`, `x² · x³ = x⁵`, positive exponents only so that `x / x` is never
//! hidden), common factors taken out of sums and differences (`c·x ± c·y = c·(x ± y)` for a
//! constant `c`, which then folds into an enclosing constant factor, and `p·x ± p·y = p·(x ± y)`
//! for any common factor `p`; these change the rounding by an ulp or so and could overflow only
//! where `x ± y` does), `sin²x + cos²x = 1`, signs pulled outward (`(−x)·y = −(x·y)`), and
//! canonical operand order for `+` and
//! `·`, which are commutative in IEEE arithmetic. Division by a constant becomes multiplication
//! only when the reciprocal is exact (a power of two). With simplification switched off
//! ([`Graph::new_unsimplified`]) the constructors only hash-cons; tests use that to check that
//! simplification preserves values.

use std::collections::HashMap;
use std::fmt;

/// The id of a node in a [`Graph`]; ids are dense, starting at 0, in creation order.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ExprId(u32);

impl ExprId {
    /// The index of this node in [`Graph::nodes`].
    pub fn index(self) -> usize {
        self.0 as usize
    }

    /// The id of node number `index` (which must exist in the graph it is used with).
    pub fn from_index(index: usize) -> ExprId {
        ExprId(u32::try_from(index).expect("expression graph overflow"))
    }
}

/// A function of one argument that definitions may call.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Func {
    /// Sine.
    Sin,
    /// Cosine.
    Cos,
    /// Tangent.
    Tan,
    /// Arcsine.
    Asin,
    /// Arccosine.
    Acos,
    /// Arctangent.
    Atan,
    /// Exponential.
    Exp,
    /// Natural logarithm.
    Ln,
    /// Square root.
    Sqrt,
    /// Hyperbolic sine.
    Sinh,
    /// Hyperbolic cosine.
    Cosh,
    /// Hyperbolic tangent.
    Tanh,
    /// The error function (`rovib_runtime::special::erf`, libm's; `f64` has no method).
    Erf,
}

impl Func {
    /// Every function, with the name definitions use for it (also the `f64` method name).
    pub const ALL: [(Func, &'static str); 13] = [
        (Func::Sin, "sin"),
        (Func::Cos, "cos"),
        (Func::Tan, "tan"),
        (Func::Asin, "asin"),
        (Func::Acos, "acos"),
        (Func::Atan, "atan"),
        (Func::Exp, "exp"),
        (Func::Ln, "ln"),
        (Func::Sqrt, "sqrt"),
        (Func::Sinh, "sinh"),
        (Func::Cosh, "cosh"),
        (Func::Tanh, "tanh"),
        (Func::Erf, "erf"),
    ];

    /// The function's name, which is also the name of the `f64` method that computes it.
    pub fn name(self) -> &'static str {
        Self::ALL.iter().find(|(f, _)| *f == self).map(|(_, n)| *n).unwrap_or("?")
    }

    /// Looks a function up by name.
    pub fn from_name(name: &str) -> Option<Func> {
        Self::ALL.iter().find(|(_, n)| *n == name).map(|(f, _)| *f)
    }

    /// Evaluates the function with the same `f64` method the generated code calls.
    pub fn apply(self, x: f64) -> f64 {
        match self {
            Func::Sin => x.sin(),
            Func::Cos => x.cos(),
            Func::Tan => x.tan(),
            Func::Asin => x.asin(),
            Func::Acos => x.acos(),
            Func::Atan => x.atan(),
            Func::Exp => x.exp(),
            Func::Ln => x.ln(),
            Func::Sqrt => x.sqrt(),
            Func::Sinh => x.sinh(),
            Func::Cosh => x.cosh(),
            Func::Tanh => x.tanh(),
            Func::Erf => libm::erf(x),
        }
    }
}

/// The comparison of a [`Node::Select`]; `>` and `>=` are these with the operands swapped.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Cmp {
    /// `x < y`.
    Lt,
    /// `x <= y`.
    Le,
}

impl Cmp {
    /// Whether `x cmp y` holds (false if either is NaN).
    pub fn holds(self, x: f64, y: f64) -> bool {
        match self {
            Cmp::Lt => x < y,
            Cmp::Le => x <= y,
        }
    }

    /// The operator as written.
    pub fn symbol(self) -> &'static str {
        match self {
            Cmp::Lt => "<",
            Cmp::Le => "<=",
        }
    }
}

/// One node of the graph. Constants are stored by their bit pattern so that nodes can be hashed.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum Node {
    /// A constant, as `f64::to_bits`.
    Const(u64),
    /// Input variable number `i` (see [`Graph::var_name`]).
    Var(u32),
    /// `−a`.
    Neg(ExprId),
    /// `a + b`.
    Add(ExprId, ExprId),
    /// `a − b`.
    Sub(ExprId, ExprId),
    /// `a · b`.
    Mul(ExprId, ExprId),
    /// `a / b`.
    Div(ExprId, ExprId),
    /// `a` to an integer power other than 0 and 1.
    Powi(ExprId, i32),
    /// `a` to a non-integer power `b`.
    Powf(ExprId, ExprId),
    /// A function of one argument.
    Call(Func, ExprId),
    /// `atan2(y, x)`, the angle of the point (x, y).
    Atan2(ExprId, ExprId),
    /// `if x cmp y { a } else { b }` (`Select(cmp, x, y, a, b)`): both branches are computed
    /// and one is chosen, so the lane form is branch-free; a NaN comparison chooses `b`.
    Select(Cmp, ExprId, ExprId, ExprId, ExprId),
}

impl Node {
    /// The operands of this node, in order.
    pub fn children(&self) -> impl Iterator<Item = ExprId> {
        let children = match *self {
            Node::Const(_) | Node::Var(_) => [None; 4],
            Node::Neg(a) | Node::Powi(a, _) | Node::Call(_, a) => [Some(a), None, None, None],
            Node::Add(a, b)
            | Node::Sub(a, b)
            | Node::Mul(a, b)
            | Node::Div(a, b)
            | Node::Powf(a, b)
            | Node::Atan2(a, b) => [Some(a), Some(b), None, None],
            Node::Select(_, x, y, a, b) => [Some(x), Some(y), Some(a), Some(b)],
        };
        children.into_iter().flatten()
    }
}

/// A hash-consed expression DAG (see the module docs).
#[derive(Clone, Debug)]
pub struct Graph {
    nodes: Vec<Node>,
    memo: HashMap<Node, ExprId>,
    var_names: Vec<String>,
    simplify: bool,
    zero: ExprId,
    one: ExprId,
}

impl Default for Graph {
    fn default() -> Self {
        Self::new()
    }
}

impl Graph {
    /// An empty graph whose constructors simplify.
    pub fn new() -> Self {
        Self::with_simplification(true)
    }

    /// An empty graph whose constructors only hash-cons, without rewriting; for tests that
    /// compare simplified and unsimplified expressions.
    pub fn new_unsimplified() -> Self {
        Self::with_simplification(false)
    }

    fn with_simplification(simplify: bool) -> Self {
        let mut g = Graph {
            nodes: Vec::new(),
            memo: HashMap::new(),
            var_names: Vec::new(),
            simplify,
            zero: ExprId(0),
            one: ExprId(0),
        };
        g.zero = g.push(Node::Const(0f64.to_bits()));
        g.one = g.push(Node::Const(1f64.to_bits()));
        g
    }

    /// The nodes in id order (children before parents).
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// The node with this id.
    pub fn node(&self, id: ExprId) -> Node {
        self.nodes[id.index()]
    }

    /// The number of nodes.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the graph has no nodes (never true: 0 and 1 are always present).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Adds a node without rewriting it, or returns the id of the identical node.
    pub fn push(&mut self, node: Node) -> ExprId {
        if let Some(&id) = self.memo.get(&node) {
            return id;
        }
        let id = ExprId(u32::try_from(self.nodes.len()).expect("expression graph overflow"));
        debug_assert!(node.children().all(|c| c < id), "children must come before parents: {node:?} at {id:?}");
        self.nodes.push(node);
        self.memo.insert(node, id);
        id
    }

    /// The variable named `name`, created on first use. Variables are numbered in order of
    /// creation.
    pub fn var(&mut self, name: &str) -> ExprId {
        let index = match self.var_names.iter().position(|n| n == name) {
            Some(i) => i,
            None => {
                self.var_names.push(name.to_owned());
                self.var_names.len() - 1
            }
        };
        self.push(Node::Var(index as u32))
    }

    /// The name of variable number `index`.
    pub fn var_name(&self, index: u32) -> &str {
        &self.var_names[index as usize]
    }

    /// The number of variables created so far.
    pub fn var_count(&self) -> usize {
        self.var_names.len()
    }

    /// The constant `value`.
    pub fn constant(&mut self, value: f64) -> ExprId {
        self.push(Node::Const(value.to_bits()))
    }

    /// The constant 0.
    pub fn zero(&self) -> ExprId {
        self.zero
    }

    /// The constant 1.
    pub fn one(&self) -> ExprId {
        self.one
    }

    /// The value of a constant node, or `None`.
    pub fn as_const(&self, id: ExprId) -> Option<f64> {
        match self.node(id) {
            Node::Const(bits) => Some(f64::from_bits(bits)),
            _ => None,
        }
    }

    /// Whether the node is the constant zero (of either sign): a structural zero.
    pub fn is_zero(&self, id: ExprId) -> bool {
        self.as_const(id) == Some(0.0)
    }

    fn is_const_value(&self, id: ExprId, value: f64) -> bool {
        self.as_const(id) == Some(value)
    }

    /// Folds a constant result, but only if it is finite: a NaN or infinity is left for run time
    /// so that it shows up where it happens.
    fn fold(&mut self, value: f64) -> Option<ExprId> {
        value.is_finite().then(|| self.constant(value))
    }

    /// Splits `e` into a constant coefficient and the rest: `c·x → (c, x)`, `−x → (−1, x)`,
    /// `x → (1, x)`. Used to collect like terms.
    fn split_coefficient(&self, e: ExprId) -> (f64, ExprId) {
        match self.node(e) {
            Node::Neg(x) => (-1.0, x),
            Node::Mul(a, b) => match self.as_const(a) {
                Some(c) => (c, b),
                None => (1.0, e),
            },
            _ => (1.0, e),
        }
    }

    /// `p·x ± p·y = p·(x ± y)` for a common factor `p` that is not a constant (constants are
    /// [`Graph::split_coefficient`]'s), with `op` the sum or the difference; `None` if `a` and `b`
    /// are not two products with a common factor.
    fn factored(&mut self, a: ExprId, b: ExprId, op: fn(&mut Self, ExprId, ExprId) -> ExprId) -> Option<ExprId> {
        let (Node::Mul(a0, a1), Node::Mul(b0, b1)) = (self.node(a), self.node(b)) else { return None };
        let (p, x, y) = if a0 == b0 {
            (a0, a1, b1)
        } else if a0 == b1 {
            (a0, a1, b0)
        } else if a1 == b0 {
            (a1, a0, b1)
        } else if a1 == b1 {
            (a1, a0, b0)
        } else {
            return None;
        };
        // Constant coefficients are split_coefficient's business (with its finiteness checks).
        if self.as_const(p).is_some() || self.as_const(x).is_some() || self.as_const(y).is_some() {
            return None;
        }
        let s = op(self, x, y);
        Some(self.mul(p, s))
    }

    /// Whether `{a, b}` is `{sin²x, cos²x}` for one `x` (then `a + b = 1`, up to rounding).
    fn is_pythagorean(&self, a: ExprId, b: ExprId) -> bool {
        let square_of = |e: ExprId| match self.node(e) {
            Node::Powi(x, 2) => match self.node(x) {
                Node::Call(f @ (Func::Sin | Func::Cos), arg) => Some((f, arg)),
                _ => None,
            },
            _ => None,
        };
        match (square_of(a), square_of(b)) {
            (Some((fa, xa)), Some((fb, xb))) => xa == xb && fa != fb,
            _ => false,
        }
    }

    /// `c · x` with the constant rules applied.
    fn scaled(&mut self, c: f64, x: ExprId) -> ExprId {
        let c = self.constant(c);
        self.mul(c, x)
    }

    /// `a + b`.
    pub fn add(&mut self, a: ExprId, b: ExprId) -> ExprId {
        if !self.simplify {
            return self.push(Node::Add(a, b));
        }
        if let (Some(x), Some(y)) = (self.as_const(a), self.as_const(b))
            && let Some(id) = self.fold(x + y)
        {
            return id;
        }
        if self.is_zero(a) {
            return b;
        }
        if self.is_zero(b) {
            return a;
        }
        let (ca, xa) = self.split_coefficient(a);
        let (cb, xb) = self.split_coefficient(b);
        // Like terms are collected only where the summed coefficient is finite.
        if xa == xb && self.as_const(xa).is_none() && (ca + cb).is_finite() {
            return self.scaled(ca + cb, xa);
        }
        // A common constant factor: `c·x + c·y = c·(x + y)` (one product fewer; rounds
        // differently, by an ulp or so).
        if ca == cb && xa != a && xb != b {
            let s = self.add(xa, xb);
            return self.scaled(ca, s);
        }
        if let Some(id) = self.factored(a, b, Self::add) {
            return id;
        }
        if self.is_pythagorean(a, b) {
            return self.one;
        }
        // A negative term is subtracted: `a + (−c)·y = a − c·y`, exactly, since negation is.
        if cb < 0.0 && xb != b {
            let y = self.scaled(-cb, xb);
            return self.sub(a, y);
        }
        if ca < 0.0 && xa != a {
            let y = self.scaled(-ca, xa);
            return self.sub(b, y);
        }
        let (a, b) = self.canonical_order(a, b);
        self.push(Node::Add(a, b))
    }

    /// `a − b`.
    pub fn sub(&mut self, a: ExprId, b: ExprId) -> ExprId {
        if !self.simplify {
            return self.push(Node::Sub(a, b));
        }
        if let (Some(x), Some(y)) = (self.as_const(a), self.as_const(b))
            && let Some(id) = self.fold(x - y)
        {
            return id;
        }
        if self.is_zero(b) {
            return a;
        }
        if self.is_zero(a) {
            return self.neg(b);
        }
        if a == b {
            return self.zero;
        }
        let (ca, xa) = self.split_coefficient(a);
        let (cb, xb) = self.split_coefficient(b);
        if xa == xb && self.as_const(xa).is_none() && (ca - cb).is_finite() {
            return self.scaled(ca - cb, xa);
        }
        if ca == cb && xa != a && xb != b {
            let d = self.sub(xa, xb);
            return self.scaled(ca, d);
        }
        if let Some(id) = self.factored(a, b, Self::sub) {
            return id;
        }
        if cb < 0.0 && xb != b {
            let y = self.scaled(-cb, xb);
            return self.add(a, y);
        }
        self.push(Node::Sub(a, b))
    }

    /// `a · b`.
    pub fn mul(&mut self, a: ExprId, b: ExprId) -> ExprId {
        if !self.simplify {
            return self.push(Node::Mul(a, b));
        }
        // Constants go to the left so that `c · x` is the one shape of a scaled term.
        let (a, b) = if self.as_const(b).is_some() && self.as_const(a).is_none() { (b, a) } else { (a, b) };
        if let Some(x) = self.as_const(a) {
            if let Some(y) = self.as_const(b)
                && let Some(id) = self.fold(x * y)
            {
                return id;
            }
            if x == 0.0 {
                return self.zero;
            }
            if x == 1.0 {
                return b;
            }
            if x == -1.0 {
                return self.neg(b);
            }
            match self.node(b) {
                Node::Neg(y) => return self.scaled(-x, y),
                Node::Mul(c, y) => {
                    if let Some(cv) = self.as_const(c)
                        && let Some(folded) = self.fold(x * cv)
                    {
                        return self.mul(folded, y);
                    }
                }
                _ => {}
            }
            return self.push(Node::Mul(a, b));
        }
        // Pull signs and constant factors outward so that like terms meet.
        match (self.node(a), self.node(b)) {
            (Node::Neg(x), Node::Neg(y)) => return self.mul(x, y),
            (Node::Neg(x), _) => {
                let m = self.mul(x, b);
                return self.neg(m);
            }
            (_, Node::Neg(y)) => {
                let m = self.mul(a, y);
                return self.neg(m);
            }
            _ => {}
        }
        for (s, other) in [(a, b), (b, a)] {
            if let Node::Mul(c, y) = self.node(s)
                && let Some(cv) = self.as_const(c)
            {
                let m = self.mul(y, other);
                return self.scaled(cv, m);
            }
        }
        // Integer powers of one base, positive exponents only.
        let (ba, ea) = self.split_power(a);
        let (bb, eb) = self.split_power(b);
        if ba == bb && ea > 0 && eb > 0 {
            return self.powi(ba, ea + eb);
        }
        let (a, b) = self.canonical_order(a, b);
        self.push(Node::Mul(a, b))
    }

    fn split_power(&self, e: ExprId) -> (ExprId, i32) {
        match self.node(e) {
            Node::Powi(x, n) => (x, n),
            _ => (e, 1),
        }
    }

    fn canonical_order(&self, a: ExprId, b: ExprId) -> (ExprId, ExprId) {
        if a <= b { (a, b) } else { (b, a) }
    }

    /// `a / b`.
    pub fn div(&mut self, a: ExprId, b: ExprId) -> ExprId {
        if !self.simplify {
            return self.push(Node::Div(a, b));
        }
        if let (Some(x), Some(y)) = (self.as_const(a), self.as_const(b))
            && let Some(id) = self.fold(x / y)
        {
            return id;
        }
        if self.is_zero(a) && !self.is_zero(b) {
            return self.zero;
        }
        if self.is_const_value(b, 1.0) {
            return a;
        }
        if self.is_const_value(b, -1.0) {
            return self.neg(a);
        }
        if a == b && !self.is_zero(a) {
            return self.one;
        }
        if let Some(y) = self.as_const(b) {
            // Multiplying by the reciprocal is exact only for powers of two.
            let r = 1.0 / y;
            if r.is_normal() && r.to_bits() & ((1u64 << 52) - 1) == 0 {
                let r = self.constant(r);
                return self.mul(r, a);
            }
        }
        match (self.node(a), self.node(b)) {
            (Node::Neg(x), Node::Neg(y)) => return self.div(x, y),
            (Node::Neg(x), _) => {
                let d = self.div(x, b);
                return self.neg(d);
            }
            (_, Node::Neg(y)) => {
                let d = self.div(a, y);
                return self.neg(d);
            }
            _ => {}
        }
        if let Node::Mul(c, x) = self.node(a)
            && let Some(cv) = self.as_const(c)
        {
            let d = self.div(x, b);
            return self.scaled(cv, d);
        }
        self.push(Node::Div(a, b))
    }

    /// `−a`.
    pub fn neg(&mut self, a: ExprId) -> ExprId {
        if !self.simplify {
            return self.push(Node::Neg(a));
        }
        if let Some(x) = self.as_const(a) {
            return self.constant(-x);
        }
        match self.node(a) {
            Node::Neg(x) => x,
            Node::Sub(x, y) => self.sub(y, x),
            Node::Mul(c, x) if self.as_const(c).is_some() => {
                let cv = self.as_const(c).unwrap_or(1.0);
                self.scaled(-cv, x)
            }
            _ => self.push(Node::Neg(a)),
        }
    }

    /// `a` to the integer power `n`.
    pub fn powi(&mut self, a: ExprId, n: i32) -> ExprId {
        if !self.simplify {
            return self.push(Node::Powi(a, n));
        }
        if n == 0 {
            return self.one;
        }
        if n == 1 {
            return a;
        }
        if let Some(x) = self.as_const(a)
            && let Some(id) = self.fold(x.powi(n))
        {
            return id;
        }
        match self.node(a) {
            Node::Powi(x, m) if m > 0 && n > 0 => {
                if let Some(mn) = m.checked_mul(n) {
                    return self.powi(x, mn);
                }
            }
            Node::Neg(x) => {
                let p = self.powi(x, n);
                return if n % 2 == 0 { p } else { self.neg(p) };
            }
            // sqrt(x)² = x wherever sqrt(x) is finite.
            Node::Call(Func::Sqrt, x) if n == 2 => return x,
            _ => {}
        }
        self.push(Node::Powi(a, n))
    }

    /// `a` to the power `b`: integer constant exponents become [`Graph::powi`], ½ becomes a
    /// square root.
    pub fn pow(&mut self, a: ExprId, b: ExprId) -> ExprId {
        if self.simplify
            && let Some(e) = self.as_const(b)
        {
            if e.fract() == 0.0 && e.abs() <= 64.0 {
                return self.powi(a, e as i32);
            }
            if e == 0.5 {
                return self.call(Func::Sqrt, a);
            }
            if let Some(x) = self.as_const(a)
                && let Some(id) = self.fold(x.powf(e))
            {
                return id;
            }
        }
        self.push(Node::Powf(a, b))
    }

    /// `f(a)`.
    pub fn call(&mut self, f: Func, a: ExprId) -> ExprId {
        if !self.simplify {
            return self.push(Node::Call(f, a));
        }
        if let Some(x) = self.as_const(a)
            && let Some(id) = self.fold(f.apply(x))
        {
            return id;
        }
        if let Node::Neg(x) = self.node(a) {
            match f {
                // Odd functions.
                Func::Sin | Func::Tan | Func::Asin | Func::Atan | Func::Sinh | Func::Tanh | Func::Erf => {
                    let y = self.call(f, x);
                    return self.neg(y);
                }
                // Even functions.
                Func::Cos | Func::Cosh => return self.call(f, x),
                _ => {}
            }
        }
        self.push(Node::Call(f, a))
    }

    /// `atan2(y, x)`.
    pub fn atan2(&mut self, y: ExprId, x: ExprId) -> ExprId {
        if self.simplify
            && let (Some(yv), Some(xv)) = (self.as_const(y), self.as_const(x))
            && let Some(id) = self.fold(yv.atan2(xv))
        {
            return id;
        }
        self.push(Node::Atan2(y, x))
    }

    /// `if x cmp y { a } else { b }`: a constant comparison chooses its branch, equal branches
    /// are the branch.
    pub fn select(&mut self, cmp: Cmp, x: ExprId, y: ExprId, a: ExprId, b: ExprId) -> ExprId {
        if self.simplify {
            if a == b {
                return a;
            }
            if let (Some(xv), Some(yv)) = (self.as_const(x), self.as_const(y)) {
                return if cmp.holds(xv, yv) { a } else { b };
            }
        }
        self.push(Node::Select(cmp, x, y, a, b))
    }

    /// Evaluates the given roots at the point `vars` (indexed by variable number), computing
    /// each needed node once, in id order.
    pub fn eval(&self, roots: &[ExprId], vars: &[f64]) -> Vec<f64> {
        let needed = self.reachable(roots);
        let mut values = vec![f64::NAN; self.nodes.len()];
        for (i, node) in self.nodes.iter().enumerate() {
            if !needed[i] {
                continue;
            }
            let v = |id: ExprId| values[id.index()];
            values[i] = match *node {
                Node::Const(bits) => f64::from_bits(bits),
                Node::Var(k) => vars[k as usize],
                Node::Neg(a) => -v(a),
                Node::Add(a, b) => v(a) + v(b),
                Node::Sub(a, b) => v(a) - v(b),
                Node::Mul(a, b) => v(a) * v(b),
                Node::Div(a, b) => v(a) / v(b),
                Node::Powi(a, n) => v(a).powi(n),
                Node::Powf(a, b) => v(a).powf(v(b)),
                Node::Call(f, a) => f.apply(v(a)),
                Node::Atan2(y, x) => v(y).atan2(v(x)),
                Node::Select(cmp, x, y, a, b) => {
                    if cmp.holds(v(x), v(y)) {
                        v(a)
                    } else {
                        v(b)
                    }
                }
            };
        }
        roots.iter().map(|r| values[r.index()]).collect()
    }

    /// Marks every node that the roots depend on.
    pub fn reachable(&self, roots: &[ExprId]) -> Vec<bool> {
        let mut seen = vec![false; self.nodes.len()];
        for r in roots {
            seen[r.index()] = true;
        }
        // Parents have larger ids than children, so one backward sweep finds everything.
        for i in (0..self.nodes.len()).rev() {
            if seen[i] {
                for c in self.nodes[i].children() {
                    seen[c.index()] = true;
                }
            }
        }
        seen
    }

    /// Whether `e` depends on variable number `var`.
    pub fn depends_on(&self, e: ExprId, var: u32) -> bool {
        let seen = self.reachable(&[e]);
        self.nodes.iter().enumerate().any(|(i, n)| seen[i] && *n == Node::Var(var))
    }

    /// Formats an expression as text in the definition-file syntax (for messages and tests).
    pub fn display(&self, id: ExprId) -> DisplayExpr<'_> {
        DisplayExpr { graph: self, id }
    }
}

/// An expression formatted in the definition-file syntax; see [`Graph::display`].
pub struct DisplayExpr<'a> {
    graph: &'a Graph,
    id: ExprId,
}

impl fmt::Display for DisplayExpr<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let g = self.graph;
        let sub = |id| DisplayExpr { graph: g, id };
        match g.node(self.id) {
            Node::Const(bits) => write!(f, "{:?}", f64::from_bits(bits)),
            Node::Var(k) => write!(f, "{}", g.var_name(k)),
            Node::Neg(a) => write!(f, "(-{})", sub(a)),
            Node::Add(a, b) => write!(f, "({} + {})", sub(a), sub(b)),
            Node::Sub(a, b) => write!(f, "({} - {})", sub(a), sub(b)),
            Node::Mul(a, b) => write!(f, "({} * {})", sub(a), sub(b)),
            Node::Div(a, b) => write!(f, "({} / {})", sub(a), sub(b)),
            Node::Powi(a, n) => write!(f, "pow({}, {n})", sub(a)),
            Node::Powf(a, b) => write!(f, "pow({}, {})", sub(a), sub(b)),
            Node::Call(func, a) => write!(f, "{}({})", func.name(), sub(a)),
            Node::Atan2(y, x) => write!(f, "atan2({}, {})", sub(y), sub(x)),
            Node::Select(cmp, x, y, a, b) => {
                write!(f, "if({} {} {}, {}, {})", sub(x), cmp.symbol(), sub(y), sub(a), sub(b))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_nodes_are_shared() {
        let mut g = Graph::new();
        let x = g.var("x");
        let y = g.var("y");
        let a = g.mul(x, y);
        let b = g.mul(y, x);
        assert_eq!(a, b, "multiplication is commutative, so x·y and y·x are one node");
        let s1 = g.call(Func::Sin, a);
        let s2 = g.call(Func::Sin, b);
        assert_eq!(s1, s2);
    }

    #[test]
    fn children_come_before_parents() {
        let mut g = Graph::new();
        let x = g.var("x");
        let s = g.call(Func::Sin, x);
        let e = g.mul(s, x);
        for (i, n) in g.nodes().iter().enumerate() {
            assert!(n.children().all(|c| c.index() < i));
        }
        assert!(e > s && s > x);
    }

    #[test]
    fn identities_for_zero_and_one() {
        let mut g = Graph::new();
        let x = g.var("x");
        let zero = g.zero();
        let one = g.one();
        assert_eq!(g.add(x, zero), x);
        assert_eq!(g.mul(x, one), x);
        assert_eq!(g.mul(zero, x), zero);
        assert_eq!(g.sub(x, x), zero);
        assert_eq!(g.div(x, x), one);
        assert_eq!(g.div(zero, x), zero);
        assert_eq!(g.powi(x, 1), x);
        assert_eq!(g.powi(x, 0), one);
    }

    #[test]
    fn like_terms_and_powers_are_collected() {
        let mut g = Graph::new();
        let x = g.var("x");
        let two = g.constant(2.0);
        let three = g.constant(3.0);
        let x2 = g.mul(two, x);
        let x3 = g.mul(three, x);
        let sum = g.add(x2, x3);
        assert_eq!(g.display(sum).to_string(), "(5.0 * x)");
        let xx = g.mul(x, x);
        assert_eq!(g.node(xx), Node::Powi(x, 2));
        let x3 = g.powi(x, 3);
        let x5 = g.mul(xx, x3);
        assert_eq!(g.node(x5), Node::Powi(x, 5));
        let mx = g.neg(x);
        assert_eq!(g.add(x, mx), g.zero());
    }

    #[test]
    fn folding_never_produces_non_finite_constants() {
        let mut g = Graph::new();
        let zero = g.zero();
        let one = g.one();
        let inf = g.div(one, zero);
        assert!(g.as_const(inf).is_none(), "1/0 stays a division for run time");
        let minus_one = g.constant(-1.0);
        let nan = g.call(Func::Sqrt, minus_one);
        assert!(g.as_const(nan).is_none());
    }

    #[test]
    fn like_terms_are_not_collected_into_an_infinite_coefficient() {
        let mut g = Graph::new();
        let x = g.var("x");
        let big = g.constant(1e308);
        let t = g.mul(big, x);
        let sum = g.add(t, t);
        let minus_t = g.neg(t);
        let diff = g.sub(t, minus_t);
        for e in [sum, diff] {
            assert!(g.nodes().iter().all(|n| !matches!(n, Node::Const(b) if !f64::from_bits(*b).is_finite())));
            assert_eq!(g.eval(&[e], &[0.5]), vec![1e308]);
        }
    }

    #[test]
    fn division_by_a_power_of_two_becomes_an_exact_multiplication() {
        let mut g = Graph::new();
        let x = g.var("x");
        let two = g.constant(2.0);
        let three = g.constant(3.0);
        let half = g.div(x, two);
        assert_eq!(g.display(half).to_string(), "(0.5 * x)");
        let third = g.div(x, three);
        assert_eq!(g.node(third), Node::Div(x, three), "1/3 is not exact, keep the division");
    }
}
