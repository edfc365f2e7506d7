//! The import graph between the top-level modules of a crate, read from its source files, and
//! its circles (strongly connected components of more than one module).
//!
//! Each `.rs` file under a crate's source folder belongs to the top-level module its path names
//! (`src/report/energy.rs` and `src/report/mod.rs` to `report`). A file references module `x`
//! when its code names `crate::x` (also inside a `use crate::{x, ...}` group), `crate::Name`
//! where the crate root re-exports `Name` from `x` (`pub use x::Name;` in `lib.rs`), or climbs
//! out of its own top-level module with `super::` (`super::super::x` from `a/b.rs`). Comments
//! and doc comments do not count (an intra-doc link is documentation, not a dependency), nor do
//! string and character literals, nor items under `#[cfg(test)]` (a unit test may build its
//! input with a higher layer, as an integration test would). Inline `mod name { ... }`
//! blocks are followed, so `super::` inside one stays in its file's module.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// One place a module references another: the file (relative to the crate's source folder) and
/// its 1-based line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Place {
    /// The file, relative to the source folder.
    pub file: PathBuf,
    /// The line, from 1.
    pub line: usize,
}

/// The top-level module graph of one crate: for each edge `from → to`, the first place found.
#[derive(Clone, Debug, Default)]
pub struct ModuleGraph {
    /// Every top-level module with a file.
    pub modules: BTreeSet<String>,
    /// `(from, to)` → the first place `from` references `to`.
    pub edges: BTreeMap<(String, String), Place>,
}

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Ident(String),
    Punct(char),
    /// `::`
    Path,
}

/// The tokens of Rust source, without comments and literals, each with its line.
fn tokens(text: &str) -> Vec<(Token, usize)> {
    let c: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut line = 1;
    let mut i = 0;
    let n = c.len();
    // Skip a quoted string starting at `i` (on the opening quote), honouring escapes.
    let skip_string = |mut i: usize, line: &mut usize| -> usize {
        i += 1;
        while i < n && c[i] != '"' {
            if c[i] == '\n' {
                *line += 1;
            }
            if c[i] == '\\' {
                i += 1;
                if i < n && c[i] == '\n' {
                    *line += 1;
                }
            }
            i += 1;
        }
        i + 1
    };
    while i < n {
        let ch = c[i];
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && i + 1 < n && c[i + 1] == '/' {
            while i < n && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && i + 1 < n && c[i + 1] == '*' {
            let mut depth = 0;
            while i < n {
                if c[i] == '/' && i + 1 < n && c[i + 1] == '*' {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && i + 1 < n && c[i + 1] == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if c[i] == '\n' {
                        line += 1;
                    }
                    i += 1;
                }
            }
        } else if ch == '"' {
            i = skip_string(i, &mut line);
        } else if ch == '\'' {
            // A character literal ('a', '\n', '\u{..}') or a lifetime / label ('a).
            if i + 1 < n && c[i + 1] == '\\' {
                i += 2;
                while i < n && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if i + 2 < n && c[i + 2] == '\'' {
                i += 3;
            } else {
                i += 1;
            }
        } else if ch.is_alphanumeric() || ch == '_' {
            let start = i;
            while i < n && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            let word: String = c[start..i].iter().collect();
            // Raw strings r"..", r#".."#, br".."; byte strings b"..".
            if (word == "r" || word == "br") && i < n && (c[i] == '"' || c[i] == '#') {
                let mut hashes = 0;
                while i < n && c[i] == '#' {
                    hashes += 1;
                    i += 1;
                }
                if i < n && c[i] == '"' {
                    i += 1;
                    loop {
                        if i >= n {
                            break;
                        }
                        if c[i] == '\n' {
                            line += 1;
                        }
                        if c[i] == '"' && (0..hashes).all(|k| i + 1 + k < n && c[i + 1 + k] == '#') {
                            i += 1 + hashes;
                            break;
                        }
                        i += 1;
                    }
                    continue;
                }
                out.push((Token::Ident(word), line));
                continue;
            }
            if (word == "b" || word == "c") && i < n && c[i] == '"' {
                i = skip_string(i, &mut line);
                continue;
            }
            if word == "b" && i < n && c[i] == '\'' {
                i += 1;
                if i < n && c[i] == '\\' {
                    i += 1;
                }
                while i + 1 < n && c[i + 1] != '\'' {
                    i += 1;
                }
                i += 2;
                continue;
            }
            out.push((Token::Ident(word), line));
        } else if ch == ':' && i + 1 < n && c[i + 1] == ':' {
            out.push((Token::Path, line));
            i += 2;
        } else {
            out.push((Token::Punct(ch), line));
            i += 1;
        }
    }
    out
}

/// The module path a file stands for, relative to the source folder (`a/b.rs`, `a/b/mod.rs` →
/// `[a, b]`); the crate root (`lib.rs`) is empty.
fn module_path(relative: &Path) -> Vec<String> {
    let mut parts: Vec<String> = relative.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap_or_default();
    let stem = last.strip_suffix(".rs").unwrap_or(&last);
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts
}

/// The first identifiers of a path group `{a::b, c, d::{e}}` starting at `start` (on the
/// `{`): `[a, c, d]`, with their lines.
fn group_heads(toks: &[(Token, usize)], start: usize) -> Vec<(String, usize)> {
    let mut heads = Vec::new();
    let mut depth = 0;
    let mut expect_head = true;
    for (tok, line) in &toks[start..] {
        match tok {
            Token::Punct('{') => {
                depth += 1;
                expect_head = depth == 1;
            }
            Token::Punct('}') => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            Token::Punct(',') if depth == 1 => expect_head = true,
            Token::Ident(word) if expect_head && depth == 1 => {
                heads.push((word.clone(), *line));
                expect_head = false;
            }
            _ => {
                if depth == 1 {
                    expect_head = false;
                }
            }
        }
    }
    heads
}

/// Whether the tokens start with `#[cfg(test)]`.
fn is_cfg_test(toks: &[(Token, usize)]) -> bool {
    let want = [
        Token::Punct('#'),
        Token::Punct('['),
        Token::Ident("cfg".into()),
        Token::Punct('('),
        Token::Ident("test".into()),
        Token::Punct(')'),
        Token::Punct(']'),
    ];
    toks.len() >= want.len() && toks.iter().zip(&want).all(|((t, _), w)| t == w)
}

/// The index just past the item starting at `start`: at its `;` if it ends before any block,
/// or past the `}` that closes its first block.
fn skip_item(toks: &[(Token, usize)], start: usize) -> usize {
    let mut depth = 0usize;
    let mut i = start;
    while i < toks.len() {
        match toks[i].0 {
            Token::Punct(';') if depth == 0 => return i + 1,
            Token::Punct('{') => depth += 1,
            Token::Punct('}') => {
                depth = depth.saturating_sub(1);
                if depth == 0 {
                    return i + 1;
                }
            }
            _ => {}
        }
        i += 1;
    }
    i
}

/// The names the crate root re-exports, each with the top-level module it comes from
/// (`pub use error::Error;` → `Error` → `error`).
fn root_reexports(lib: &str, modules: &BTreeSet<String>) -> BTreeMap<String, String> {
    let toks = tokens(lib);
    let mut map = BTreeMap::new();
    let mut i = 0;
    while i + 2 < toks.len() {
        if toks[i].0 == Token::Ident("pub".into())
            && toks[i + 1].0 == Token::Ident("use".into())
            && let Token::Ident(module) = &toks[i + 2].0
        {
            let mut j = i + 3;
            while j < toks.len() && toks[j].0 != Token::Punct(';') {
                if let Token::Ident(name) = &toks[j].0
                    && modules.contains(module)
                    && name != "self"
                {
                    map.insert(name.clone(), module.clone());
                }
                j += 1;
            }
            i = j;
            continue;
        }
        i += 1;
    }
    map
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut paths: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    paths.sort();
    for path in paths {
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

impl ModuleGraph {
    /// The graph of the crate whose source folder is `src` (with `lib.rs` as its root), leaving
    /// out the files and folders in `skip` (relative to `src`: another crate's root such as a
    /// binary's `main.rs` and its modules).
    pub fn read(src: &Path, skip: &[&str]) -> std::io::Result<Self> {
        let mut files = Vec::new();
        rust_files(src, &mut files);
        let files: Vec<PathBuf> = files
            .into_iter()
            .filter(|f| {
                let rel = f.strip_prefix(src).unwrap_or(f);
                !skip.iter().any(|s| rel.starts_with(s))
            })
            .collect();
        let mut graph = ModuleGraph::default();
        for f in &files {
            let rel = f.strip_prefix(src).unwrap_or(f);
            if let Some(top) = module_path(rel).first() {
                graph.modules.insert(top.clone());
            }
        }
        let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap_or_default();
        let reexports = root_reexports(&lib, &graph.modules);
        for f in &files {
            let rel = f.strip_prefix(src).unwrap_or(f).to_path_buf();
            let path = module_path(&rel);
            let Some(own) = path.first().cloned() else {
                continue;
            };
            let text = std::fs::read_to_string(f)?;
            graph.scan(&own, &path, &rel, &text, &reexports);
        }
        Ok(graph)
    }

    fn add(&mut self, from: &str, to: &str, file: &Path, line: usize) {
        if from != to && self.modules.contains(to) {
            self.edges
                .entry((from.to_string(), to.to_string()))
                .or_insert_with(|| Place { file: file.to_path_buf(), line });
        }
    }

    /// Adds an edge from `own` to every module that `text` (the file `rel`, module path `path`)
    /// names through `crate::` or through enough `super::` to leave `own`; names re-exported by
    /// the crate root are followed to their module. `#[cfg(test)]` items are skipped.
    fn scan(&mut self, own: &str, path: &[String], rel: &Path, text: &str, reexports: &BTreeMap<String, String>) {
        let toks = tokens(text);
        // Inline modules: (brace depth at which the block closes).
        let mut inline: Vec<usize> = Vec::new();
        let mut depth = 0usize;
        let mut i = 0;
        while i < toks.len() {
            if is_cfg_test(&toks[i..]) {
                i = skip_item(&toks, i + 7);
                continue;
            }
            match &toks[i].0 {
                Token::Punct('{') => depth += 1,
                Token::Punct('}') => {
                    if inline.last() == Some(&depth) {
                        inline.pop();
                    }
                    depth = depth.saturating_sub(1);
                }
                Token::Ident(w) if w == "mod" => {
                    if let (Some((Token::Ident(_), _)), Some((Token::Punct('{'), _))) =
                        (toks.get(i + 1), toks.get(i + 2))
                    {
                        inline.push(depth + 1);
                    }
                }
                Token::Ident(w) if w == "crate" => {
                    let after_dollar = i > 0 && toks[i - 1].0 == Token::Punct('$');
                    if !after_dollar && toks.get(i + 1).map(|t| &t.0) == Some(&Token::Path) {
                        self.add_heads(own, &toks, i + 2, rel, reexports);
                    }
                }
                Token::Ident(w) if w == "super" => {
                    let before_is_path = i > 0 && toks[i - 1].0 == Token::Path;
                    if !before_is_path {
                        let (ups, j) = supers(&toks, i);
                        if ups > 0 && ups >= path.len() + inline.len() {
                            self.add_heads(own, &toks, j, rel, reexports);
                        }
                        i = j.max(i + 1);
                        continue;
                    }
                }
                _ => {}
            }
            i += 1;
        }
    }

    /// The edges from `own` to the module named at `toks[at]`: one name, or each head of a
    /// `{...}` group; a name the crate root re-exports stands for its module.
    fn add_heads(
        &mut self,
        own: &str,
        toks: &[(Token, usize)],
        at: usize,
        rel: &Path,
        reexports: &BTreeMap<String, String>,
    ) {
        let target = |name: &str| reexports.get(name).cloned().unwrap_or_else(|| name.to_string());
        match toks.get(at) {
            Some((Token::Ident(name), line)) => self.add(own, &target(name), rel, *line),
            Some((Token::Punct('{'), _)) => {
                for (name, line) in group_heads(toks, at) {
                    self.add(own, &target(&name), rel, line);
                }
            }
            _ => {}
        }
    }

    /// The circles: every strongly connected component of more than one module, sorted.
    pub fn cycles(&self) -> Vec<Vec<String>> {
        let names: Vec<&String> = self.modules.iter().collect();
        let index: BTreeMap<&String, usize> = names.iter().enumerate().map(|(k, n)| (*n, k)).collect();
        let m = names.len();
        let mut reach = vec![vec![false; m]; m];
        for (from, to) in self.edges.keys() {
            reach[index[from]][index[to]] = true;
        }
        for k in 0..m {
            for a in 0..m {
                if reach[a][k] {
                    for b in 0..m {
                        if reach[k][b] {
                            reach[a][b] = true;
                        }
                    }
                }
            }
        }
        let mut seen = vec![false; m];
        let mut out = Vec::new();
        for a in 0..m {
            if seen[a] {
                continue;
            }
            let component: Vec<usize> = (0..m).filter(|&b| b == a || (reach[a][b] && reach[b][a])).collect();
            for &b in &component {
                seen[b] = true;
            }
            if component.len() > 1 {
                out.push(component.iter().map(|&b| names[b].clone()).collect());
            }
        }
        out
    }

    /// The edges inside one circle, one per line with the place it was found.
    pub fn describe(&self, cycle: &[String]) -> String {
        let mut text = String::new();
        for ((from, to), place) in &self.edges {
            if cycle.contains(from) && cycle.contains(to) {
                text.push_str(&format!("    {from} -> {to}  ({}:{})\n", place.file.display(), place.line));
            }
        }
        text
    }
}

/// How many `super::` start at `toks[i]`, and the index of the token after them.
fn supers(toks: &[(Token, usize)], i: usize) -> (usize, usize) {
    let (mut ups, mut j) = (0, i);
    while toks.get(j).map(|t| &t.0) == Some(&Token::Ident("super".into()))
        && toks.get(j + 1).map(|t| &t.0) == Some(&Token::Path)
    {
        ups += 1;
        j += 2;
    }
    (ups, j)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comments_strings_and_groups() {
        let text = "// crate::a::x\n/// [`crate::b`]\n/* crate::c */ let s = \"crate::d\";\n\
                    use crate::{e::F, g, h::{i, j}};\nfn f<'a>(c: char) { let _ = 'x'; crate::k::l(); }\n\
                    mod tests { use super::m; }\n#[cfg(test)]\nmod t { use crate::a; }\n";
        let mut graph = ModuleGraph::default();
        for m in ["a", "b", "c", "d", "e", "g", "h", "i", "k", "m", "own"] {
            graph.modules.insert(m.into());
        }
        graph.scan("own", &["own".to_string()], Path::new("own.rs"), text, &BTreeMap::new());
        let to: Vec<&str> = graph.edges.keys().map(|(_, t)| t.as_str()).collect();
        assert_eq!(to, ["e", "g", "h", "k"]);
    }

    #[test]
    fn super_climbs_out() {
        let mut graph = ModuleGraph::default();
        for m in ["a", "b"] {
            graph.modules.insert(m.into());
        }
        let path = ["a".to_string(), "inner".to_string()];
        graph.scan("a", &path, Path::new("a/inner.rs"), "use super::super::b;\n", &BTreeMap::new());
        assert!(graph.edges.contains_key(&("a".into(), "b".into())));
        graph.edges.clear();
        graph.scan("a", &path, Path::new("a/inner.rs"), "use super::b;\n", &BTreeMap::new());
        assert!(graph.edges.is_empty());
    }
}
