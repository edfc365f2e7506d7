//! An interpreter for emitted functions, shared by the codegen tests: it parses the printed code
//! back with syn and evaluates it, so a check covers what is actually printed (precedence,
//! parentheses, temporaries, `sin_cos`), not just the expression graph.

use std::collections::HashMap;

use quote::quote;
use rovib_codegen::expr::Func;

/// Interprets an emitted function body: `let` statements, stores `out[i] = ...` (any target
/// with a literal index; `fill` clears), and a trailing expression, which is returned. `q[i]`
/// reads input `i`.
pub fn interpret(body: &syn::Block, q: &[f64], n_out: usize) -> (Vec<f64>, Option<f64>) {
    let mut env: HashMap<String, Value> = HashMap::new();
    let mut out = vec![f64::NAN; n_out];
    let mut ret = None;
    for stmt in &body.stmts {
        match stmt {
            syn::Stmt::Local(local) => {
                let value = eval(&local.init.as_ref().expect("let has a value").expr, &env, q);
                match (&local.pat, value) {
                    (syn::Pat::Ident(id), v) => {
                        env.insert(id.ident.to_string(), v);
                    }
                    (syn::Pat::Tuple(t), Value::Pair(s, c)) => {
                        let names: Vec<String> = t
                            .elems
                            .iter()
                            .map(|p| match p {
                                syn::Pat::Ident(id) => id.ident.to_string(),
                                _ => panic!("unexpected pattern"),
                            })
                            .collect();
                        env.insert(names[0].clone(), Value::Num(s));
                        env.insert(names[1].clone(), Value::Num(c));
                    }
                    _ => panic!("unexpected let"),
                }
            }
            syn::Stmt::Expr(syn::Expr::Assign(a), _) => {
                let syn::Expr::Index(ix) = &*a.left else { panic!("stores index into out") };
                let i = literal_index(&ix.index);
                out[i] = eval(&a.right, &env, q).num();
            }
            syn::Stmt::Expr(syn::Expr::MethodCall(m), _) if m.method == "fill" => {
                out.iter_mut().for_each(|v| *v = 0.0);
            }
            syn::Stmt::Expr(e, None) => ret = Some(eval(e, &env, q).num()),
            other => panic!("unexpected statement {}", quote!(#other)),
        }
    }
    (out, ret)
}

#[derive(Clone, Copy, Debug)]
pub enum Value {
    Num(f64),
    Pair(f64, f64),
}

impl Value {
    fn num(self) -> f64 {
        match self {
            Value::Num(x) => x,
            Value::Pair(..) => panic!("a pair where a number was expected"),
        }
    }
}

fn literal_index(e: &syn::Expr) -> usize {
    match e {
        syn::Expr::Lit(syn::ExprLit { lit: syn::Lit::Int(i), .. }) => i.base10_parse().expect("index"),
        _ => panic!("non-literal index"),
    }
}

fn eval(e: &syn::Expr, env: &HashMap<String, Value>, q: &[f64]) -> Value {
    let num = |e: &syn::Expr| eval(e, env, q).num();
    Value::Num(match e {
        syn::Expr::Lit(l) => match &l.lit {
            syn::Lit::Float(f) => f.base10_parse().expect("float"),
            syn::Lit::Int(i) => i.base10_parse::<u64>().expect("int") as f64,
            _ => panic!("unexpected literal"),
        },
        syn::Expr::Path(p) => return env[&p.path.get_ident().expect("plain name").to_string()],
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
            let name = m.method.to_string();
            match name.as_str() {
                "sin_cos" => return Value::Pair(x.sin(), x.cos()),
                "powf" => x.powf(num(&m.args[0])),
                "atan2" => x.atan2(num(&m.args[0])),
                _ => Func::from_name(&name).expect("a known function").apply(x),
            }
        }
        other => panic!("unexpected expression {}", quote!(#other)),
    })
}
