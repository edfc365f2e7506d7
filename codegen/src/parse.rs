//! Expressions as written in definition files, parsed with syn into the expression graph.
//!
//! The syntax is a small subset of Rust's expression syntax, so syn parses it and Rust's
//! precedence rules apply: numbers, names, `+ - * /`, unary minus, parentheses, and calls of
//! `sin cos tan asin acos atan exp ln sqrt sinh cosh tanh` (one argument), `atan2(y, x)` and
//! `pow(base, exponent)` (two arguments), and the constant `pi`. Powers are written
//! `pow(x, 2)`: `^` is exclusive-or in Rust and binds more loosely than `+`, so `x^2 + 1` would
//! mean `x^(2 + 1)`; it is rejected with a message that says what to write instead.

use std::collections::HashMap;

use proc_macro2::Span;
use syn::spanned::Spanned;
use syn::{BinOp, Expr, Lit, UnOp};

use crate::expr::{ExprId, Func, Graph};

/// A problem in one expression, located within the expression's text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExprError {
    /// 1-based line within the expression text.
    pub line: usize,
    /// 0-based column (in characters) within that line.
    pub column: usize,
    /// What is wrong.
    pub message: String,
    /// What to change.
    pub help: String,
}

impl ExprError {
    fn at(span: Span, message: impl Into<String>, help: impl Into<String>) -> Self {
        let start = span.start();
        ExprError { line: start.line.max(1), column: start.column, message: message.into(), help: help.into() }
    }
}

/// The names an expression may use: each maps to an expression already in the graph (a
/// coordinate in its declared unit, a constant, a parameter).
pub struct Scope<'a> {
    /// Name → expression.
    pub names: &'a HashMap<String, ExprId>,
    /// Where the expression appears, for messages ("the position of atom H1").
    pub context: &'a str,
}

/// Names of the two-argument functions.
pub const BINARY_FUNCTIONS: [&str; 2] = ["atan2", "pow"];

/// Parses `text` and builds it into `graph`.
pub fn parse_expression(graph: &mut Graph, text: &str, scope: &Scope<'_>) -> Result<ExprId, ExprError> {
    if text.trim().is_empty() {
        return Err(ExprError {
            line: 1,
            column: 0,
            message: format!("empty expression in {}", scope.context),
            help: "write an expression, for example `0` or `r1 * cos(alpha / 2)`".into(),
        });
    }
    let expr: Expr = syn::parse_str(text).map_err(|e| {
        let help = if text.contains("**") {
            "write powers as `pow(x, 2)`; `**` is not an operator here".to_owned()
        } else {
            "expressions use numbers, names, + - * /, parentheses and calls such as sin(x) or pow(x, 2)".to_owned()
        };
        ExprError::at(e.span(), format!("syntax error in {}: {e}", scope.context), help)
    })?;
    Builder { graph, scope }.build(&expr)
}

struct Builder<'g, 's> {
    graph: &'g mut Graph,
    scope: &'s Scope<'s>,
}

impl Builder<'_, '_> {
    fn build(&mut self, expr: &Expr) -> Result<ExprId, ExprError> {
        match expr {
            Expr::Lit(lit) => self.literal(&lit.lit),
            Expr::Paren(p) => self.build(&p.expr),
            Expr::Group(g) => self.build(&g.expr),
            Expr::Path(path) => {
                let Some(ident) = path.path.get_ident() else {
                    return Err(ExprError::at(
                        path.span(),
                        format!("`{}` is not a plain name", quote::quote!(#path)),
                        "names are single identifiers such as `r1` or `alpha`",
                    ));
                };
                self.name(&ident.to_string(), ident.span())
            }
            Expr::Unary(u) => match u.op {
                UnOp::Neg(_) => {
                    let a = self.build(&u.expr)?;
                    Ok(self.graph.neg(a))
                }
                _ => {
                    let op = &u.op;
                    Err(ExprError::at(
                        u.op.span(),
                        format!("unsupported unary operator `{}` in {}", quote::quote!(#op), self.scope.context),
                        "only unary minus is supported; powers are `pow(x, y)`",
                    ))
                }
            },
            Expr::Binary(b) => {
                let op = match b.op {
                    BinOp::Add(_) => Graph::add,
                    BinOp::Sub(_) => Graph::sub,
                    BinOp::Mul(_) => Graph::mul,
                    BinOp::Div(_) => Graph::div,
                    BinOp::BitXor(_) => {
                        return Err(ExprError::at(
                            b.op.span(),
                            format!("`^` is not a power in {}", self.scope.context),
                            "write powers as `pow(base, exponent)`, e.g. `pow(r1 - re, 2)`",
                        ));
                    }
                    _ => {
                        let op = &b.op;
                        return Err(ExprError::at(
                            b.op.span(),
                            format!("unsupported operator `{}` in {}", quote::quote!(#op), self.scope.context),
                            "the operators are + - * / and unary minus; powers are `pow(x, y)`",
                        ));
                    }
                };
                let l = self.build(&b.left)?;
                let r = self.build(&b.right)?;
                Ok(op(self.graph, l, r))
            }
            Expr::Call(call) => {
                let name = match &*call.func {
                    Expr::Path(p) => p.path.get_ident().map(|i| i.to_string()),
                    _ => None,
                };
                let Some(name) = name else {
                    return Err(ExprError::at(
                        call.func.span(),
                        format!("only named functions can be called in {}", self.scope.context),
                        function_help(),
                    ));
                };
                let args: Vec<&Expr> = call.args.iter().collect();
                let expected = if BINARY_FUNCTIONS.contains(&name.as_str()) {
                    2
                } else if Func::from_name(&name).is_some() {
                    1
                } else {
                    let help = match name.as_str() {
                        "log" => "the natural logarithm is `ln`".to_owned(),
                        "powi" | "powf" | "sqr" => "write powers as `pow(base, exponent)`".to_owned(),
                        _ => function_help(),
                    };
                    return Err(ExprError::at(
                        call.func.span(),
                        format!("unknown function `{name}` in {}", self.scope.context),
                        help,
                    ));
                };
                if args.len() != expected {
                    return Err(ExprError::at(
                        call.func.span(),
                        format!(
                            "`{name}` takes {expected} argument{} but {} {} given in {}",
                            if expected == 1 { "" } else { "s" },
                            args.len(),
                            if args.len() == 1 { "was" } else { "were" },
                            self.scope.context
                        ),
                        match name.as_str() {
                            "pow" => "write `pow(base, exponent)`".to_owned(),
                            "atan2" => "write `atan2(y, x)`".to_owned(),
                            _ => format!("write `{name}(x)`"),
                        },
                    ));
                }
                let a = self.build(args[0])?;
                match name.as_str() {
                    "pow" => {
                        let b = self.build(args[1])?;
                        Ok(self.graph.pow(a, b))
                    }
                    "atan2" => {
                        let b = self.build(args[1])?;
                        Ok(self.graph.atan2(a, b))
                    }
                    _ => Ok(self.graph.call(Func::from_name(&name).expect("checked above"), a)),
                }
            }
            Expr::MethodCall(m) => Err(ExprError::at(
                m.method.span(),
                format!("method calls like `.{}()` are not supported in {}", m.method, self.scope.context),
                format!("write `{}(x)` instead of `x.{}()`", m.method, m.method),
            )),
            other => Err(ExprError::at(
                other.span(),
                format!("unsupported expression `{}` in {}", quote::quote!(#other), self.scope.context),
                "expressions use numbers, names, + - * /, parentheses and calls such as sin(x) or pow(x, 2)",
            )),
        }
    }

    fn literal(&mut self, lit: &Lit) -> Result<ExprId, ExprError> {
        let (value, suffix) = match lit {
            Lit::Int(i) => (i.base10_digits().parse::<f64>().ok(), i.suffix()),
            Lit::Float(f) => (f.base10_digits().parse::<f64>().ok(), f.suffix()),
            _ => {
                return Err(ExprError::at(
                    lit.span(),
                    format!("`{}` is not a number in {}", quote::quote!(#lit), self.scope.context),
                    "write numbers like 1, 0.5 or 1.2e-3",
                ));
            }
        };
        if !suffix.is_empty() {
            return Err(ExprError::at(
                lit.span(),
                format!("number with a type suffix `{suffix}` in {}", self.scope.context),
                "write plain numbers like 1.5, without a suffix",
            ));
        }
        match value {
            Some(v) if v.is_finite() => Ok(self.graph.constant(v)),
            _ => Err(ExprError::at(
                lit.span(),
                format!("number out of range in {}", self.scope.context),
                "write a finite number",
            )),
        }
    }

    fn name(&mut self, name: &str, span: Span) -> Result<ExprId, ExprError> {
        if let Some(&id) = self.scope.names.get(name) {
            return Ok(id);
        }
        if name == "pi" {
            return Ok(self.graph.constant(std::f64::consts::PI));
        }
        let mut known: Vec<&str> = self.scope.names.keys().map(String::as_str).collect();
        known.push("pi");
        known.sort_unstable();
        let suggestion = closest(name, &known).map(|s| format!("did you mean `{s}`? ")).unwrap_or_default();
        let help = if Func::from_name(name).is_some() || BINARY_FUNCTIONS.contains(&name) {
            format!("`{name}` is a function: call it, e.g. `{name}(x)`")
        } else {
            format!("{suggestion}the names available here are: {}", known.join(", "))
        };
        Err(ExprError::at(span, format!("unknown name `{name}` in {}", self.scope.context), help))
    }
}

fn function_help() -> String {
    let mut names: Vec<&str> = Func::ALL.iter().map(|(_, n)| *n).collect();
    names.extend(BINARY_FUNCTIONS);
    format!("the functions are {}", names.join(", "))
}

/// The known name closest to `name` by edit distance, if it is close enough to be a typo.
pub fn closest<'a>(name: &str, known: &[&'a str]) -> Option<&'a str> {
    known.iter().map(|k| (edit_distance(name, k), *k)).filter(|(d, k)| *d <= 2.max(k.len() / 3)).min().map(|(_, k)| k)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            cur[j + 1] = (prev[j] + usize::from(ca != *cb)).min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<(Graph, ExprId), ExprError> {
        let mut g = Graph::new();
        let x = g.var("x");
        let names = HashMap::from([("x".to_owned(), x)]);
        let scope = Scope { names: &names, context: "the test" };
        let id = parse_expression(&mut g, text, &scope)?;
        Ok((g, id))
    }

    fn value(text: &str, x: f64) -> f64 {
        let (g, id) = parse(text).unwrap();
        g.eval(&[id], &[x])[0]
    }

    #[test]
    fn precedence_follows_rust() {
        assert_eq!(value("1 + 2 * x", 3.0), 7.0);
        assert_eq!(value("-x * 2 - 1", 3.0), -7.0);
        assert_eq!(value("x / 2 / 4", 8.0), 1.0);
        assert_eq!(value("-pow(x, 2)", 3.0), -9.0);
        assert_eq!(value("2 * pow(x, 2)", 3.0), 18.0);
        assert!((value("atan2(1, x)", 1.0) - std::f64::consts::FRAC_PI_4).abs() < 1e-15);
        assert!((value("cos(pi * x)", 1.0) + 1.0).abs() < 1e-15);
    }

    #[test]
    fn caret_is_rejected_with_the_spelling_to_use() {
        let e = parse("x^2").unwrap_err();
        assert!(e.message.contains("`^` is not a power"), "{e:?}");
        assert!(e.help.contains("pow(base, exponent)"));
        assert_eq!((e.line, e.column), (1, 1));
    }

    #[test]
    fn unknown_names_suggest_the_closest() {
        let e = parse("2 * y + xx").unwrap_err();
        assert_eq!(e.message, "unknown name `y` in the test");
        assert_eq!(e.column, 4);
        let e = parse("sinn(x)").unwrap_err();
        assert_eq!(e.message, "unknown function `sinn` in the test");
        let e = parse("pow(x)").unwrap_err();
        assert_eq!(e.message, "`pow` takes 2 arguments but 1 was given in the test");
        let e = parse("sin(x, x)").unwrap_err();
        assert_eq!(e.message, "`sin` takes 1 argument but 2 were given in the test");
    }

    #[test]
    fn syntax_errors_are_located() {
        let e = parse("x + / 2").unwrap_err();
        assert!(e.message.starts_with("syntax error in the test"), "{e:?}");
        assert_eq!((e.line, e.column), (1, 4));
        let e = parse("x * *2").unwrap_err();
        assert_eq!(e.message, "unsupported unary operator `*` in the test");
        let e = parse("x.sin()").unwrap_err();
        assert!(e.help.contains("write `sin(x)`"));
    }
}
