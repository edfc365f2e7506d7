//! Expressions as written in definition files, parsed with syn into the expression graph.
//!
//! The syntax is a small subset of Rust's expression syntax, so syn parses it and Rust's
//! precedence rules apply: numbers, names, `+ - * /`, unary minus, parentheses, and calls of
//! `sin cos tan asin acos atan exp ln sqrt sinh cosh tanh erf` (one argument), `atan2(y, x)` and
//! `pow(base, exponent)` (two arguments), and the constant `pi`. Powers are written
//! `pow(x, 2)`: `^` is exclusive-or in Rust and binds more loosely than `+`, so `x^2 + 1` would
//! mean `x^(2 + 1)`; it is rejected with a message that says what to write instead.

use std::collections::HashMap;

use proc_macro2::Span;
use syn::spanned::Spanned;
use syn::{BinOp, Expr, Lit, UnOp};

use crate::expr::{Cmp, ExprId, Func, Graph};
use crate::special::{MAX_LEGENDRE_DEGREE, legendre};

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
/// coordinate in its declared unit, a constant, a parameter), plus the definition's named
/// expressions and functions.
pub struct Scope<'a> {
    /// Name → expression.
    pub names: &'a HashMap<String, ExprId>,
    /// Where the expression appears, for messages ("the position of atom H1").
    pub context: &'a str,
    /// The functions (always callable) and named expressions (usable where `named` is true).
    pub library: &'a Library,
    /// Whether the library's named expressions are visible (not inside function bodies).
    pub named: bool,
}

/// The named expressions and functions of a definition, inlined where they are used: a named
/// expression is built with the names of the place that uses it (so a named expression that uses
/// a potential parameter can be used in the potential but not in a position), a function with
/// its parameters bound to the arguments' expressions and the constants. Hash-consing shares what
/// repeated uses have in common, and derivatives of the inlined graph are exact.
#[derive(Clone, Debug, Default)]
pub struct Library {
    /// The constants' values: the names a function body sees besides its parameters.
    pub constants: HashMap<String, f64>,
    /// Function name → definition.
    pub functions: HashMap<String, Function>,
    /// Named expression name → definition.
    pub expressions: HashMap<String, Named>,
    /// Coefficient array name → values (`c[k]` in expressions).
    pub arrays: HashMap<String, Vec<f64>>,
}

/// A function defined once in the definition (`"lj(r, eps, sigma)" = "..."`).
#[derive(Clone, Debug)]
pub struct Function {
    /// The parameter names, in order.
    pub params: Vec<String>,
    /// The body's text.
    pub body: String,
    /// Whether the body has a problem (already reported): a call then builds a placeholder.
    pub broken: bool,
}

/// A named sub-expression (`r_OAr = "sqrt(...)"`).
#[derive(Clone, Debug)]
pub struct Named {
    /// The expression's text.
    pub body: String,
    /// Whether the body has a problem (already reported): a use then builds a placeholder.
    pub broken: bool,
}

/// What a named expression or function with a problem stands for, so that the rest of the
/// definition can still be checked (never emitted: a definition with a problem generates nothing).
const BROKEN_PLACEHOLDER: f64 = 1.0;

/// How deeply named expressions and function calls may nest inside each other's bodies (each
/// level is a nested parse, so this bounds the build script's stack).
pub const MAX_INLINE_DEPTH: usize = 64;

/// What one top-level parse has inlined so far: a named expression or a call with the same
/// arguments builds the same expression, so it is built once (which keeps a chain of functions
/// that each call the previous one twice linear, not exponential).
#[derive(Default)]
struct Inlined {
    /// (name, argument expressions) → result; named expressions have no arguments.
    cache: HashMap<(String, Vec<ExprId>), ExprId>,
    /// Current nesting of bodies being built.
    depth: usize,
}

/// Names of the two-argument functions.
pub const BINARY_FUNCTIONS: [&str; 2] = ["atan2", "pow"];

/// Parses `text` and builds it into `graph`.
pub fn parse_expression(graph: &mut Graph, text: &str, scope: &Scope<'_>) -> Result<ExprId, ExprError> {
    parse_inlining(graph, text, scope, &mut Inlined::default())
}

fn parse_inlining(
    graph: &mut Graph,
    text: &str,
    scope: &Scope<'_>,
    inlined: &mut Inlined,
) -> Result<ExprId, ExprError> {
    if text.trim().is_empty() {
        return Err(ExprError {
            line: 1,
            column: 0,
            message: format!("empty expression in {}", scope.context),
            help: "write an expression, for example `0` or `r1 * cos(alpha / 2)`".into(),
        });
    }
    check_shape(text, scope)?;
    let text = &spell_if(text);
    let expr: Expr = syn::parse_str(text).map_err(|e| {
        let help = if text.contains("**") {
            "write powers as `pow(x, 2)`; `**` is not an operator here".to_owned()
        } else {
            "expressions use numbers, names, + - * /, parentheses and calls such as sin(x) or pow(x, 2)".to_owned()
        };
        ExprError::at(e.span(), format!("syntax error in {}: {e}", scope.context), help)
    })?;
    let mut builder = Builder { graph, scope, inlined, tasks: vec![Task::Visit(expr)], values: Vec::new() };
    let result = builder.run();
    // Whatever an error left unvisited is taken apart without recursion.
    dismantle(builder.tasks.drain(..).filter_map(|t| match t {
        Task::Visit(e) => Some(e),
        _ => None,
    }));
    result
}

/// The deepest nesting an expression may have: open parentheses plus pending prefix operators
/// (`-(-(x))` is 4 deep). syn parses nesting recursively, so this bound keeps the build script's
/// stack safe; no formula needs more, while a flat sum may have any number of terms.
pub const MAX_NESTING: usize = 128;

/// Rejects, before syn sees it, what could make syn or the builder recurse deeply or what no
/// expression contains: characters outside the expression alphabet, Rust keywords, and nesting
/// deeper than [`MAX_NESTING`]. Sums, products and calls in a row are not nesting.
fn check_shape(text: &str, scope: &Scope<'_>) -> Result<(), ExprError> {
    let (mut line, mut column) = (1usize, 0usize);
    // Pending prefix operators of each open parenthesis level, innermost last.
    let mut levels: Vec<usize> = vec![0];
    let mut depth = 0usize;
    // Whether the previous token ends an operand (so `-` or `*` after it is binary).
    let mut after_operand = false;
    let mut chars = text.chars().peekable();
    let err = |line, column, message: String, help: &str| ExprError { line, column, message, help: help.to_owned() };
    while let Some(c) = chars.next() {
        let (l, col) = (line, column);
        column += 1;
        match c {
            '\n' => {
                line += 1;
                column = 0;
            }
            c if c.is_whitespace() => {}
            c if c.is_ascii_alphanumeric() || c == '_' => {
                let mut word = String::from(c);
                while let Some(&n) = chars.peek().filter(|n| n.is_ascii_alphanumeric() || **n == '_' || **n == '.') {
                    // A `.` continues a number (`1.5`, `2.e3`) but ends a name (`x.sin`).
                    if n == '.' && !word.starts_with(|d: char| d.is_ascii_digit()) {
                        break;
                    }
                    // `1e-3`: the sign belongs to the exponent.
                    word.push(n);
                    chars.next();
                    column += 1;
                    if word.starts_with(|d: char| d.is_ascii_digit())
                        && (n == 'e' || n == 'E')
                        && let Some(&sign @ ('+' | '-')) = chars.peek()
                    {
                        word.push(sign);
                        chars.next();
                        column += 1;
                    }
                }
                // `if` is the piecewise function (see `spell_if`).
                if word != "if"
                    && syn::parse_str::<syn::Ident>(&word).is_err()
                    && !word.starts_with(|d: char| d.is_ascii_digit())
                {
                    return Err(err(
                        l,
                        col,
                        format!("`{word}` is not a name (it is a Rust keyword) in {}", scope.context),
                        "expressions use numbers, names, + - * /, parentheses and calls such as sin(x) or pow(x, 2)",
                    ));
                }
                after_operand = true;
            }
            '(' | '[' => {
                levels.push(0);
                depth += 1;
                after_operand = false;
            }
            ')' | ']' => {
                if levels.len() > 1 {
                    depth -= 1 + levels.pop().unwrap_or(0);
                }
                after_operand = true;
            }
            '-' | '*' if !after_operand => {
                *levels.last_mut().expect("the outermost level is never popped") += 1;
                depth += 1;
            }
            '<' | '>' => {
                // `<=` and `>=` are one operator.
                if chars.peek() == Some(&'=') {
                    chars.next();
                    column += 1;
                }
                let pending = levels.last_mut().expect("the outermost level is never popped");
                depth -= *pending;
                *pending = 0;
                after_operand = false;
            }
            '+' | '-' | '*' | '/' | '^' | ',' => {
                // A binary operator or a comma ends the operand of every pending prefix operator.
                let pending = levels.last_mut().expect("the outermost level is never popped");
                depth -= *pending;
                *pending = 0;
                after_operand = false;
            }
            '.' => after_operand = false,
            other => {
                return Err(err(
                    l,
                    col,
                    format!("unexpected character `{other}` in {}", scope.context),
                    "expressions use numbers, names, + - * /, parentheses and calls such as sin(x) or pow(x, 2)",
                ));
            }
        }
        if depth > MAX_NESTING {
            return Err(err(
                l,
                col,
                format!("expression nested more than {MAX_NESTING} deep in {}", scope.context),
                "flatten it: parentheses and unary minus signs may nest at most 128 deep (sums of any length are fine)",
            ));
        }
    }
    Ok(())
}

/// The spelling of `if` handed to syn: `if` is a Rust keyword, so `if(c, a, b)` would not parse
/// as a call. `ıf` (dotless i) has as many characters, so places in messages do not move, and
/// cannot be a name in a definition (names are ASCII).
const IF_SPELLING: &str = "\u{131}f";

/// `text` with every word `if` spelt [`IF_SPELLING`].
fn spell_if(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut word = String::new();
    for c in text.chars().chain(std::iter::once(' ')) {
        if c.is_ascii_alphanumeric() || c == '_' || (c == '.' && word.starts_with(|d: char| d.is_ascii_digit())) {
            word.push(c);
            continue;
        }
        out.push_str(if word == "if" { IF_SPELLING } else { &word });
        word.clear();
        out.push(c);
    }
    out.pop();
    out
}

/// Takes syn expressions apart with an explicit stack. Dropping a deep syn tree recurses once per
/// level (a 10⁴-term sum is 10⁴ levels deep); this moves every child out first so each node is
/// dropped alone. [`check_shape`] limits the trees to the variants handled here.
/// The error of a call of `name` with `args` where `expected` arguments are taken, in
/// `context`, with `help` saying how to write it (the arguments are dismantled first).
fn wrong_arity(name: &str, expected: usize, args: Vec<Expr>, span: Span, context: &str, help: String) -> ExprError {
    let given = args.len();
    dismantle(args);
    ExprError::at(
        span,
        format!(
            "`{name}` takes {expected} argument{} but {given} {} given in {context}",
            if expected == 1 { "" } else { "s" },
            if given == 1 { "was" } else { "were" },
        ),
        help,
    )
}

fn dismantle(exprs: impl IntoIterator<Item = Expr>) {
    let mut stack: Vec<Expr> = exprs.into_iter().collect();
    while let Some(e) = stack.pop() {
        match e {
            Expr::Binary(b) => stack.extend([*b.left, *b.right]),
            Expr::Unary(u) => stack.push(*u.expr),
            Expr::Paren(p) => stack.push(*p.expr),
            Expr::Group(g) => stack.push(*g.expr),
            Expr::Call(c) => {
                stack.push(*c.func);
                stack.extend(c.args);
            }
            Expr::MethodCall(m) => {
                stack.push(*m.receiver);
                stack.extend(m.args);
            }
            Expr::Field(f) => stack.push(*f.base),
            Expr::Index(i) => stack.extend([*i.expr, *i.index]),
            Expr::Tuple(t) => stack.extend(t.elems),
            Expr::Range(r) => stack.extend(r.start.into_iter().chain(r.end).map(|b| *b)),
            Expr::Cast(c) => stack.push(*c.expr),
            _ => {}
        }
    }
}

/// One step of the builder's post-order walk.
// Tasks live in one Vec for the whole walk; boxing the large variant would only add allocations.
#[allow(clippy::large_enum_variant)]
enum Task {
    /// Build this expression (push its value).
    Visit(Expr),
    /// Pop one value, push its negation.
    Neg,
    /// Pop two values (right on top), push the result.
    Binary(fn(&mut Graph, ExprId, ExprId) -> ExprId),
    /// Pop one value, push the function of it.
    Call(Func),
    /// Pop the arguments of the library function (the last on top), push its inlined body.
    Inline(String, Span),
    /// Pop x, y, a, b (b on top), push `if x cmp y { a } else { b }`.
    Select(Cmp),
    /// Pop x, push |x|.
    Abs,
    /// Pop a, b, push min(a, b) (`false`) or max(a, b) (`true`).
    MinMax(bool),
    /// Pop l (and m if `true`), then x; push the Legendre (associated Legendre) polynomial.
    Legendre(bool, Span),
    /// Pop the index, push the array's value there.
    Index(String, Span),
    /// Pop the bounds (last on top), push the sum of the body over the index range.
    Sum(String, Box<Expr>, Span),
}

/// Builds a syn expression into the graph, iteratively: a post-order walk with an explicit
/// stack, so a sum of any length needs no stack depth. Operands are built left before right, as
/// a recursive walk would, so node ids (and the generated code) do not depend on the walk.
struct Builder<'g, 's> {
    graph: &'g mut Graph,
    scope: &'s Scope<'s>,
    inlined: &'g mut Inlined,
    tasks: Vec<Task>,
    values: Vec<ExprId>,
}

impl Builder<'_, '_> {
    fn run(&mut self) -> Result<ExprId, ExprError> {
        while let Some(task) = self.tasks.pop() {
            match task {
                Task::Visit(e) => self.visit(e)?,
                Task::Neg => {
                    let a = self.pop();
                    let v = self.graph.neg(a);
                    self.values.push(v);
                }
                Task::Binary(op) => {
                    let r = self.pop();
                    let l = self.pop();
                    let v = op(self.graph, l, r);
                    self.values.push(v);
                }
                Task::Call(f) => {
                    let a = self.pop();
                    let v = self.graph.call(f, a);
                    self.values.push(v);
                }
                Task::Inline(name, span) => {
                    let v = self.inline_function(&name, span)?;
                    self.values.push(v);
                }
                Task::Select(cmp) => {
                    let b = self.pop();
                    let a = self.pop();
                    let y = self.pop();
                    let x = self.pop();
                    let v = self.graph.select(cmp, x, y, a, b);
                    self.values.push(v);
                }
                Task::Abs => {
                    let x = self.pop();
                    let (zero, minus_x) = (self.graph.zero(), self.graph.neg(x));
                    let v = self.graph.select(Cmp::Lt, x, zero, minus_x, x);
                    self.values.push(v);
                }
                Task::MinMax(max) => {
                    let b = self.pop();
                    let a = self.pop();
                    // min: a where a <= b; max: a where b <= a; else b (also for NaN).
                    let v = if max {
                        self.graph.select(Cmp::Le, b, a, a, b)
                    } else {
                        self.graph.select(Cmp::Le, a, b, a, b)
                    };
                    self.values.push(v);
                }
                Task::Legendre(associated, span) => {
                    let v = self.legendre(associated, span)?;
                    self.values.push(v);
                }
                Task::Index(name, span) => {
                    let i = self.pop();
                    let values = &self.scope.library.arrays[&name];
                    let v = match self.graph.as_const(i) {
                        Some(k) if k.fract() == 0.0 && k >= 0.0 && (k as usize) < values.len() => values[k as usize],
                        Some(k) if k.fract() == 0.0 => {
                            return Err(ExprError::at(
                                span,
                                format!(
                                    "index {k} is outside `{name}` ({} values) in {}",
                                    values.len(),
                                    self.scope.context
                                ),
                                format!("`{name}` has indices 0 to {}", values.len().saturating_sub(1)),
                            ));
                        }
                        _ => {
                            return Err(ExprError::at(
                                span,
                                format!("the index of `{name}` is not an integer constant in {}", self.scope.context),
                                "index arrays with integers: numbers, constants or a `sum` index, e.g. `c[k]`",
                            ));
                        }
                    };
                    let v = self.graph.constant(v);
                    self.values.push(v);
                }
                Task::Sum(index, body, span) => {
                    let v = self.sum(&index, *body, span)?;
                    self.values.push(v);
                }
            }
        }
        Ok(self.pop())
    }

    fn pop(&mut self) -> ExprId {
        self.values.pop().expect("every task pushes the values its parent pops")
    }

    /// Pushes `first`, then `second` (if any), to be built in that order, after which `then`
    /// combines them.
    fn schedule(&mut self, then: Task, first: Expr, second: Option<Expr>) {
        self.tasks.push(then);
        self.tasks.extend(second.map(Task::Visit));
        self.tasks.push(Task::Visit(first));
    }

    fn visit(&mut self, expr: Expr) -> Result<(), ExprError> {
        match expr {
            Expr::Lit(lit) => {
                let v = self.literal(&lit.lit)?;
                self.values.push(v);
            }
            Expr::Paren(p) => self.tasks.push(Task::Visit(*p.expr)),
            Expr::Group(g) => self.tasks.push(Task::Visit(*g.expr)),
            Expr::Path(path) => {
                let Some(ident) = path.path.get_ident() else {
                    return Err(ExprError::at(
                        path.span(),
                        format!("`{}` is not a plain name", quote::quote!(#path)),
                        "names are single identifiers such as `r1` or `alpha`",
                    ));
                };
                let v = self.name(&ident.to_string(), ident.span())?;
                self.values.push(v);
            }
            Expr::Unary(u) => match u.op {
                UnOp::Neg(_) => self.schedule(Task::Neg, *u.expr, None),
                op => {
                    dismantle([*u.expr]);
                    return Err(ExprError::at(
                        op.span(),
                        format!("unsupported unary operator `{}` in {}", quote::quote!(#op), self.scope.context),
                        "only unary minus is supported; powers are `pow(x, y)`",
                    ));
                }
            },
            Expr::Binary(b) => {
                let op = match b.op {
                    BinOp::Add(_) => Graph::add,
                    BinOp::Sub(_) => Graph::sub,
                    BinOp::Mul(_) => Graph::mul,
                    BinOp::Div(_) => Graph::div,
                    op => {
                        dismantle([*b.left, *b.right]);
                        return Err(if let BinOp::BitXor(_) = op {
                            ExprError::at(
                                op.span(),
                                format!("`^` is not a power in {}", self.scope.context),
                                "write powers as `pow(base, exponent)`, e.g. `pow(r1 - re, 2)`",
                            )
                        } else if let BinOp::Lt(_) | BinOp::Le(_) | BinOp::Gt(_) | BinOp::Ge(_) = op {
                            ExprError::at(
                                op.span(),
                                format!("a comparison `{}` outside `if` in {}", quote::quote!(#op), self.scope.context),
                                "comparisons are the first argument of `if(x < y, a, b)` (or `select`)",
                            )
                        } else {
                            ExprError::at(
                                op.span(),
                                format!("unsupported operator `{}` in {}", quote::quote!(#op), self.scope.context),
                                "the operators are + - * / and unary minus; powers are `pow(x, y)`",
                            )
                        });
                    }
                };
                self.schedule(Task::Binary(op), *b.left, Some(*b.right));
            }
            Expr::Call(call) => self.call(call)?,
            Expr::Index(i) if matches!(&*i.expr, Expr::Path(p) if p.path.get_ident().is_some()) => {
                let Expr::Path(p) = &*i.expr else { unreachable!("matched above") };
                let ident = p.path.get_ident().expect("matched above");
                let (name, span) = (ident.to_string(), ident.span());
                if !self.scope.library.arrays.contains_key(&name) {
                    dismantle([Expr::Index(i)]);
                    let mut arrays: Vec<&str> = self.scope.library.arrays.keys().map(String::as_str).collect();
                    arrays.sort_unstable();
                    return Err(ExprError::at(
                        span,
                        format!("`{name}` is not an array in {}", self.scope.context),
                        if arrays.is_empty() {
                            "declare arrays in an [arrays] table, e.g. c = [1.0, 0.5] or c = { file = \"c.csv\" }"
                                .to_owned()
                        } else {
                            format!("the arrays are: {}", arrays.join(", "))
                        },
                    ));
                }
                self.tasks.push(Task::Index(name, span));
                self.tasks.push(Task::Visit(*i.index));
            }
            Expr::MethodCall(m) => {
                let (method, span) = (m.method.to_string(), m.method.span());
                dismantle([Expr::MethodCall(m)]);
                return Err(ExprError::at(
                    span,
                    format!("method calls like `.{method}()` are not supported in {}", self.scope.context),
                    format!("write `{method}(x)` instead of `x.{method}()`"),
                ));
            }
            other => {
                // Located at a token of the node itself: syn's `span()` of a whole expression
                // walks all of it, recursively.
                let (what, span) = match &other {
                    Expr::Field(f) => ("a field access `.`".to_owned(), f.dot_token.span),
                    Expr::Tuple(t) => ("a tuple `(a, b)`".to_owned(), t.paren_token.span.open()),
                    Expr::Range(r) => ("a range `..`".to_owned(), r.limits.span()),
                    Expr::Index(i) => ("indexing `[...]`".to_owned(), i.bracket_token.span.open()),
                    Expr::Cast(c) => ("a cast `as`".to_owned(), c.as_token.span),
                    _ => (format!("`{}`", quote::quote!(#other)), other.span()),
                };
                dismantle([other]);
                return Err(ExprError::at(
                    span,
                    format!("unsupported expression {what} in {}", self.scope.context),
                    "expressions use numbers, names, + - * /, parentheses and calls such as sin(x) or pow(x, 2)",
                ));
            }
        }
        Ok(())
    }

    fn call(&mut self, call: syn::ExprCall) -> Result<(), ExprError> {
        let name = match &*call.func {
            Expr::Path(p) => p.path.get_ident().map(|i| i.to_string()),
            _ => None,
        };
        let Some(name) = name else {
            let span = call.paren_token.span.open();
            dismantle([Expr::Call(call)]);
            return Err(ExprError::at(
                span,
                format!("only named functions can be called in {}", self.scope.context),
                function_help(),
            ));
        };
        let span = call.func.span();
        let args: Vec<Expr> = call.args.into_iter().collect();
        if let Some(f) = self.scope.library.functions.get(&name) {
            if args.len() != f.params.len() {
                let help = format!("write `{name}({})`", f.params.join(", "));
                return Err(wrong_arity(&name, f.params.len(), args, span, self.scope.context, help));
            }
            self.tasks.push(Task::Inline(name, span));
            // The first argument is built first.
            self.tasks.extend(args.into_iter().rev().map(Task::Visit));
            return Ok(());
        }
        if let Some(&(_, arity)) = SPECIAL_FUNCTIONS.iter().find(|(n, _)| *n == name.replace(IF_SPELLING, "if")) {
            return self.special(name.replace(IF_SPELLING, "if"), arity, span, args);
        }
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
            dismantle(args);
            return Err(ExprError::at(span, format!("unknown function `{name}` in {}", self.scope.context), help));
        };
        if args.len() != expected {
            let help = match name.as_str() {
                "pow" => "write `pow(base, exponent)`".to_owned(),
                "atan2" => "write `atan2(y, x)`".to_owned(),
                _ => format!("write `{name}(x)`"),
            };
            return Err(wrong_arity(&name, expected, args, span, self.scope.context, help));
        }
        let mut args = args.into_iter();
        let first = args.next().expect("counted above");
        match name.as_str() {
            "pow" => self.schedule(Task::Binary(Graph::pow), first, args.next()),
            "atan2" => self.schedule(Task::Binary(Graph::atan2), first, args.next()),
            _ => self.schedule(Task::Call(Func::from_name(&name).expect("checked above")), first, None),
        }
        Ok(())
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

    /// Schedules a call of one of [`SPECIAL_FUNCTIONS`].
    fn special(&mut self, name: String, arity: usize, span: Span, args: Vec<Expr>) -> Result<(), ExprError> {
        if args.len() != arity {
            let help = format!("write `{}`", SPECIAL_USAGE.iter().find(|(n, _)| *n == name).map_or("", |(_, u)| u));
            return Err(wrong_arity(&name, arity, args, span, self.scope.context, help));
        }
        let mut args = args;
        if name == "sum" {
            let index = match &args[0] {
                Expr::Path(p) => p.path.get_ident().map(|i| (i.to_string(), i.span())),
                _ => None,
            };
            let Some((index, index_span)) = index.filter(|(i, _)| !self.scope.names.contains_key(i) && i != "pi")
            else {
                let s = args[0].span();
                dismantle(args);
                return Err(ExprError::at(
                    s,
                    format!("the first argument of `sum` is not a new index name in {}", self.scope.context),
                    "write `sum(k, first, last, term)` with an index name not otherwise in use, e.g. `sum(k, 0, 9, c[k] * legendre(k, x))`",
                ));
            };
            let _ = index_span;
            let body = args.pop().expect("four arguments");
            args.remove(0);
            self.tasks.push(Task::Sum(index, Box::new(body), span));
            self.tasks.extend(args.into_iter().rev().map(Task::Visit));
            return Ok(());
        }
        let task = match name.as_str() {
            "if" | "select" => {
                let condition = args.remove(0);
                let mut c = condition;
                while let Expr::Paren(p) = c {
                    c = *p.expr;
                }
                let Expr::Binary(b) = c else {
                    let s = c.span();
                    dismantle([c]);
                    dismantle(args);
                    return Err(ExprError::at(
                        s,
                        format!("the first argument of `{name}` is not a comparison in {}", self.scope.context),
                        format!("write `{name}(x < y, a, b)`, with one of < <= > >="),
                    ));
                };
                let (cmp, swap) = match b.op {
                    BinOp::Lt(_) => (Cmp::Lt, false),
                    BinOp::Le(_) => (Cmp::Le, false),
                    BinOp::Gt(_) => (Cmp::Lt, true),
                    BinOp::Ge(_) => (Cmp::Le, true),
                    op => {
                        dismantle([*b.left, *b.right]);
                        dismantle(args);
                        return Err(ExprError::at(
                            op.span(),
                            format!("the first argument of `{name}` is not a comparison in {}", self.scope.context),
                            format!("write `{name}(x < y, a, b)`, with one of < <= > >="),
                        ));
                    }
                };
                let (x, y) = if swap { (*b.right, *b.left) } else { (*b.left, *b.right) };
                args.splice(0..0, [x, y]);
                Task::Select(cmp)
            }
            "abs" => Task::Abs,
            "min" => Task::MinMax(false),
            "max" => Task::MinMax(true),
            "legendre" => Task::Legendre(false, span),
            _ => Task::Legendre(true, span),
        };
        self.tasks.push(task);
        // The first argument is built first.
        self.tasks.extend(args.into_iter().rev().map(Task::Visit));
        Ok(())
    }

    /// `sum(index, first, last, body)` with the bounds on the stack: the body built once per
    /// index value (a constant), the terms added in index order.
    fn sum(&mut self, index: &str, body: Expr, span: Span) -> Result<ExprId, ExprError> {
        let last = self.pop();
        let first = self.pop();
        let bound = |v: ExprId| self.graph.as_const(v).filter(|b| b.fract() == 0.0 && b.abs() <= 1e9);
        let (Some(first), Some(last)) = (bound(first), bound(last)) else {
            dismantle([body]);
            return Err(ExprError::at(
                span,
                format!("the bounds of `sum` are not integer constants in {}", self.scope.context),
                "write `sum(k, first, last, term)` with integers (numbers or constants) first <= last",
            ));
        };
        let terms = last - first + 1.0;
        if !(1.0..=MAX_SUM_TERMS as f64).contains(&terms) {
            dismantle([body]);
            return Err(ExprError::at(
                span,
                format!("`sum` from {first} to {last} has {terms} terms in {}", self.scope.context),
                format!("a sum has 1 to {MAX_SUM_TERMS} terms: first <= last"),
            ));
        }
        if self.inlined.depth >= MAX_INLINE_DEPTH {
            dismantle([body]);
            return Err(ExprError::at(
                span,
                format!(
                    "sums, named expressions and functions nested more than {MAX_INLINE_DEPTH} deep in {}",
                    self.scope.context
                ),
                "write some of the nested parts out, or combine them",
            ));
        }
        let mut names = self.scope.names.clone();
        let mut total = self.graph.zero();
        self.inlined.depth += 1;
        let mut result = Ok(());
        for k in (first as i64)..=(last as i64) {
            let k_id = self.graph.constant(k as f64);
            names.insert(index.to_owned(), k_id);
            let scope = Scope {
                names: &names,
                context: self.scope.context,
                library: self.scope.library,
                named: self.scope.named,
            };
            let mut builder = Builder {
                graph: self.graph,
                scope: &scope,
                inlined: self.inlined,
                tasks: vec![Task::Visit(body.clone())],
                values: Vec::new(),
            };
            let term = builder.run();
            dismantle(builder.tasks.drain(..).filter_map(|t| match t {
                Task::Visit(e) => Some(e),
                _ => None,
            }));
            match term {
                Ok(t) => total = self.graph.add(total, t),
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        self.inlined.depth -= 1;
        dismantle([body]);
        result.map(|()| total)
    }

    /// The Legendre polynomial P_l(x), or the associated P_l^m(x), from the values on the stack
    /// (x, l and m last), expanded by the three-term recurrences into the graph.
    fn legendre(&mut self, associated: bool, span: Span) -> Result<ExprId, ExprError> {
        let name = if associated { "assoc_legendre" } else { "legendre" };
        // The stack holds l, (m,) x, with x on top.
        let x = self.pop();
        let mut integers = self.values.split_off(self.values.len() - if associated { 2 } else { 1 }).into_iter();
        let graph = &*self.graph;
        let context = self.scope.context;
        let mut integer = |what: &str| -> Result<u32, ExprError> {
            let v = integers.next().expect("popped above");
            match graph.as_const(v) {
                Some(k) if k.fract() == 0.0 && (0.0..=f64::from(MAX_LEGENDRE_DEGREE)).contains(&k) => Ok(k as u32),
                _ => Err(ExprError::at(
                    span,
                    format!("the {what} of `{name}` is not an integer from 0 to {MAX_LEGENDRE_DEGREE} in {context}"),
                    if associated {
                        "write `assoc_legendre(l, m, x)` with integers 0 <= m <= l (numbers or constants)"
                    } else {
                        "write `legendre(l, x)` with an integer degree l >= 0 (a number or constant)"
                    },
                )),
            }
        };
        let (l, m) = if associated {
            let l = integer("degree l")?;
            let m = integer("order m")?;
            if m > l {
                return Err(ExprError::at(
                    span,
                    format!("`assoc_legendre` with order m = {m} above the degree l = {l} in {}", self.scope.context),
                    "P_l^m is zero for m > l; write `assoc_legendre(l, m, x)` with 0 <= m <= l",
                ));
            }
            (l, m)
        } else {
            (integer("degree l")?, 0)
        };
        Ok(legendre(self.graph, l, m, x))
    }

    /// Builds the body of library function `name` with its parameters bound to the arguments on
    /// the value stack.
    fn inline_function(&mut self, name: &str, span: Span) -> Result<ExprId, ExprError> {
        let library: &Library = self.scope.library;
        let f = &library.functions[name];
        let args = self.values.split_off(self.values.len() - f.params.len());
        if f.broken {
            return Ok(self.graph.constant(BROKEN_PLACEHOLDER));
        }
        let key = (name.to_owned(), args);
        if let Some(&v) = self.inlined.cache.get(&key) {
            return Ok(v);
        }
        // The constants' nodes in name order, so that node ids never depend on hashing.
        let mut constants: Vec<(&String, &f64)> = library.constants.iter().collect();
        constants.sort_unstable_by(|a, b| a.0.cmp(b.0));
        let mut names: HashMap<String, ExprId> =
            constants.into_iter().map(|(k, &v)| (k.clone(), self.graph.constant(v))).collect();
        names.extend(f.params.iter().cloned().zip(key.1.iter().copied()));
        let context = format!("the function `{name}`");
        let scope = Scope { names: &names, context: &context, library, named: false };
        let v = self.inline(&f.body, &scope, name, span)?;
        self.inlined.cache.insert(key, v);
        Ok(v)
    }

    /// Builds the body of a named expression or function in `scope`, one level deeper; a
    /// problem inside it (a name the place of use does not have) is reported at the use.
    fn inline(&mut self, body: &str, scope: &Scope<'_>, name: &str, span: Span) -> Result<ExprId, ExprError> {
        if self.inlined.depth >= MAX_INLINE_DEPTH {
            return Err(ExprError::at(
                span,
                format!(
                    "named expressions and functions nested more than {MAX_INLINE_DEPTH} deep in {}",
                    self.scope.context
                ),
                "write some of the nested parts out, or combine them",
            ));
        }
        self.inlined.depth += 1;
        let v = parse_inlining(self.graph, body, scope, self.inlined);
        self.inlined.depth -= 1;
        v.map_err(|e| ExprError::at(span, format!("{} (inside `{name}`)", e.message), e.help))
    }

    fn name(&mut self, name: &str, span: Span) -> Result<ExprId, ExprError> {
        if let Some(&id) = self.scope.names.get(name) {
            return Ok(id);
        }
        if name == IF_SPELLING {
            return Err(ExprError::at(
                span,
                format!("`if` is not called in {}", self.scope.context),
                "write `if(x < y, a, b)`",
            ));
        }
        if name == "pi" {
            return Ok(self.graph.constant(std::f64::consts::PI));
        }
        if let Some(named) = self.scope.library.expressions.get(name).filter(|_| self.scope.named) {
            if named.broken {
                return Ok(self.graph.constant(BROKEN_PLACEHOLDER));
            }
            let key = (name.to_owned(), Vec::new());
            if let Some(&v) = self.inlined.cache.get(&key) {
                return Ok(v);
            }
            let scope = Scope {
                names: self.scope.names,
                context: self.scope.context,
                library: self.scope.library,
                named: true,
            };
            let v = self.inline(&named.body, &scope, name, span)?;
            self.inlined.cache.insert(key, v);
            return Ok(v);
        }
        let mut known: Vec<&str> = self.scope.names.keys().map(String::as_str).collect();
        if self.scope.named {
            known.extend(self.scope.library.expressions.keys().map(String::as_str));
        }
        known.push("pi");
        known.sort_unstable();
        let suggestion = closest(name, &known).map(|s| format!("did you mean `{s}`? ")).unwrap_or_default();
        let help = if Func::from_name(name).is_some()
            || BINARY_FUNCTIONS.contains(&name)
            || self.scope.library.functions.contains_key(name)
        {
            format!("`{name}` is a function: call it, e.g. `{name}(x)`")
        } else {
            format!("{suggestion}the names available here are: {}", known.join(", "))
        };
        Err(ExprError::at(span, format!("unknown name `{name}` in {}", self.scope.context), help))
    }
}

/// The functions built into the graph from other operations, with their argument counts.
pub const SPECIAL_FUNCTIONS: [(&str, usize); 8] =
    [("if", 3), ("select", 3), ("abs", 1), ("min", 2), ("max", 2), ("legendre", 2), ("assoc_legendre", 3), ("sum", 4)];

/// The most terms one `sum` may have.
pub const MAX_SUM_TERMS: usize = 1_000_000;

/// How each of [`SPECIAL_FUNCTIONS`] is called.
const SPECIAL_USAGE: [(&str, &str); 8] = [
    ("sum", "sum(k, first, last, term)"),
    ("if", "if(x < y, a, b)"),
    ("select", "select(x < y, a, b)"),
    ("abs", "abs(x)"),
    ("min", "min(a, b)"),
    ("max", "max(a, b)"),
    ("legendre", "legendre(l, x)"),
    ("assoc_legendre", "assoc_legendre(l, m, x)"),
];

fn function_help() -> String {
    let mut names: Vec<&str> = Func::ALL.iter().map(|(_, n)| *n).collect();
    names.extend(BINARY_FUNCTIONS);
    names.extend(SPECIAL_FUNCTIONS.iter().map(|(n, _)| *n));
    format!("the functions are {}", names.join(", "))
}

/// The known name closest to `name` by edit distance (Levenshtein, `strsim`), if it is close
/// enough to be a typo.
pub fn closest<'a>(name: &str, known: &[&'a str]) -> Option<&'a str> {
    known
        .iter()
        .map(|k| (strsim::levenshtein(name, k), *k))
        .filter(|(d, k)| *d <= 2.max(k.len() / 3))
        .min()
        .map(|(_, k)| k)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<(Graph, ExprId), ExprError> {
        let mut g = Graph::new();
        let x = g.var("x");
        let names = HashMap::from([("x".to_owned(), x)]);
        let library = Library::default();
        let scope = Scope { names: &names, context: "the test", library: &library, named: true };
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
    fn piecewise_functions() {
        assert_eq!(value("if(x < 1, 10, 20)", 0.5), 10.0);
        assert_eq!(value("if(x < 1, 10, 20)", 1.0), 20.0);
        assert_eq!(value("if(x <= 1, 10, 20)", 1.0), 10.0);
        assert_eq!(value("if(x > 1, 10, 20)", 1.0), 20.0);
        assert_eq!(value("select((x >= 1), 10, 20)", 1.0), 10.0);
        assert_eq!(value("if(2 * x > 1, x, -x) + 1", 0.25), 0.75);
        assert_eq!(value("abs(x - 3)", 1.0), 2.0);
        assert_eq!(value("abs(x)", -0.0), 0.0);
        assert_eq!(value("min(x, 2) + max(x, 2)", 5.0), 7.0);
        assert_eq!(value("min(x, 2) - max(x, 2)", -1.0), -3.0);
        // A NaN comparison chooses the second branch.
        assert_eq!(value("if(x < 1, 10, 20)", f64::NAN), 20.0);
        assert_eq!(value("legendre(2, x)", 0.5), -0.125);
        assert_eq!(value("assoc_legendre(2, 2, x)", 0.5), 2.25);
        // A constant condition chooses at build time.
        let (g, id) = parse("if(1 < 2, x, 2 * x)").unwrap();
        assert_eq!(g.node(id), crate::expr::Node::Var(0));
    }

    #[test]
    fn piecewise_mistakes_are_located() {
        let e = parse("x < 1").unwrap_err();
        assert_eq!(e.message, "a comparison `<` outside `if` in the test");
        assert_eq!((e.line, e.column), (1, 2));
        let e = parse("1 + if(x, 1, 2)").unwrap_err();
        assert_eq!(e.message, "the first argument of `if` is not a comparison in the test");
        assert_eq!((e.line, e.column), (1, 7));
        let e = parse("2 * if(x < 1, 2)").unwrap_err();
        assert_eq!(e.message, "`if` takes 3 arguments but 2 were given in the test");
        assert!(e.help.contains("if(x < y, a, b)"));
        assert_eq!((e.line, e.column), (1, 4));
        let e = parse("2 * if + x").unwrap_err();
        assert_eq!(e.message, "`if` is not called in the test");
        assert_eq!((e.line, e.column), (1, 4));
        let e = parse("if(x == 1, 1, 2)").unwrap_err();
        assert_eq!(e.message, "unexpected character `=` in the test");
        let e = parse("legendre(x, x)").unwrap_err();
        assert!(e.message.starts_with("the degree l of `legendre` is not an integer"), "{e:?}");
        let e = parse("legendre(1.5, x)").unwrap_err();
        assert!(e.message.starts_with("the degree l of `legendre` is not an integer"), "{e:?}");
        let e = parse("assoc_legendre(1, 2, x)").unwrap_err();
        assert!(e.message.starts_with("`assoc_legendre` with order m = 2 above the degree l = 1"), "{e:?}");
        let e = parse("abs(x, 1)").unwrap_err();
        assert_eq!(e.message, "`abs` takes 1 argument but 2 were given in the test");
    }

    #[test]
    fn derivatives_of_piecewise_functions_are_by_branch() {
        use crate::diff::Differentiator;
        for (text, x, want) in [
            ("abs(x)", -2.0, -1.0),
            ("abs(x)", 2.0, 1.0),
            ("min(x * x, 1)", 0.5, 1.0),
            ("min(x * x, 1)", 2.0, 0.0),
            ("max(x * x, 1)", 2.0, 4.0),
            ("if(x < 1, x * x * x, 3 * x)", 0.5, 0.75),
            ("if(x < 1, x * x * x, 3 * x)", 1.5, 3.0),
        ] {
            let (mut g, id) = parse(text).unwrap();
            let d = Differentiator::new().derivative(&mut g, id, 0);
            assert_eq!(g.eval(&[d], &[x])[0], want, "d/dx {text} at {x}");
        }
    }

    /// The reverse sweep (`crate::adjoint`, used for large molecules) gives the branch's
    /// derivative too, also where the branch operand appears twice (`abs(x)` is
    /// `if(x < 0, -x, x)`).
    #[test]
    fn reverse_mode_derivatives_of_piecewise_functions() {
        use crate::diff::Differentiator;
        for text in ["abs(x)", "3 * abs(x) + min(x, x * x)", "max(2 * x, abs(x - 1))", "if(x < 1, x * x, -x)"] {
            for x in [-1.5, -0.25, 0.25, 0.75, 1.5, 3.0] {
                let (mut g, id) = parse(text).unwrap();
                let forward = Differentiator::new().derivative(&mut g, id, 0);
                let reverse = crate::adjoint::gradient(&mut g, id, &[0])[0];
                let v = g.eval(&[forward, reverse], &[x]);
                assert_eq!(v[0], v[1], "d/dx {text} at {x}");
            }
        }
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
    fn deep_nesting_keywords_and_stray_characters_are_located_errors() {
        let limit = MAX_NESTING / 2;
        assert!(parse(&format!("{}x{}", "-(".repeat(limit), ")".repeat(limit))).is_ok());
        let e = parse(&format!("1 + {}x{}", "(".repeat(MAX_NESTING + 1), ")".repeat(MAX_NESTING + 1))).unwrap_err();
        assert!(e.message.starts_with("expression nested more than 128 deep"), "{e:?}");
        assert_eq!((e.line, e.column), (1, 4 + MAX_NESTING));
        // A flat sum and a long run of minus signs separated by operators are not nesting.
        let flat = vec!["x"; 20_000].join(" + ");
        assert_eq!(value(&flat, 1.0), 20_000.0);
        assert_eq!(value(&vec!["-x"; 1000].join(" - "), 1.0), 998.0);
        let e = parse(&format!("{}x", "-".repeat(MAX_NESTING + 1))).unwrap_err();
        assert!(e.message.starts_with("expression nested more than"), "{e:?}");
        let e = parse("x +\n return x").unwrap_err();
        assert_eq!(e.message, "`return` is not a name (it is a Rust keyword) in the test");
        assert_eq!((e.line, e.column), (2, 1));
        let e = parse("x == 1").unwrap_err();
        assert_eq!(e.message, "unexpected character `=` in the test");
        assert!(parse("1e-3 * x + 2.5E+2 - 1.").is_ok());
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
