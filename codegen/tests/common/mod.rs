//! An interpreter for emitted functions, shared by the codegen tests: it parses the printed code
//! back with syn and evaluates it, so a check covers what is actually printed (precedence,
//! parentheses, temporaries, `sin_cos`), not just the expression graph.

use std::collections::HashMap;

use quote::quote;
use rovib_codegen::expr::Func;

/// Interprets an emitted function body: `let` statements, stores `out[i] = ...` (any target
/// with a literal index; `fill` clears), blocks (the scope grouping of long functions, see
/// `rovib_codegen::scopes`: `let (a, b,) = { ...; (a, b,) };` and `{ ... }`, each with its own
/// scope), and a trailing expression, which is returned. `q[i]` reads input `i`.
pub fn interpret(body: &syn::Block, q: &[f64], n_out: usize) -> (Vec<f64>, Option<f64>) {
    let mut out = vec![f64::NAN; n_out];
    let ret = run(body, &mut HashMap::new(), q, &mut out).map(Value::num);
    (out, ret)
}

/// Runs a block in its own scope: the names it binds are gone from `env` when it ends (the
/// generated code never shadows a name). Returns its tail expression's value.
fn run(body: &syn::Block, env: &mut HashMap<String, Value>, q: &[f64], out: &mut [f64]) -> Option<Value> {
    let mut ret = None;
    let mut bound = Vec::new();
    for stmt in &body.stmts {
        match stmt {
            syn::Stmt::Local(local) => {
                let value = eval(&local.init.as_ref().expect("let has a value").expr, env, q, out);
                match (&local.pat, value) {
                    (syn::Pat::Ident(id), v) => {
                        bound.push(id.ident.to_string());
                        env.insert(id.ident.to_string(), v);
                    }
                    (syn::Pat::Tuple(t), v) => {
                        let values = match v {
                            Value::Pair(s, c) => vec![s, c],
                            Value::Tuple(values) => values,
                            Value::Num(_) => panic!("a number bound to a tuple pattern"),
                        };
                        assert_eq!(t.elems.len(), values.len(), "tuple pattern and value differ in length");
                        for (p, v) in t.elems.iter().zip(values) {
                            let syn::Pat::Ident(id) = p else { panic!("unexpected pattern") };
                            bound.push(id.ident.to_string());
                            env.insert(id.ident.to_string(), Value::Num(v));
                        }
                    }
                    _ => panic!("unexpected let"),
                }
            }
            syn::Stmt::Expr(syn::Expr::Assign(a), _) => {
                let syn::Expr::Index(ix) = &*a.left else { panic!("stores index into out") };
                let i = literal_index(&ix.index);
                out[i] = eval(&a.right, env, q, out).num();
            }
            syn::Stmt::Expr(syn::Expr::MethodCall(m), _) if m.method == "fill" => {
                out.iter_mut().for_each(|v| *v = 0.0);
            }
            // A block statement (a group without values to hand on), or a block as the tail.
            syn::Stmt::Expr(syn::Expr::Block(b), _) => ret = run(&b.block, env, q, out),
            syn::Stmt::Expr(e, None) => ret = Some(eval(e, env, q, out)),
            other => panic!("unexpected statement {}", quote!(#other)),
        }
    }
    for name in bound {
        env.remove(&name);
    }
    ret
}

#[derive(Clone, Debug)]
pub enum Value {
    Num(f64),
    Pair(f64, f64),
    Tuple(Vec<f64>),
}

impl Value {
    fn num(self) -> f64 {
        match self {
            Value::Num(x) => x,
            _ => panic!("a pair or tuple where a number was expected"),
        }
    }
}

fn literal_index(e: &syn::Expr) -> usize {
    match e {
        syn::Expr::Lit(syn::ExprLit { lit: syn::Lit::Int(i), .. }) => i.base10_parse().expect("index"),
        _ => panic!("non-literal index"),
    }
}

fn eval(e: &syn::Expr, env: &mut HashMap<String, Value>, q: &[f64], out: &mut [f64]) -> Value {
    if let syn::Expr::Block(b) = e {
        return run(&b.block, env, q, out).expect("a block with a value");
    }
    if let syn::Expr::Tuple(t) = e {
        return Value::Tuple(t.elems.iter().map(|x| eval(x, env, q, out).num()).collect());
    }
    if let syn::Expr::If(i) = e {
        // `if x < y { a } else { b }`: a piecewise node.
        let syn::Expr::Binary(c) = &*i.cond else { panic!("the condition is a comparison") };
        let (x, y) = (eval(&c.left, env, q, out).num(), eval(&c.right, env, q, out).num());
        let holds = match c.op {
            syn::BinOp::Lt(_) => x < y,
            syn::BinOp::Le(_) => x <= y,
            _ => panic!("unexpected comparison"),
        };
        let (_, other) = i.else_branch.as_ref().expect("an else branch");
        return match holds {
            true => run(&i.then_branch, env, q, out).expect("a value"),
            false => eval(other, env, q, out),
        };
    }
    let mut num = |e: &syn::Expr| eval(e, env, q, out).num();
    Value::Num(match e {
        syn::Expr::Lit(l) => match &l.lit {
            syn::Lit::Float(f) => f.base10_parse().expect("float"),
            syn::Lit::Int(i) => i.base10_parse::<u64>().expect("int") as f64,
            _ => panic!("unexpected literal"),
        },
        syn::Expr::Path(p) => return env[&p.path.get_ident().expect("plain name").to_string()].clone(),
        syn::Expr::Paren(p) => num(&p.expr),
        syn::Expr::Unary(u) => -num(&u.expr),
        syn::Expr::Index(ix) => q[literal_index(&ix.index)],
        syn::Expr::Binary(b) => {
            let (l, r) = (num(&b.left), num(&b.right));
            match b.op {
                syn::BinOp::Add(_) => l + r,
                syn::BinOp::Sub(_) => l - r,
                syn::BinOp::Mul(_) => l * r,
                syn::BinOp::Div(_) => l / r,
                _ => panic!("unexpected operator"),
            }
        }
        syn::Expr::MethodCall(m) => {
            let x = num(&m.receiver);
            let arg = m.args.first().map(&mut num);
            let name = m.method.to_string();
            match name.as_str() {
                "sin_cos" => return Value::Pair(x.sin(), x.cos()),
                "powf" => x.powf(arg.expect("an argument")),
                "atan2" => x.atan2(arg.expect("an argument")),
                _ => Func::from_name(&name).expect("a known function").apply(x),
            }
        }
        // `::rovib_runtime::special::erf(x)`, the one path call.
        syn::Expr::Call(c) if quote!(#c).to_string().contains("special :: erf") => {
            Func::Erf.apply(num(c.args.first().expect("an argument")))
        }
        other => panic!("unexpected expression {}", quote!(#other)),
    })
}

/// The body of the generated method `name` in a generated molecule's source.
#[allow(dead_code)] // used by the test crates that read generated molecules, not by every one
pub fn method(source: &str, name: &str) -> syn::Block {
    let file = syn::parse_file(source).expect("generated source parses");
    file.items
        .iter()
        .find_map(|item| match item {
            syn::Item::Impl(i) => i.items.iter().find_map(|it| match it {
                syn::ImplItem::Fn(f) if f.sig.ident == name => Some(f.block.clone()),
                _ => None,
            }),
            _ => None,
        })
        .unwrap_or_else(|| panic!("no method `{name}`"))
}
