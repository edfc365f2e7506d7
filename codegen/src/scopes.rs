//! Bounded scope nesting for long generated functions.
//!
//! Every `let` opens a lexical scope that lasts to the end of its block, so a function body of
//! `L` consecutive `let`s is a chain of `L` nested scopes. With debug information (cargo's `dev`
//! and `test` profiles) rustc describes each as a `DILexicalBlock` inside the previous one,
//! and LLVM's DWARF writer walks that chain recursively: measured with rustc 1.95 at
//! `-C debuginfo=2 -C opt-level=1` on straight-line `f64` code, a function of 2 500 `let`s
//! compiles and one of 3 000 crashes rustc with a stack overflow (SIGSEGV); `debuginfo=1`
//! crashes too, only `line-tables-only` or `RUST_MIN_STACK=16777216` get through
//! (docs/src/history/benchmarks.md, "Large molecules, third step"). Release builds carry no debug information
//! and never hit it.
//! This is how the test profile overflowed for the dense forms of ethane.
//!
//! [`nest`] keeps the chain short without changing what is computed: a function with more than
//! [`FLAT_LETS`] `let`s has its statements grouped into blocks of at most [`CHUNK_LETS`] `let`s,
//! each block handing on only the values that later statements read:
//!
//! ```text
//! let (t17, t40) = {
//!     let t12 = ...;
//!     ...
//!     k.a[(0, 3)] = t21;
//!     (t17, t40)
//! };
//! ```
//!
//! The deepest chain is then the number of blocks plus [`CHUNK_LETS`], and if the blocks
//! themselves are more than [`FLAT_LETS`] the grouping is applied again to them. Functions with
//! at most [`FLAT_LETS`] `let`s (every function of the shipped molecules up to ethane) are
//! emitted exactly as before. [`max_let_depth`] measures the result, for tests and the cost
//! report.

use std::collections::{HashMap, HashSet};

use proc_macro2::{Ident, TokenStream, TokenTree};
use quote::quote;

/// Functions with at most this many `let`s (at one level) are left flat.
pub const FLAT_LETS: usize = 1024;

/// At most this many `let`s go into one block when a function is grouped.
pub const CHUNK_LETS: usize = 256;

/// The deepest chain of nested `let` scopes that [`nest`] can leave in a function, for
/// functions up to about `FLAT_LETS · CHUNK_LETS` (262 144) `let`s; a regression test holds the
/// generated code to it. rustc's limit measured above is about 2 500.
pub const MAX_LET_DEPTH: usize = FLAT_LETS + CHUNK_LETS + 8;

/// One statement of a generated function body.
pub struct Statement {
    /// The statement's tokens, e.g. `let t3 = t1 * t2;` or `k.a[(0, 1)] = t3;`.
    pub tokens: TokenStream,
    /// The names it binds (`let` patterns); empty for stores.
    pub defines: Vec<Ident>,
    /// Whether it may be moved into a block. The statement between the two halves of a
    /// function with a barrier (it calls back into the runtime and binds `omega`, `qdot`) stays
    /// at the top level.
    pub movable: bool,
}

impl Statement {
    /// A statement that binds nothing (a store).
    pub fn store(tokens: TokenStream) -> Self {
        Self { tokens, defines: Vec::new(), movable: true }
    }

    /// A `let` binding `defines`.
    pub fn binding(tokens: TokenStream, defines: Vec<Ident>) -> Self {
        Self { tokens, defines, movable: true }
    }
}

/// Every identifier in `tokens`, recursively (the names a statement reads, and some it does not,
/// such as `k` or `sin_cos`; only names some statement defines matter).
fn idents(tokens: &TokenStream, out: &mut HashSet<String>) {
    for t in tokens.clone() {
        match t {
            TokenTree::Ident(i) => {
                out.insert(i.to_string());
            }
            TokenTree::Group(g) => idents(&g.stream(), out),
            _ => {}
        }
    }
}

/// The statements with their scope chains bounded (see the module docs): unchanged if at most
/// [`FLAT_LETS`] of them are `let`s.
pub fn nest(statements: Vec<Statement>) -> Vec<TokenStream> {
    nest_with(statements, FLAT_LETS, CHUNK_LETS)
}

/// [`nest`] with other limits (for tests of the repeated grouping).
fn nest_with(statements: Vec<Statement>, flat: usize, chunk: usize) -> Vec<TokenStream> {
    let mut level: Vec<(Statement, HashSet<String>)> = statements
        .into_iter()
        .map(|s| {
            let mut uses = HashSet::new();
            idents(&s.tokens, &mut uses);
            (s, uses)
        })
        .collect();
    while level.iter().filter(|(s, _)| !s.defines.is_empty()).count() > flat {
        let before = level.len();
        level = group(level, chunk);
        if level.len() >= before {
            break; // nothing movable left to group
        }
    }
    level.into_iter().map(|(s, _)| s.tokens).collect()
}

/// One grouping pass: runs of movable statements become blocks of at most `chunk` `let`s.
fn group(level: Vec<(Statement, HashSet<String>)>, chunk: usize) -> Vec<(Statement, HashSet<String>)> {
    // The last statement that reads each name.
    let mut last_use: HashMap<&str, usize> = HashMap::new();
    for (i, (_, uses)) in level.iter().enumerate() {
        for u in uses {
            last_use.insert(u.as_str(), i);
        }
    }
    // Chunk boundaries: [start, end) ranges of movable statements with at most CHUNK_LETS lets.
    let mut ranges = Vec::new();
    let (mut start, mut lets) = (None::<usize>, 0);
    for (i, (s, _)) in level.iter().enumerate() {
        if !s.movable {
            if let Some(b) = start.take() {
                ranges.push(b..i);
            }
            lets = 0;
            continue;
        }
        let b = *start.get_or_insert(i);
        if !s.defines.is_empty() {
            lets += 1;
            if lets == chunk {
                ranges.push(b..i + 1);
                start = None;
                lets = 0;
            }
        }
    }
    if let Some(b) = start {
        ranges.push(b..level.len());
    }
    let live_out: Vec<Vec<Ident>> = ranges
        .iter()
        .map(|r| {
            level[r.clone()]
                .iter()
                .flat_map(|(s, _)| &s.defines)
                .filter(|d| last_use.get(d.to_string().as_str()).is_some_and(|&u| u >= r.end))
                .cloned()
                .collect()
        })
        .collect();
    drop(last_use);

    let mut out = Vec::new();
    let mut ranges = ranges.into_iter().zip(live_out).peekable();
    let mut items = level.into_iter().enumerate().peekable();
    while let Some((i, item)) = items.next() {
        let Some((r, live)) = ranges.next_if(|(r, _)| r.start == i) else {
            out.push(item);
            continue;
        };
        let mut body = vec![item];
        while let Some((_, next)) = items.next_if(|(j, _)| *j < r.end) {
            body.push(next);
        }
        let mut uses = HashSet::new();
        for (_, u) in &body {
            uses.extend(u.iter().cloned());
        }
        let stmts = body.into_iter().map(|(s, _)| s.tokens);
        let tokens = if live.is_empty() {
            quote!({ #(#stmts)* })
        } else {
            quote!(let (#(#live,)*) = { #(#stmts)* (#(#live,)*) };)
        };
        out.push((Statement { tokens, defines: live, movable: true }, uses));
    }
    out
}

/// The deepest chain of nested `let` scopes in any function of `file`: in each block, the
/// number of `let`s before a point plus the depth of any block nested there. Counts blocks
/// that are statements or `let` initialisers, the only places generated code nests them.
pub fn max_let_depth(file: &syn::File) -> usize {
    let mut depth = 0;
    for item in &file.items {
        let blocks: Vec<&syn::Block> = match item {
            syn::Item::Fn(f) => vec![&f.block],
            syn::Item::Impl(i) => i
                .items
                .iter()
                .filter_map(|it| match it {
                    syn::ImplItem::Fn(f) => Some(&f.block),
                    _ => None,
                })
                .collect(),
            _ => Vec::new(),
        };
        for b in blocks {
            depth = depth.max(block_depth(b, 0));
        }
    }
    depth
}

fn block_depth(block: &syn::Block, base: usize) -> usize {
    let (mut lets, mut deepest) = (0, base);
    for stmt in &block.stmts {
        let nested = match stmt {
            syn::Stmt::Local(l) => l.init.as_ref().map(|i| &*i.expr),
            syn::Stmt::Expr(e, _) => Some(e),
            _ => None,
        };
        if let Some(syn::Expr::Block(b)) = nested {
            deepest = deepest.max(block_depth(&b.block, base + lets));
        }
        if matches!(stmt, syn::Stmt::Local(_)) {
            lets += 1;
            deepest = deepest.max(base + lets);
        }
    }
    deepest
}

#[cfg(test)]
mod tests {
    use super::*;
    use quote::format_ident;

    /// `n` lets, `t_i = 1.5 t_(i−1) + t_(i mod 7)`, with every 97th value stored, as a body.
    fn chain(n: usize) -> Vec<Statement> {
        let mut s = vec![Statement::binding(quote!(let t0 = q[0];), vec![format_ident!("t0")])];
        for i in 1..n {
            let (t, a, b) = (format_ident!("t{i}"), format_ident!("t{}", i - 1), format_ident!("t{}", i % 7));
            s.push(Statement::binding(quote!(let #t = #a * 1.5 + #b;), vec![t.clone()]));
            if i % 97 == 0 {
                s.push(Statement::store(quote!(out[#i] = #t;)));
            }
        }
        s
    }

    fn parse(stmts: &[TokenStream]) -> syn::File {
        syn::parse2(quote!(fn f() { #(#stmts)* })).unwrap()
    }

    #[test]
    fn short_functions_stay_flat_and_long_ones_are_bounded() {
        let flat = nest(chain(FLAT_LETS));
        assert_eq!(flat.len(), FLAT_LETS + (FLAT_LETS - 1) / 97);
        assert_eq!(max_let_depth(&parse(&flat)), FLAT_LETS);
        for n in [FLAT_LETS + 1, 20_000] {
            let d = max_let_depth(&parse(&nest(chain(n))));
            assert!((CHUNK_LETS..=MAX_LET_DEPTH).contains(&d), "{n} lets: depth {d}");
        }
        // Grouping repeats while the blocks are too many: 2 000 lets in blocks of 4, at most 8
        // at one level: three levels (500, 125, 32 blocks), then 8 blocks of 4 at the top.
        let d = max_let_depth(&parse(&nest_with(chain(2000), 8, 4)));
        assert!(d <= 8 + 4 * 4, "depth {d}");
    }

    /// Only the values read after a block leave it, and the grouped body computes the same:
    /// every name a later statement reads is still bound there (syn-parsed, then each block's
    /// tuple checked against the names the rest of the body reads).
    #[test]
    fn blocks_hand_on_exactly_the_values_read_later() {
        let mut s = chain(FLAT_LETS + 10);
        s.push(Statement::store(quote!(out[0] = t200;)));
        let file = parse(&nest(s));
        let syn::Item::Fn(f) = &file.items[0] else { panic!("a function") };
        let syn::Stmt::Local(first) = &f.block.stmts[0] else { panic!("a let") };
        let syn::Pat::Tuple(names) = &first.pat else { panic!("a tuple pattern") };
        let names: Vec<String> = names.elems.iter().map(|p| quote!(#p).to_string()).collect();
        // t0..t6 are read to the end, t255 by t256, t200 by the last store.
        assert_eq!(names, ["t0", "t1", "t2", "t3", "t4", "t5", "t6", "t200", "t255"]);
    }
}
