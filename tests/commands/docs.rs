//! The documents stay true to the code: the README, the figure pages and the user guide under
//! `docs/src` (an mdBook).
//!
//! * Every fenced ` ```toml ` block is checked, by its marker:
//!   - ` ```toml scene `: parses as a scene (and its `[ensemble]` table as an ensemble);
//!   - ` ```toml molecule `: generates as a molecule definition;
//!   - ` ```toml scene-part FILE ` / ` ```toml molecule-part FILE `: a few tables of a scene or a
//!     definition; its keys replace or join those of FILE (a path from the repository's root),
//!     and the whole is checked as a scene or a definition;
//!   - ` ```toml cargo `: a Cargo manifest snippet; parses as TOML and names the `rovib` crate.
//!
//!   A ` ```toml ` block without a marker, or with any other, is an error, so no block is skipped.
//! * Every `rovib <command> --flag` named in the command-line reference exists in that command's
//!   `--help`, and every flag of every command's `--help` is named there.
//! * Every relative link and image of the pages points to a file that exists, every page of the
//!   guide is in its `SUMMARY.md`, and every `{{#include}}` names a file that exists. mdBook
//!   itself does not check links between pages.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A fenced code block: the file, the line of its opening fence, its info string and its text.
struct Block {
    file: String,
    line: usize,
    info: String,
    text: String,
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// The guide's pages, relative to the workspace root, sorted.
fn guide_pages() -> Vec<String> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|x| x == "md") {
                out.push(path);
            }
        }
    }
    let mut paths = Vec::new();
    walk(&root().join("docs/src"), &mut paths);
    let mut pages: Vec<String> = paths
        .iter()
        .map(|p| p.strip_prefix(root()).expect("under the root").to_string_lossy().replace('\\', "/"))
        .collect();
    pages.sort();
    pages
}

/// Every Markdown document the checks cover: the README, the figure pages, the Python package's
/// README and the guide.
fn documents() -> Vec<String> {
    let mut docs: Vec<String> =
        ["README.md", "BENCHMARKS.md", "STABILITY.md", "python/README.md"].iter().map(|s| s.to_string()).collect();
    docs.extend(guide_pages());
    docs
}

/// The fenced code blocks of a Markdown text (``` fences; the info string is what follows the
/// opening fence).
fn blocks(file: &str, text: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut open: Option<Block> = None;
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        match open.as_mut() {
            None => {
                if let Some(info) = trimmed.strip_prefix("```") {
                    open = Some(Block {
                        file: file.to_owned(),
                        line: i + 1,
                        info: info.trim().to_owned(),
                        text: String::new(),
                    });
                }
            }
            Some(block) => {
                if trimmed.starts_with("```") {
                    out.push(open.take().expect("an open block"));
                } else {
                    block.text.push_str(line);
                    block.text.push('\n');
                }
            }
        }
    }
    assert!(open.is_none(), "{file}: a code block is not closed");
    out
}

/// What a ```toml block is checked as (its marker).
#[derive(Debug, PartialEq)]
enum Marker {
    Scene,
    Molecule,
    /// Tables of a scene, joined to the scene file at this path.
    ScenePart(String),
    /// Tables of a definition, joined to the definition file at this path.
    MoleculePart(String),
    /// A Cargo manifest snippet.
    Cargo,
}

/// The marker of a ```toml block, `None` for a block of another language; a ```toml block
/// without a known marker is an error naming the block.
fn toml_marker(block: &Block) -> Option<Marker> {
    let mut words = block.info.split([' ', ',']).filter(|w| !w.is_empty());
    if words.next() != Some("toml") {
        return None;
    }
    let place = format!("{}:{}", block.file, block.line);
    let base = |words: &mut dyn Iterator<Item = &str>, kind: &str| match words.next() {
        Some(path) if root().join(path).is_file() => path.to_owned(),
        Some(path) => panic!("{place}: ```toml {kind}-part {path}: no file {path} in the repository"),
        None => {
            panic!("{place}: ```toml {kind}-part needs the file it is a part of: ```toml {kind}-part scenes/h2o.toml")
        }
    };
    Some(match words.next() {
        Some("scene") => Marker::Scene,
        Some("molecule") => Marker::Molecule,
        Some("scene-part") => Marker::ScenePart(base(&mut words, "scene")),
        Some("molecule-part") => Marker::MoleculePart(base(&mut words, "molecule")),
        Some("cargo") => Marker::Cargo,
        other => panic!(
            "{place}: {}: write ```toml scene, ```toml molecule, ```toml scene-part FILE, ```toml molecule-part FILE or ```toml cargo",
            match other {
                Some(m) => format!("unknown marker `{m}` on a toml block"),
                None => "a toml block without a marker is not checked".to_owned(),
            }
        ),
    })
}

/// `base`'s text with the keys of `part` replacing or joining its own, edited in place so that
/// the order of entries (which matters for a definition's `[expressions]` and `[functions]`) and
/// everything else of `base` stay. Tables are joined key by key, at every depth; a key of `part`
/// that `base` has replaces its value, a new one is written after the last entry of its table
/// (a new table at the end of the file).
fn joined(base: &str, part: &str) -> Result<String, String> {
    use toml::de::{DeTable, DeValue};
    type Entry<'a> = (&'a toml::Spanned<toml::de::DeString<'a>>, &'a toml::Spanned<DeValue<'a>>);
    /// The entries of `t` in the order in which the text gives them.
    fn in_order<'a>(t: &'a DeTable<'a>) -> Vec<Entry<'a>> {
        let mut entries: Vec<_> = t.iter().collect();
        entries.sort_by_key(|(k, _)| k.span().start);
        entries
    }
    /// The text of one `key = value` entry of `text`.
    fn entry(text: &str, (k, v): Entry<'_>) -> String {
        text[k.span().start..v.span().end].to_owned()
    }
    fn join(
        base: &str,
        part: &str,
        into: &DeTable<'_>,
        from: &DeTable<'_>,
        path: &str,
        edits: &mut Vec<(std::ops::Range<usize>, String)>,
        appended: &mut String,
    ) {
        let end = into.values().map(|v| v.span().end).max();
        for (k, v) in in_order(from) {
            let key = k.get_ref().as_ref();
            let inline = |s: &str, v: &toml::Spanned<DeValue<'_>>| s[v.span()].starts_with('{');
            match (into.get(key), v.get_ref()) {
                (Some(old), DeValue::Table(t)) if !inline(part, v) => match old.get_ref() {
                    DeValue::Table(o) if !inline(base, old) => {
                        join(base, part, o, t, &format!("{path}{key}."), edits, appended)
                    }
                    _ => edits.push((old.span(), part[v.span()].to_owned())),
                },
                (Some(old), _) => edits.push((old.span(), part[v.span()].to_owned())),
                (None, DeValue::Table(t)) if !inline(part, v) => {
                    appended.push_str(&format!("\n[{path}{key}]\n"));
                    for e in in_order(t) {
                        appended.push_str(&entry(part, e));
                        appended.push('\n');
                    }
                }
                (None, _) if path.is_empty() => edits.push((0..0, entry(part, (k, v)) + "\n")),
                (None, _) => edits.push((end.map_or(0..0, |e| e..e), format!("\n{}", entry(part, (k, v))))),
            }
        }
    }
    let into = DeTable::parse(base).map_err(|e| format!("the base file: {e}"))?;
    let from = DeTable::parse(part).map_err(|e| format!("the block: {e}"))?;
    let (mut edits, mut appended) = (Vec::new(), String::new());
    join(base, part, into.get_ref(), from.get_ref(), "", &mut edits, &mut appended);
    let mut text = base.to_owned();
    edits.sort_by_key(|(range, _)| std::cmp::Reverse(range.start));
    for (range, new) in edits {
        text.replace_range(range, &new);
    }
    Ok(text + &appended)
}

/// `molecules/NAME.toml` for a definition whose `name = "NAME"` line is its first of that key.
fn molecule_path(text: &str) -> String {
    let name = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("name").map(str::trim).and_then(|r| r.strip_prefix('=')))
        .map(|r| r.trim().trim_matches('"').to_owned())
        .unwrap_or_default();
    format!("molecules/{name}.toml")
}

/// Checks one marked block; the error names the document and the block's line.
fn check_block(block: &Block, marker: &Marker) -> Result<(), String> {
    let name = format!("{} (block at line {})", block.file, block.line);
    match marker {
        Marker::Scene => check_scene(&name, &block.text),
        // The generator requires the name to be the file's stem: the block stands for
        // molecules/NAME.toml.
        Marker::Molecule => check_molecule(&molecule_path(&block.text), &block.text),
        Marker::ScenePart(base) => check_scene(&format!("{name} joined to {base}"), &joined(&read(base), &block.text)?),
        Marker::MoleculePart(base) => check_molecule(base, &joined(&read(base), &block.text)?),
        Marker::Cargo => {
            let manifest: toml::Table = block.text.parse().map_err(|e| format!("{name}: {e}"))?;
            let names_rovib = ["dependencies", "dev-dependencies", "build-dependencies"]
                .iter()
                .any(|t| manifest.get(*t).and_then(|d| d.get("rovib")).is_some());
            if names_rovib {
                Ok(())
            } else {
                Err(format!("{name}: a Cargo snippet that does not name the `rovib` crate"))
            }
        }
    }
}

fn check_scene(name: &str, text: &str) -> Result<(), String> {
    let scene = rovib::scene::parse_scene(name, text).map_err(|e| e.to_string())?;
    if scene.ensemble {
        rovib::ensemble::scene::parse_ensemble(&scene).map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn check_molecule(path: &str, text: &str) -> Result<(), String> {
    rovib_codegen::generate_molecule(path, text)
        .map(|_| ())
        .map_err(|errors| errors.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("\n"))
}

#[test]
fn every_marked_scene_and_molecule_block_parses() {
    let (mut scenes, mut molecules, mut parts) = (0, 0, 0);
    let mut failures = Vec::new();
    for doc in documents() {
        for block in blocks(&doc, &read(&doc)) {
            let Some(marker) = toml_marker(&block) else { continue };
            match marker {
                Marker::Scene => scenes += 1,
                Marker::Molecule => molecules += 1,
                _ => parts += 1,
            }
            if let Err(e) = check_block(&block, &marker) {
                failures.push(format!("{}:{} (```{}):\n{e}", block.file, block.line, block.info));
            }
        }
    }
    assert!(failures.is_empty(), "blocks that do not parse:\n\n{}", failures.join("\n\n"));
    // The README's scene, the tutorials' scenes and definitions: a marker lost in an edit would
    // otherwise make this test pass on nothing.
    assert!(
        scenes >= 5 && molecules >= 2 && parts >= 5,
        "only {scenes} scene, {molecules} molecule and {parts} part blocks found"
    );
}

#[test]
fn a_broken_block_is_caught() {
    let scene = Block {
        file: "example.md".into(),
        line: 1,
        info: "toml scene".into(),
        text: "molecule = \"h2o\"\n[initial]\nq = { r1 = 1.0 }\n[run]\nend = 10.0\noutput_intervall = 1.0\n".into(),
    };
    let e = check_block(&scene, &Marker::Scene).expect_err("a misspelt key");
    assert!(e.contains("output_intervall"), "{e}");
    let molecule = Block {
        file: "example.md".into(),
        line: 1,
        info: "toml molecule".into(),
        text: read("molecules/h2o.toml").replace("r1 * sin(half * alpha)", "r1 * sin(half * alpah)"),
    };
    let e = check_block(&molecule, &Marker::Molecule).expect_err("an unknown name");
    assert!(e.contains("alpah"), "{e}");
    let part = Block {
        file: "example.md".into(),
        line: 1,
        info: "toml scene-part scenes/n2ar_pair.toml".into(),
        text: "[spectrum]\nestimater = \"pair\"\n".into(),
    };
    let e = check_block(&part, &toml_marker(&part).unwrap()).expect_err("a misspelt key in a part");
    assert!(e.contains("estimater"), "{e}");
    let part = Block {
        file: "example.md".into(),
        line: 1,
        info: "toml molecule-part codegen/tests/fixtures/co2ar/co2ar.toml".into(),
        text: "[expressions]\nr_c_ar = \"sqrt(pow(x_ar, 2) + pow(z_arr, 2))\"\n".into(),
    };
    let e = check_block(&part, &toml_marker(&part).unwrap()).expect_err("an unknown name in a part");
    assert!(e.contains("z_arr"), "{e}");
    let cargo = Block {
        file: "example.md".into(),
        line: 1,
        info: "toml cargo".into(),
        text: "[dependencies]\nrovb = \"1\"\n".into(),
    };
    assert!(check_block(&cargo, &Marker::Cargo).is_err());
}

#[test]
#[should_panic(expected = "unknown marker `scnee`")]
fn a_misspelt_marker_is_an_error() {
    let block = Block { file: "example.md".into(), line: 3, info: "toml scnee".into(), text: String::new() };
    toml_marker(&block);
}

#[test]
#[should_panic(expected = "a toml block without a marker is not checked")]
fn a_block_without_a_marker_is_an_error() {
    let block = Block { file: "example.md".into(), line: 3, info: "toml".into(), text: String::new() };
    toml_marker(&block);
}

#[test]
#[should_panic(expected = "no file scenes/nothing.toml")]
fn a_part_of_a_missing_file_is_an_error() {
    let block = Block {
        file: "example.md".into(),
        line: 3,
        info: "toml scene-part scenes/nothing.toml".into(),
        text: String::new(),
    };
    toml_marker(&block);
}

/// `rovib <args> --help`.
fn help(args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_rovib")).args(args).arg("--help").output().expect("rovib runs");
    assert!(out.status.success(), "rovib {args:?} --help failed: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).expect("UTF-8 help")
}

/// The long flags (`--name`) in a text, without `--help` and `--version`.
fn long_flags(text: &str) -> BTreeSet<String> {
    let mut flags = BTreeSet::new();
    for (i, _) in text.match_indices("--") {
        let name: String = text[i + 2..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '-').collect();
        let before = text[..i].chars().next_back();
        if !name.is_empty() && before.is_none_or(|c| c.is_whitespace() || c == '[' || c == '`' || c == '(') {
            flags.insert(name);
        }
    }
    flags.remove("help");
    flags.remove("version");
    flags
}

/// The `rovib <command> ... --flag` spans of the command-line reference, as (command, flag).
fn documented_flags(reference: &str) -> BTreeSet<(String, String)> {
    let mut out = BTreeSet::new();
    for span in reference.split('`').skip(1).step_by(2) {
        let mut words = span.split_whitespace();
        if words.next() != Some("rovib") {
            continue;
        }
        let Some(command) = words.next() else { continue };
        for flag in long_flags(span) {
            out.insert((command.to_owned(), flag));
        }
    }
    out
}

/// The subcommands `rovib --help` lists.
fn commands() -> Vec<String> {
    let text = help(&[]);
    let list = text.split("Commands:").nth(1).expect("rovib --help lists its commands");
    list.lines()
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .map(str::to_owned)
        .collect()
}

#[test]
fn the_cli_reference_names_every_flag_and_only_real_ones() {
    let reference = read("docs/src/reference/cli.md");
    let documented = documented_flags(&reference);
    let commands = commands();
    assert!(commands.len() >= 6, "{commands:?}");
    let mut missing = Vec::new();
    let mut unknown = Vec::new();
    let mut real = BTreeSet::new();
    for command in &commands {
        assert!(
            reference.contains(&format!("## `rovib {command}`")),
            "docs/src/reference/cli.md has no section \"## `rovib {command}`\""
        );
        for flag in long_flags(&help(&[command])) {
            if !documented.contains(&(command.clone(), flag.clone())) {
                missing.push(format!("rovib {command} --{flag}"));
            }
            real.insert((command.clone(), flag));
        }
    }
    for (command, flag) in &documented {
        if !real.contains(&(command.clone(), flag.clone())) {
            unknown.push(format!("rovib {command} --{flag}"));
        }
    }
    assert!(missing.is_empty(), "flags in --help that docs/src/reference/cli.md does not name: {missing:?}");
    assert!(unknown.is_empty(), "flags docs/src/reference/cli.md names that --help does not have: {unknown:?}");
}

#[test]
fn a_flag_that_does_not_exist_is_caught() {
    let documented = documented_flags("| `rovib run --out DIR` | ... |\n| `rovib run --outt DIR` | ... |");
    assert!(documented.contains(&("run".to_owned(), "outt".to_owned())));
    assert!(!long_flags(&help(&["run"])).contains("outt"));
}

/// The targets of the Markdown links and images `[..](target)` of a text, outside code, with
/// their line numbers.
fn links(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut in_code = false;
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code {
            continue;
        }
        // Drop inline code spans.
        let prose: String = line.split('`').step_by(2).collect::<Vec<_>>().join(" ");
        for (j, _) in prose.match_indices("](") {
            let rest = &prose[j + 2..];
            if let Some(end) = rest.find(')') {
                out.push((i + 1, rest[..end].trim().to_owned()));
            }
        }
    }
    out
}

/// The broken relative links of one document: each as "file:line: target".
fn broken_links(doc: &str, text: &str) -> Vec<String> {
    let dir = Path::new(doc).parent().unwrap_or(Path::new(""));
    let mut broken = Vec::new();
    for (line, target) in links(text) {
        if target.is_empty() || target.contains("://") || target.starts_with('#') || target.starts_with("mailto:") {
            continue;
        }
        let path = target.split('#').next().unwrap_or_default();
        if !root().join(dir).join(path).exists() {
            broken.push(format!("{doc}:{line}: {target}"));
        }
    }
    for (i, line) in text.lines().enumerate() {
        if let Some(start) = line.find("{{#include ") {
            let arg = line[start + 11..].split("}}").next().unwrap_or_default();
            let path = arg.split(':').next().unwrap_or_default().trim();
            if !root().join(dir).join(path).exists() {
                broken.push(format!("{doc}:{}: {{{{#include {path}}}}}", i + 1));
            }
        }
    }
    broken
}

#[test]
fn every_relative_link_and_include_resolves() {
    let mut broken = Vec::new();
    for doc in documents() {
        broken.extend(broken_links(&doc, &read(&doc)));
    }
    assert!(broken.is_empty(), "links to files that do not exist:\n{}", broken.join("\n"));
}

#[test]
fn a_broken_link_is_caught() {
    let text = "See [the scene reference](reference/scene.md) and [nothing](reference/nothing.md).\n\
                ```\n[not a link](in/code.md)\n```\n{{#include ../../no_such_file.md}}\n";
    let broken = broken_links("docs/src/page.md", text);
    assert_eq!(
        broken,
        ["docs/src/page.md:1: reference/nothing.md", "docs/src/page.md:5: {{#include ../../no_such_file.md}}"]
    );
}

#[test]
fn every_page_of_the_guide_is_in_its_summary() {
    let summary = read("docs/src/SUMMARY.md");
    let listed: BTreeSet<String> = links(&summary).into_iter().map(|(_, t)| format!("docs/src/{t}")).collect();
    let pages: BTreeSet<String> = guide_pages().into_iter().filter(|p| p != "docs/src/SUMMARY.md").collect();
    let orphans: Vec<_> = pages.difference(&listed).collect();
    assert!(orphans.is_empty(), "pages of docs/src that SUMMARY.md does not list: {orphans:?}");
    let missing: Vec<_> = listed.difference(&pages).collect();
    assert!(missing.is_empty(), "SUMMARY.md lists pages that do not exist: {missing:?}");
}

#[test]
fn the_readme_is_a_front_page() {
    let size = read("README.md").len();
    assert!(size <= 15 * 1024, "README.md is {size} bytes; keep it a front page of at most 15 KB");
    let readme = read("README.md");
    for command in ["cargo run --release -- run scenes/h2o.toml", "cargo test"] {
        assert!(readme.contains(command), "README.md no longer shows `{command}`, which .ci/run runs");
    }
}

/// The pages whose Rust blocks run as doctests: those `src/lib.rs` includes under
/// `#[cfg(doctest)]`.
fn doctested_pages() -> BTreeSet<String> {
    read("src/lib.rs")
        .lines()
        .filter_map(|l| l.trim().strip_prefix("#[doc = include_str!(\"../")?.strip_suffix("\")]"))
        .map(str::to_owned)
        .collect()
}

/// Every code block says its language (a block without one is Rust to rustdoc and plain text to
/// mdBook), and every Rust block is on a page whose blocks run as doctests.
#[test]
fn every_block_names_its_language_and_every_rust_block_is_compiled() {
    let doctested = doctested_pages();
    assert!(doctested.contains("README.md"), "no doctested pages found in src/lib.rs: {doctested:?}");
    let mut failures = Vec::new();
    for doc in documents() {
        for block in blocks(&doc, &read(&doc)) {
            let language = block.info.split([' ', ',']).next().unwrap_or("");
            if language.is_empty() {
                failures.push(format!("{}:{}: a code block without a language (```text, ```sh, ...)", doc, block.line));
            } else if language == "rust" && !doctested.contains(&doc) {
                failures.push(format!(
                    "{}:{}: a Rust block on a page that src/lib.rs does not include as a doctest",
                    doc, block.line
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}
