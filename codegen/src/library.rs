//! The definition's `[functions]` and `[expressions]` tables, validated into a [`Library`].
//!
//! ```toml
//! [functions]                       # defined once, called anywhere; the key is the signature
//! "lj(r, eps, sigma)" = "4 * eps * (pow(sigma / r, 12) - pow(sigma / r, 6))"
//!
//! [expressions]                     # named sub-expressions, in file order
//! rx = "r * sin(theta)"
//! d1 = "sqrt(pow(rx - 2.2, 2) + pow(r * cos(theta), 2))"
//! ```
//!
//! A function body sees its parameters, the constants and the functions defined above it; a
//! named expression sees the coordinates, constants, parameters (of the potential and the
//! dipole), the functions and the named expressions above it. So neither can refer to itself,
//! directly or through others: recursion and cycles are errors at the place of the reference.
//! Both are inlined where they are used ([`crate::parse::Library`]); a named expression that
//! uses a potential parameter can be used in the potential but not in a position.

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;

use toml::Spanned;

use crate::definition_error::{DefinitionError, ExpressionPlace};
use crate::diagnostic::Source;
use crate::expr::{ExprId, Graph};
use crate::parse::{self, ExprError, Function, Library, Named, Scope};

/// Checks a new name (valid, not reserved, not taken) and records it, as `what` (e.g. "function").
pub type Declare<'a> = dyn FnMut(&Spanned<String>, &'static str) -> Result<(), DefinitionError> + 'a;

/// One validation of the library: what [`validate`] needs from the definition's validator.
pub struct Input<'a> {
    /// The `[functions]` table as read.
    pub functions: &'a BTreeMap<Spanned<String>, Spanned<String>>,
    /// The `[expressions]` table as read.
    pub expressions: &'a BTreeMap<Spanned<String>, Spanned<String>>,
    /// The constants' values.
    pub constants: HashMap<String, f64>,
    /// The arrays' values.
    pub arrays: HashMap<String, Vec<f64>>,
    /// Every other name a named expression may use: coordinates, constants, parameters.
    pub names: Vec<String>,
}

/// The entries of a table in file order (TOML tables are read sorted by key).
fn in_file_order(table: &BTreeMap<Spanned<String>, Spanned<String>>) -> Vec<(&Spanned<String>, &Spanned<String>)> {
    let mut entries: Vec<_> = table.iter().collect();
    entries.sort_by_key(|(k, _)| k.span().start);
    entries
}

/// Validates the functions, then the named expressions, each in file order. `declare` checks a
/// new name (valid, not reserved, not taken) and records it. Every problem is returned; an entry
/// with a problem is in the library marked broken, so uses of it raise no further errors.
pub fn validate(src: &Source<'_>, input: Input<'_>, declare: &mut Declare<'_>) -> (Library, Vec<DefinitionError>) {
    let mut library = Library { constants: input.constants, arrays: input.arrays, ..Library::default() };
    let mut errors = Vec::new();

    let functions = in_file_order(input.functions);
    let function_names: Vec<(String, Range<usize>)> = functions
        .iter()
        .map(|(k, _)| (k.get_ref().split('(').next().unwrap_or_default().trim().to_owned(), k.span()))
        .collect();
    for (i, (key, body)) in functions.iter().enumerate() {
        let (name, params) = match signature(src, key, declare) {
            Ok(s) => s,
            Err(e) => {
                errors.push(e);
                continue;
            }
        };
        let mut scratch = Graph::new();
        let mut names: HashMap<String, ExprId> =
            library.constants.iter().map(|(k, &v)| (k.clone(), scratch.constant(v))).collect();
        for p in &params {
            let v = scratch.var(p);
            names.insert(p.clone(), v);
        }
        let context = format!("the function `{name}`");
        let scope = Scope { names: &names, context: &context, library: &library, named: false };
        let built = parse::parse_expression(&mut scratch, body.get_ref(), &scope).map_err(|e| {
            let e = explain_order(e, "function", &name, &function_names[i..], src, "unknown function");
            src.expression_error(body.span(), body.get_ref(), e)
        });
        let broken = built.is_err();
        errors.extend(built.err());
        library.functions.insert(name, Function { params, body: body.get_ref().clone(), broken });
    }

    let expressions = in_file_order(input.expressions);
    let expression_names: Vec<(String, Range<usize>)> =
        expressions.iter().map(|(k, _)| (k.get_ref().clone(), k.span())).collect();
    for (i, (key, body)) in expressions.iter().enumerate() {
        let name = key.get_ref();
        if let Err(e) = declare(key, "named expression") {
            errors.push(e);
            continue;
        }
        let mut scratch = Graph::new();
        let names: HashMap<String, ExprId> = input.names.iter().map(|n| (n.clone(), scratch.var(n))).collect();
        let context = format!("the named expression `{name}`");
        let scope = Scope { names: &names, context: &context, library: &library, named: true };
        let built = parse::parse_expression(&mut scratch, body.get_ref(), &scope).map_err(|e| {
            let e = explain_order(e, "named expression", name, &expression_names[i..], src, "unknown name");
            src.expression_error(body.span(), body.get_ref(), e)
        });
        let broken = built.is_err();
        errors.extend(built.err());
        library.expressions.insert(name.clone(), Named { body: body.get_ref().clone(), broken });
    }
    (library, errors)
}

/// Rewrites "unknown name `b`" (or function) inside `name`'s body when `b` is `name` itself or
/// defined below it (`this_and_later[0]` is `name`): the reference is a cycle or comes too early.
fn explain_order(
    e: ExprError,
    what: &str,
    name: &str,
    this_and_later: &[(String, Range<usize>)],
    src: &Source<'_>,
    unknown: &str,
) -> ExprError {
    for (j, (other, span)) in this_and_later.iter().enumerate() {
        if !e.message.starts_with(&format!("{unknown} `{other}` ")) {
            continue;
        }
        let (message, help) = if j == 0 {
            (
                format!("the {what} `{name}` refers to itself"),
                format!("a {what} cannot be defined in terms of itself (no recursion); write it out"),
            )
        } else {
            let (line, _) = src.place(span.start);
            (
                format!("the {what} `{name}` uses `{other}`, which is defined below it (line {line})"),
                format!(
                    "a {what} may use only those defined above it (so there are no cycles): move `{other}` above `{name}`"
                ),
            )
        };
        return ExprError { message, help, ..e };
    }
    e
}

/// Reads a function's key `name(p1, p2, ...)`: declares the name, checks the parameters.
fn signature(
    src: &Source<'_>,
    key: &Spanned<String>,
    declare: &mut Declare<'_>,
) -> Result<(String, Vec<String>), DefinitionError> {
    let text = key.get_ref().trim();
    let form = "write the key as the signature, quoted: \"lj(r, eps, sigma)\" = \"4 * eps * ...\"";
    let (Some(open), true) = (text.find('('), text.ends_with(')')) else {
        return Err(src.error(key.span(), format!("function `{text}` has no parameter list"), form));
    };
    let name = text[..open].trim().to_owned();
    declare(&Spanned::new(key.span(), name.clone()), "function")?;
    let inner = &text[open + 1..text.len() - 1];
    if inner.trim().is_empty() {
        return Err(src.error(
            key.span(),
            format!("function `{name}` has no parameters"),
            "a function takes at least one parameter; a part without parameters belongs in [expressions]",
        ));
    }
    let mut params: Vec<String> = Vec::new();
    for p in inner.split(',').map(str::trim) {
        let reserved = p == "pi"
            || crate::expr::Func::from_name(p).is_some()
            || parse::BINARY_FUNCTIONS.contains(&p)
            || parse::SPECIAL_FUNCTIONS.iter().any(|(f, _)| *f == p)
            || syn::parse_str::<syn::Ident>(p).is_err()
            || !p.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            || !p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
        if reserved {
            return Err(src.error(
                key.span(),
                format!("`{p}` is not a valid parameter name of function `{name}`"),
                "parameters are names of letters, digits and `_`, not `pi`, a function name or a Rust keyword",
            ));
        }
        if params.iter().any(|q| q == p) {
            return Err(src.error(
                key.span(),
                format!("function `{name}` has two parameters named `{p}`"),
                "give each parameter its own name",
            ));
        }
        params.push(p.to_owned());
    }
    Ok((name, params))
}
