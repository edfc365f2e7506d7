//! Property tests of the expression engine: derivatives against finite differences,
//! simplification and lowering against unsimplified evaluation, and emitted code against the
//! graph, on random expressions and random points.
//!
//! The emitted code is checked by parsing it back with syn and interpreting it, so the check
//! covers what is actually printed (precedence, parentheses, temporaries, `sin_cos`).

mod common;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use quote::quote;
use rovib_codegen::diff::Differentiator;
use rovib_codegen::emit::{self, FunctionSpec, OutputGroup};
use rovib_codegen::expr::{ExprId, Func, Graph};

/// A random expression in two variables, built identically into any graph.
#[derive(Clone, Debug)]
enum Ast {
    Var(u32),
    Const(f64),
    Neg(Box<Ast>),
    Bin(char, Box<Ast>, Box<Ast>),
    Powi(Box<Ast>, i32),
    Powf(Box<Ast>, f64),
    Call(Func, Box<Ast>),
    Atan2(Box<Ast>, Box<Ast>),
}

fn ast() -> impl Strategy<Value = Ast> {
    let leaf = prop_oneof![
        (0u32..2).prop_map(Ast::Var),
        prop::sample::select(vec![0.0, 1.0, -1.0, 0.5, 2.0, 3.0, -1.5, 0.1]).prop_map(Ast::Const),
    ];
    leaf.prop_recursive(5, 40, 2, |inner| {
        let funcs = prop::sample::select(Func::ALL.iter().map(|(f, _)| *f).collect::<Vec<_>>());
        let ops = prop::sample::select(vec!['+', '-', '*', '/']);
        prop_oneof![
            inner.clone().prop_map(|a| Ast::Neg(Box::new(a))),
            (ops, inner.clone(), inner.clone()).prop_map(|(op, a, b)| Ast::Bin(op, Box::new(a), Box::new(b))),
            (inner.clone(), -3i32..5).prop_map(|(a, n)| Ast::Powi(Box::new(a), n)),
            (inner.clone(), prop::sample::select(vec![0.5, 1.5, -0.5, 2.5]))
                .prop_map(|(a, e)| Ast::Powf(Box::new(a), e)),
            (funcs, inner.clone()).prop_map(|(f, a)| Ast::Call(f, Box::new(a))),
            (inner.clone(), inner).prop_map(|(a, b)| Ast::Atan2(Box::new(a), Box::new(b))),
        ]
    })
}

/// Builds the expression. Arguments outside a function's domain are mapped into it first
/// (`ln(1 + a²)`, `asin(tanh a)`, ...) so that most random points give finite values.
fn build(g: &mut Graph, a: &Ast) -> ExprId {
    match a {
        Ast::Var(k) => g.var(["x", "y"][*k as usize]),
        Ast::Const(c) => g.constant(*c),
        Ast::Neg(a) => {
            let a = build(g, a);
            g.neg(a)
        }
        Ast::Bin(op, a, b) => {
            let (x, y) = (build(g, a), build(g, b));
            match op {
                '+' => g.add(x, y),
                '-' => g.sub(x, y),
                '*' => g.mul(x, y),
                _ => g.div(x, y),
            }
        }
        Ast::Powi(a, n) => {
            let x = build(g, a);
            g.powi(x, *n)
        }
        Ast::Powf(a, e) => {
            let x = positive(g, a);
            let e = g.constant(*e);
            g.pow(x, e)
        }
        Ast::Call(f, a) => {
            let x = match f {
                Func::Ln | Func::Sqrt => positive(g, a),
                Func::Asin | Func::Acos => {
                    let x = build(g, a);
                    let t = g.call(Func::Tanh, x);
                    let s = g.constant(0.9);
                    g.mul(s, t)
                }
                Func::Exp | Func::Sinh | Func::Cosh => {
                    let x = build(g, a);
                    g.call(Func::Sin, x)
                }
                _ => build(g, a),
            };
            g.call(*f, x)
        }
        Ast::Atan2(a, b) => {
            let (y, x) = (build(g, a), build(g, b));
            g.atan2(y, x)
        }
    }
}

/// `1 + a²`, positive everywhere.
fn positive(g: &mut Graph, a: &Ast) -> ExprId {
    let x = build(g, a);
    let x2 = g.powi(x, 2);
    let one = g.one();
    g.add(one, x2)
}

fn point() -> impl Strategy<Value = [f64; 2]> {
    [0.2f64..2.0, -2.0f64..-0.2]
}

fn config() -> Config {
    Config { cases: 400, rng_seed: RngSeed::Fixed(20_261_122), failure_persistence: None, ..Config::default() }
}

/// Values that can be compared meaningfully: finite and not so large that rounding in a
/// cancellation dominates.
fn tame(v: f64) -> bool {
    v.is_finite() && v.abs() < 1e5
}

/// Whether every intermediate value of `e` at `p` is finite: the engine promises nothing for
/// expressions that pass through infinity (such as `atan2(x, pow(0, -1))`).
fn finite_throughout(g: &Graph, e: ExprId, p: &[f64]) -> bool {
    let reachable = g.reachable(&[e]);
    let ids: Vec<ExprId> = (0..g.len()).filter(|&i| reachable[i]).map(ExprId::from_index).collect();
    g.eval(&ids, p).iter().all(|v| v.is_finite())
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + a.abs().max(b.abs()))
}

proptest! {
    #![proptest_config(config())]

    /// ∂e/∂x and ∂e/∂y agree with a fourth-order central difference.
    #[test]
    fn derivatives_match_finite_differences(a in ast(), p in point()) {
        let mut g = Graph::new();
        g.var("x");
        g.var("y");
        let e = build(&mut g, &a);
        prop_assume!(finite_throughout(&g, e, &p));
        let mut diff = Differentiator::new();
        for var in 0..2u32 {
            let d = diff.derivative(&mut g, e, var);
            let h = 1e-3;
            let f = |t: f64| {
                let mut x = p;
                x[var as usize] += t;
                g.eval(&[e], &x)[0]
            };
            let samples = [f(-2.0 * h), f(-h), f(h), f(2.0 * h), f(0.0)];
            prop_assume!(samples.iter().all(|v| tame(*v)));
            let fd = (samples[0] - 8.0 * samples[1] + 8.0 * samples[2] - samples[3]) / (12.0 * h);
            // Where a 4th-order difference changes a lot between h and h/2, the function is too
            // rough here for finite differences to judge.
            let h2 = h / 2.0;
            let fd2 = (f(-2.0 * h2) - 8.0 * f(-h2) + 8.0 * f(h2) - f(2.0 * h2)) / (12.0 * h2);
            prop_assume!(close(fd, fd2, 1e-6));
            let exact = g.eval(&[d], &p)[0];
            prop_assert!(close(exact, fd, 1e-6), "d/d{} of {}: symbolic {exact}, fd {fd}", ["x","y"][var as usize], g.display(e));
        }
    }

    /// The simplifying constructors give the value of the expression built without rewriting.
    #[test]
    fn simplification_preserves_values(a in ast(), p in point()) {
        let mut raw = Graph::new_unsimplified();
        raw.var("x");
        raw.var("y");
        let r = build(&mut raw, &a);
        let expected = raw.eval(&[r], &p)[0];
        prop_assume!(tame(expected) && finite_throughout(&raw, r, &p));
        let mut g = Graph::new();
        g.var("x");
        g.var("y");
        let s = build(&mut g, &a);
        let got = g.eval(&[s], &p)[0];
        prop_assert!(close(got, expected, 1e-9), "{}: simplified {got}, raw {expected}", raw.display(r));
    }

    /// Lowering (integer powers to products) and emission (temporaries, inlining, sin_cos,
    /// precedence) preserve values: the printed code, interpreted, equals the lowered graph
    /// bit for bit and the original graph to rounding.
    #[test]
    fn emitted_code_computes_the_graph(exprs in prop::collection::vec(ast(), 1..4), p in point()) {
        let mut g = Graph::new();
        g.var("x");
        g.var("y");
        let roots: Vec<ExprId> = exprs.iter().map(|a| build(&mut g, a)).collect();
        let expected = g.eval(&roots, &p);
        prop_assume!(expected.iter().all(|v| tame(*v)));
        let (lowered, lroots) = emit::lower(&g, &roots);
        let lowered_values = lowered.eval(&lroots, &p);

        let entries = roots.iter().enumerate().map(|(i, &r)| (quote!([#i]), r)).collect();
        let spec = FunctionSpec {
            name: "f",
            doc: "test".into(),
            signature: quote!(fn f(q: &[f64], out: &mut [f64])),
            inputs: vec![(0, quote!(q[0])), (1, quote!(q[1]))],
            groups: vec![OutputGroup { target: quote!(out), entries }],
            ret: None,
            ret_wrap: None,
            barrier: None,
        };
        let idents = vec![quote::format_ident!("x"), quote::format_ident!("y")];
        let (tokens, stats) = emit::emit_function(&g, &spec, &idents);
        let f: syn::ItemFn = syn::parse2(tokens).expect("emitted code parses");
        let (out, _) = common::interpret(&f.block, &p, roots.len());
        for i in 0..roots.len() {
            // Equal as numbers: a pruned structural zero is stored as +0.0 even where the graph
            // would give −0.0.
            prop_assert!(out[i] == lowered_values[i],
                "emitted {} vs lowered {} for {}", out[i], lowered_values[i], g.display(roots[i]));
            prop_assert!(close(out[i], expected[i], 1e-12));
        }
        prop_assert!(stats.ops_emitted as f64 <= stats.ops_tree.max(stats.ops_per_output as f64) + 0.5);
    }
}
