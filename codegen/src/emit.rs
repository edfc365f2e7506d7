//! Emission: expression graphs to straight-line Rust, via quote and prettyplease.
//!
//! One generated function evaluates many outputs (all entries of `a`, `A` and `I`, say). The
//! emitter takes every node those outputs reach, in id order (children before parents), and
//! decides for each whether it becomes a `let` temporary or is written inline into its single
//! user. Because the graph is hash-consed, a node used by several outputs is one temporary: this
//! is common-subexpression elimination across everything the function emits. Before that, the
//! function's nodes are lowered into a fresh graph where integer powers become multiplications
//! (`x⁴ = (x·x)·(x·x)`, sharing `x·x` with any `x²` or `x³`). Where both `sin(x)` and `cos(x)` are
//! needed they come from one `x.sin_cos()`. Outputs that are structural zeros produce no code:
//! the output matrix is cleared once with `fill(0.0)` and only its non-zero entries are stored.
//!
//! Expressions are printed with the fewest parentheses that keep the graph's evaluation order,
//! so the generated code computes exactly what [`Graph::eval`] computes, bit for bit.

use std::collections::HashMap;

use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};

use crate::expr::{Cmp, ExprId, Func, Graph, Node};
use crate::scopes::{self, Statement};

/// A single-use expression heavier than this many operations gets its own `let`, so that no
/// line of generated code grows unreadable.
const MAX_INLINE_WEIGHT: u32 = 6;

/// Stores into one output: `target` followed by each entry's index, e.g. `r` and `[(0, 1)]`.
pub struct OutputGroup {
    /// The place being written, e.g. `r` or `dk[2].a`.
    pub target: TokenStream,
    /// Index suffix and value of each entry.
    pub entries: Vec<(TokenStream, ExprId)>,
}

/// A point inside a function where some inputs become available only after a statement: the
/// outputs before it are stored, then the statement runs (it may read them), then the
/// remaining inputs are loaded. Nodes that need none of the late inputs are computed before
/// the barrier and shared with everything after it.
pub struct Barrier {
    /// How many of the function's output groups are stored before the statement.
    pub groups_before: usize,
    /// The statement, e.g. `let (omega, qdot) = velocities(k)?;`.
    pub statement: TokenStream,
    /// Variables loaded only after the statement.
    pub late_vars: Vec<u32>,
}

/// One function to emit.
pub struct FunctionSpec {
    /// Its name, for statistics.
    pub name: &'static str,
    /// Doc comment.
    pub doc: String,
    /// `fn name(&self, ...) -> ...` without a body.
    pub signature: TokenStream,
    /// Variable number → the expression that loads it, e.g. `q[0]`.
    pub inputs: Vec<(u32, TokenStream)>,
    /// Outputs, stored in this order.
    pub groups: Vec<OutputGroup>,
    /// The returned scalar, if any.
    pub ret: Option<ExprId>,
    /// How to wrap the returned scalar (`Ok((omega, qdot, #ret))`), if not returned as is.
    pub ret_wrap: Option<fn(TokenStream) -> TokenStream>,
    /// A barrier splitting the body in two, if any.
    pub barrier: Option<Barrier>,
}

/// How numbers are written in an emitted function.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Flavor {
    /// Plain `f64` code (`2.0 * x`, `x.sin_cos()`, structural zeros by one `fill(0.0)`).
    F64,
    /// Code generic over `T: rovib_runtime::lanes::Real` (`T::splat(2.0) * x`; structural zeros
    /// stored entry by entry as `T::splat(0.0)`); the same operations in the same order as
    /// [`Flavor::F64`] (the transcendental functions are `T`'s: see `rovib_runtime::transcendental`).
    Lanes,
}

/// Operation counts of one emitted function.
#[derive(Clone, Debug, PartialEq)]
pub struct FunctionStats {
    /// Function name.
    pub name: &'static str,
    /// Output values (stored entries plus the returned scalar), zeros included.
    pub outputs: usize,
    /// Of those, structural zeros.
    pub zero_outputs: usize,
    /// Operations if every output were written as its own expression tree, with no sharing at
    /// all (a naive transcription of the formulas). A float because it can be astronomically
    /// large.
    pub ops_tree: f64,
    /// Operations if every output were computed separately, each with its own common
    /// subexpressions shared (CSE within an output, not across outputs).
    pub ops_per_output: u64,
    /// Operations in the emitted code, after CSE across all outputs.
    pub ops_emitted: u64,
    /// `let` temporaries in the emitted code.
    pub temporaries: usize,
}

/// The cost in operations of one node once lowered (integer powers cost multiplications).
fn op_cost(node: Node) -> u64 {
    match node {
        Node::Const(_) | Node::Var(_) => 0,
        Node::Powi(_, n) => {
            let m = n.unsigned_abs();
            // Square-and-multiply: ⌊log2 m⌋ squarings plus (popcount − 1) multiplications,
            // plus one division for a negative exponent.
            u64::from(31 - m.leading_zeros()) + u64::from(m.count_ones()) - 1 + u64::from(n < 0)
        }
        _ => 1,
    }
}

/// Lowers integer powers into multiplications: returns a fresh, unsimplified graph holding only
/// what `roots` reach, and the roots' ids in it. Evaluating the lowered graph in id order is
/// exactly what the emitted code does.
pub fn lower(graph: &Graph, roots: &[ExprId]) -> (Graph, Vec<ExprId>) {
    let mut lowering = Lowering::new(graph);
    let lowered = lowering.lower(graph, roots);
    (lowering.out, lowered)
}

/// The state of one lowering: the new graph and the map from old ids to new.
struct Lowering {
    out: Graph,
    map: HashMap<ExprId, ExprId>,
}

impl Lowering {
    fn new(src: &Graph) -> Self {
        let mut out = Graph::new_unsimplified();
        for v in 0..src.var_count() {
            out.var(src.var_name(v as u32));
        }
        Lowering { out, map: HashMap::new() }
    }

    fn lower(&mut self, src: &Graph, roots: &[ExprId]) -> Vec<ExprId> {
        let reachable = src.reachable(roots);
        for (i, &node) in src.nodes().iter().enumerate() {
            if !reachable[i] {
                continue;
            }
            let m = |c: ExprId| self.map[&c];
            let id = match node {
                Node::Const(_) | Node::Var(_) => self.out.push(node),
                Node::Neg(a) => self.out.neg(m(a)),
                Node::Add(a, b) => self.out.add(m(a), m(b)),
                Node::Sub(a, b) => self.out.sub(m(a), m(b)),
                Node::Mul(a, b) => self.out.mul(m(a), m(b)),
                Node::Div(a, b) => self.out.div(m(a), m(b)),
                Node::Powf(a, b) => self.out.pow(m(a), m(b)),
                Node::Call(f, a) => self.out.call(f, m(a)),
                Node::Atan2(a, b) => self.out.atan2(m(a), m(b)),
                Node::Select(cmp, x, y, a, b) => self.out.select(cmp, m(x), m(y), m(a), m(b)),
                Node::Powi(a, n) => {
                    let p = self.power(m(a), n.unsigned_abs());
                    if n < 0 {
                        let one = self.out.one();
                        self.out.div(one, p)
                    } else {
                        p
                    }
                }
            };
            self.map.insert(ExprId::from_index(i), id);
        }
        roots.iter().map(|r| self.map[r]).collect()
    }

    /// `x^n` for n ≥ 1 by square-and-multiply; `x·x` is hash-consed, so powers share squares.
    fn power(&mut self, x: ExprId, n: u32) -> ExprId {
        if n == 1 {
            return x;
        }
        let half = self.power(x, n / 2);
        let sq = self.out.mul(half, half);
        if n % 2 == 1 { self.out.mul(sq, x) } else { sq }
    }
}

/// A printed expression with its precedence: 4 atom, 3 unary minus, 2 `* /`, 1 `+ -`.
#[derive(Clone)]
struct Printed {
    tokens: TokenStream,
    prec: u8,
    weight: u32,
}

impl Printed {
    /// The tokens, parenthesised if this binds more loosely than `min`.
    fn at_least(&self, min: u8) -> TokenStream {
        let t = &self.tokens;
        if self.prec < min { quote!((#t)) } else { t.clone() }
    }
}

fn literal(value: f64, suffixed: bool, flavor: Flavor) -> Printed {
    if flavor == Flavor::Lanes {
        let lit: Literal = format!("{:?}", value.abs()).parse().expect("a finite f64 prints as a valid literal");
        let tokens = if value.is_sign_negative() { quote!(T::splat(-#lit)) } else { quote!(T::splat(#lit)) };
        return Printed { tokens, prec: 4, weight: 0 };
    }
    let text = format!("{:?}{}", value.abs(), if suffixed { "f64" } else { "" });
    let lit: Literal = text.parse().expect("a finite f64 prints as a valid literal");
    if value.is_sign_negative() {
        Printed { tokens: quote!(-#lit), prec: 3, weight: 0 }
    } else {
        Printed { tokens: quote!(#lit), prec: 4, weight: 0 }
    }
}

fn atom(ident: &Ident) -> Printed {
    Printed { tokens: quote!(#ident), prec: 4, weight: 0 }
}

/// The state of emitting one function: what is printed so far and the statements.
struct Emitter<'a> {
    lg: &'a Graph,
    spec: &'a FunctionSpec,
    var_idents: &'a [Ident],
    uses: Vec<u32>,
    /// `trig[x] = [sin(x), cos(x)]` where the function needs them.
    trig: HashMap<ExprId, [Option<ExprId>; 2]>,
    printed: Vec<Option<Printed>>,
    statements: Vec<Statement>,
    temporaries: usize,
    ops_emitted: u64,
    next_temp: usize,
    flavor: Flavor,
}

impl Emitter<'_> {
    fn fresh(&mut self) -> Ident {
        let t = format_ident!("t{}", self.next_temp);
        self.next_temp += 1;
        t
    }

    fn get(&self, c: ExprId) -> Printed {
        self.printed[c.index()].clone().expect("children are printed before parents")
    }

    /// Prints node `i` (inline or as a `let`), in id order.
    fn node(&mut self, i: usize) {
        if self.printed[i].is_some() {
            return;
        }
        let node = self.lg.nodes()[i];
        self.ops_emitted += op_cost(node);
        let expr = match node {
            Node::Const(bits) => {
                self.printed[i] = Some(literal(f64::from_bits(bits), false, self.flavor));
                return;
            }
            Node::Var(k) => {
                let ident = &self.var_idents[k as usize];
                let load = self
                    .spec
                    .inputs
                    .iter()
                    .find(|(v, _)| *v == k)
                    .map(|(_, t)| t.clone())
                    .expect("every variable a function reaches is one of its inputs");
                self.statements.push(Statement::binding(quote!(let #ident = #load;), vec![ident.clone()]));
                self.printed[i] = Some(atom(ident));
                return;
            }
            Node::Call(Func::Sin | Func::Cos, x) if self.trig[&x].iter().all(Option::is_some) => {
                // The pair is one call, counted once: the second node is skipped as printed.
                let [s, c] = self.trig[&x].map(|id| id.expect("both present"));
                let (ts, tc) = (self.fresh(), self.fresh());
                let recv = self.get(x).at_least(4);
                self.statements
                    .push(Statement::binding(quote!(let (#ts, #tc) = #recv.sin_cos();), vec![ts.clone(), tc.clone()]));
                self.temporaries += 2;
                self.printed[s.index()] = Some(atom(&ts));
                self.printed[c.index()] = Some(atom(&tc));
                return;
            }
            Node::Neg(a) => {
                let a = self.get(a);
                let t = a.at_least(4);
                Printed { tokens: quote!(-#t), prec: 3, weight: a.weight + 1 }
            }
            Node::Add(a, b) | Node::Sub(a, b) | Node::Mul(a, b) | Node::Div(a, b) => {
                let (a, b) = (self.get(a), self.get(b));
                let prec = if matches!(node, Node::Add(..) | Node::Sub(..)) { 1 } else { 2 };
                // Left-associative: the right operand must bind strictly tighter to keep the
                // graph's evaluation order.
                let (l, r) = (a.at_least(prec), b.at_least(prec + 1));
                let tokens = match node {
                    Node::Add(..) => quote!(#l + #r),
                    Node::Sub(..) => quote!(#l - #r),
                    Node::Mul(..) => quote!(#l * #r),
                    _ => quote!(#l / #r),
                };
                Printed { tokens, prec, weight: a.weight + b.weight + 1 }
            }
            Node::Powi(..) => unreachable!("integer powers were lowered to multiplications"),
            Node::Powf(a, b) => {
                let (a, b) = (receiver(self.lg, a, &self.printed, self.flavor), self.get(b));
                let (ra, tb) = (a.at_least(4), &b.tokens);
                Printed { tokens: quote!(#ra.powf(#tb)), prec: 4, weight: a.weight + b.weight + 1 }
            }
            Node::Call(Func::Erf, a) if self.flavor == Flavor::F64 => {
                let a = self.get(a);
                let t = &a.tokens;
                Printed { tokens: quote!(::rovib_runtime::special::erf(#t)), prec: 4, weight: a.weight + 1 }
            }
            Node::Call(f, a) => {
                let a = receiver(self.lg, a, &self.printed, self.flavor);
                let ra = a.at_least(4);
                let method = Ident::new(f.name(), Span::call_site());
                Printed { tokens: quote!(#ra.#method()), prec: 4, weight: a.weight + 1 }
            }
            Node::Atan2(y, x) => {
                let (y, x) = (receiver(self.lg, y, &self.printed, self.flavor), self.get(x));
                let (ry, tx) = (y.at_least(4), &x.tokens);
                Printed { tokens: quote!(#ry.atan2(#tx)), prec: 4, weight: y.weight + x.weight + 1 }
            }
            Node::Select(cmp, x, y, a, b) => {
                let [x, y, a, b] = [x, y, a, b].map(|c| self.get(c));
                let weight = x.weight + y.weight + a.weight + b.weight + 1;
                let [tx, ty, ta, tb] = [&x, &y, &a, &b].map(|p| p.tokens.clone());
                let tokens = match (self.flavor, cmp) {
                    (Flavor::F64, Cmp::Lt) => quote!(if #tx < #ty { #ta } else { #tb }),
                    (Flavor::F64, Cmp::Le) => quote!(if #tx <= #ty { #ta } else { #tb }),
                    (Flavor::Lanes, Cmp::Lt) => quote!(T::select_lt(#tx, #ty, #ta, #tb)),
                    (Flavor::Lanes, Cmp::Le) => quote!(T::select_le(#tx, #ty, #ta, #tb)),
                };
                // Always bound to a `let`: an `if` is not an operand everywhere.
                Printed { tokens, prec: 0, weight: weight.max(MAX_INLINE_WEIGHT + 1) }
            }
        };
        if self.uses[i] > 1 || expr.weight > MAX_INLINE_WEIGHT {
            let t = self.fresh();
            let tokens = &expr.tokens;
            self.statements.push(Statement::binding(quote!(let #t = #tokens;), vec![t.clone()]));
            self.temporaries += 1;
            self.printed[i] = Some(atom(&t));
        } else {
            self.printed[i] = Some(expr);
        }
    }

    /// Stores one output group: structural zeros by one `fill(0.0)`, the rest entry by entry.
    fn store(&mut self, group: &OutputGroup, values: &[ExprId]) {
        if group.entries.is_empty() {
            return;
        }
        let target = &group.target;
        if self.flavor == Flavor::Lanes {
            for ((index, _), v) in group.entries.iter().zip(values) {
                let value = match self.lg.is_zero(*v) {
                    true => quote!(T::splat(0.0)),
                    false => self.printed[v.index()].as_ref().expect("outputs are printed").tokens.clone(),
                };
                self.statements.push(Statement::store(quote!(#target #index = #value;)));
            }
            return;
        }
        if values.iter().any(|&v| self.lg.is_zero(v)) {
            self.statements.push(Statement::store(quote!(#target.fill(0.0);)));
        }
        for ((index, _), v) in group.entries.iter().zip(values) {
            if self.lg.is_zero(*v) {
                continue;
            }
            let value = &self.printed[v.index()].as_ref().expect("outputs are printed").tokens;
            self.statements.push(Statement::store(quote!(#target #index = #value;)));
        }
    }
}

/// Emits one function: its tokens and statistics.
pub fn emit_function(graph: &Graph, spec: &FunctionSpec, var_idents: &[Ident]) -> (TokenStream, FunctionStats) {
    emit_function_as(graph, spec, var_idents, Flavor::F64)
}

/// [`emit_function`] with numbers written as `flavor` says.
pub fn emit_function_as(
    graph: &Graph,
    spec: &FunctionSpec,
    var_idents: &[Ident],
    flavor: Flavor,
) -> (TokenStream, FunctionStats) {
    let mut roots: Vec<ExprId> = spec.groups.iter().flat_map(|g| g.entries.iter().map(|(_, e)| *e)).collect();
    roots.extend(spec.ret);
    let stats_before = count_before(graph, &roots);

    let (lowered, lowered_roots) = lower(graph, &roots);
    let lg = &lowered;
    let reachable = lg.reachable(&lowered_roots);

    // How often each node is used: by parents within this function and by stores or return.
    let mut uses = vec![0u32; lg.len()];
    for (i, node) in lg.nodes().iter().enumerate() {
        if reachable[i] {
            for c in node.children() {
                uses[c.index()] += 1;
            }
        }
    }
    for r in &lowered_roots {
        uses[r.index()] += 1;
    }

    // sin(x) and cos(x) of one x come from one sin_cos call.
    let mut trig: HashMap<ExprId, [Option<ExprId>; 2]> = HashMap::new();
    for (i, node) in lg.nodes().iter().enumerate() {
        if let (true, Node::Call(f @ (Func::Sin | Func::Cos), x)) = (reachable[i], *node) {
            trig.entry(x).or_default()[usize::from(f == Func::Cos)] = Some(ExprId::from_index(i));
        }
    }

    // Nodes that need a late input (directly or through a child) come after the barrier.
    let mut late = vec![false; lg.len()];
    if let Some(b) = &spec.barrier {
        for (i, node) in lg.nodes().iter().enumerate() {
            late[i] = match *node {
                Node::Var(k) => b.late_vars.contains(&k),
                _ => node.children().any(|c| late[c.index()]),
            };
        }
    }

    let mut e = Emitter {
        lg,
        spec,
        var_idents,
        uses,
        trig,
        printed: vec![None; lg.len()],
        statements: Vec::new(),
        temporaries: 0,
        ops_emitted: 0,
        next_temp: 0,
        flavor,
    };
    // Each group's values, in the lowered graph.
    let mut values: Vec<&[ExprId]> = Vec::new();
    let mut at = 0;
    for g in &spec.groups {
        values.push(&lowered_roots[at..at + g.entries.len()]);
        at += g.entries.len();
    }
    let groups_before = spec.barrier.as_ref().map_or(spec.groups.len(), |b| b.groups_before);
    for i in (0..lg.len()).filter(|&i| reachable[i] && !late[i]) {
        e.node(i);
    }
    for (g, v) in spec.groups.iter().zip(&values).take(groups_before) {
        e.store(g, v);
    }
    if let Some(b) = &spec.barrier {
        e.statements.push(Statement { tokens: b.statement.clone(), defines: Vec::new(), movable: false });
        for i in (0..lg.len()).filter(|&i| reachable[i] && late[i]) {
            e.node(i);
        }
        for (g, v) in spec.groups.iter().zip(&values).skip(groups_before) {
            e.store(g, v);
        }
    }
    let zero_outputs = values.iter().flat_map(|v| v.iter()).filter(|&&v| lg.is_zero(v)).count();
    let mut outputs = values.iter().map(|v| v.len()).sum::<usize>();
    if spec.ret.is_some() {
        outputs += 1;
        let r = lowered_roots[lowered_roots.len() - 1];
        let value = e.printed[r.index()].as_ref().expect("the return value is printed").tokens.clone();
        let tail = match spec.ret_wrap {
            Some(wrap) => wrap(value),
            None => value,
        };
        e.statements.push(Statement { tokens: tail, defines: Vec::new(), movable: false });
    }

    let doc = doc_lines(&spec.doc);
    let signature = &spec.signature;
    let statements = scopes::nest(std::mem::take(&mut e.statements));
    let tokens = quote! {
        #doc
        #signature {
            #(#statements)*
        }
    };
    let stats = FunctionStats {
        name: spec.name,
        outputs,
        zero_outputs,
        ops_tree: stats_before.0,
        ops_per_output: stats_before.1,
        ops_emitted: e.ops_emitted,
        temporaries: e.temporaries,
    };
    (tokens, stats)
}

/// A method-call receiver: a constant needs a type suffix (`2.0f64.sqrt()`).
fn receiver(g: &Graph, id: ExprId, printed: &[Option<Printed>], flavor: Flavor) -> Printed {
    match g.as_const(id) {
        Some(v) => literal(v, true, flavor),
        None => printed[id.index()].clone().expect("children are printed before parents"),
    }
}

/// Operation counts without sharing: (every output as a tree, every output as its own DAG).
fn count_before(graph: &Graph, roots: &[ExprId]) -> (f64, u64) {
    let reachable = graph.reachable(roots);
    let mut tree = vec![0f64; graph.len()];
    for (i, &node) in graph.nodes().iter().enumerate() {
        if reachable[i] {
            tree[i] = op_cost(node) as f64 + node.children().map(|c| tree[c.index()]).sum::<f64>();
        }
    }
    let ops_tree = roots.iter().map(|r| tree[r.index()]).sum();
    // Per-output DAG sizes, with a stamp array instead of a fresh visited set per output.
    let mut stamp = vec![usize::MAX; graph.len()];
    let mut per_output = 0u64;
    let mut stack = Vec::new();
    for (n, r) in roots.iter().enumerate() {
        stack.push(*r);
        while let Some(e) = stack.pop() {
            if stamp[e.index()] == n {
                continue;
            }
            stamp[e.index()] = n;
            let node = graph.node(e);
            per_output += op_cost(node);
            stack.extend(node.children());
        }
    }
    (ops_tree, per_output)
}

/// Formats a token stream of items as a Rust file with a header comment.
pub fn format_file(header: &str, items: TokenStream) -> Result<String, syn::Error> {
    let file: syn::File = syn::parse2(items)?;
    let body = prettyplease::unparse(&file);
    // prettyplease puts no blank line between items; one after each item's closing brace reads
    // better.
    let mut out = format!("{header}\n");
    let mut lines = body.lines().peekable();
    while let Some(line) = lines.next() {
        out.push_str(line);
        out.push('\n');
        let indent = line.len() - line.trim_start().len();
        let closes_item = ((line.trim_start() == "}" || line.ends_with("{}")) && indent <= 4)
            || (indent == 0 && line.starts_with("pub struct") && line.ends_with(';'));
        let ends_use = line.starts_with("use ") && lines.peek().is_some_and(|next| !next.starts_with("use "));
        if (closes_item || ends_use) && lines.peek().is_some_and(|next| !next.trim().starts_with('}')) {
            out.push('\n');
        }
    }
    Ok(out)
}

/// Doc attributes, one per line, so that they print as `///` comments.
pub fn doc_lines(text: &str) -> TokenStream {
    let lines = text.lines().map(|l| format!(" {l}").trim_end().to_owned());
    quote!(#(#[doc = #lines])*)
}

/// An unsuffixed integer literal, for indices and sizes.
pub fn index(i: usize) -> Literal {
    Literal::usize_unsuffixed(i)
}

/// The operations one function computing `roots` would emit (after lowering and CSE, every
/// node counted once; a `sin`/`cos` pair of one argument counts twice here, once when
/// emitted). For choosing between ways of building the same outputs before emitting any.
pub fn operations(graph: &Graph, roots: &[ExprId]) -> u64 {
    let (lowered, lowered_roots) = lower(graph, roots);
    let reachable = lowered.reachable(&lowered_roots);
    lowered.nodes().iter().zip(&reachable).filter(|(_, r)| **r).map(|(node, _)| op_cost(*node)).sum()
}
