//! The documents stay true to the code: the README, the figure pages and the user guide under
//! `docs/src` (an mdBook).
//!
//! * Every fenced block marked ` ```toml scene ` parses as a scene (and its `[ensemble]` table as
//!   an ensemble), every block marked ` ```toml molecule ` generates as a molecule definition. A
//!   ` ```toml ` block with any other marker is an error, so a misspelt marker is not skipped.
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

/// The marker of a ```toml block: `Some("scene")`, `Some("molecule")`, `None` for a plain
/// ```toml block; anything else is an error naming the block.
fn toml_marker(block: &Block) -> Option<&str> {
    let mut words = block.info.split([' ', ',']).filter(|w| !w.is_empty());
    if words.next() != Some("toml") {
        return None;
    }
    match words.next() {
        None => None,
        Some(m @ ("scene" | "molecule")) => Some(m),
        Some(other) => panic!(
            "{}:{}: unknown marker `{other}` on a toml block: write ```toml scene, ```toml molecule or plain ```toml",
            block.file, block.line
        ),
    }
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
fn check_block(block: &Block, marker: &str) -> Result<(), String> {
    let name = format!("{} (block at line {})", block.file, block.line);
    match marker {
        "scene" => {
            let scene = rovib::scene::parse_scene(&name, &block.text).map_err(|e| e.to_string())?;
            if scene.ensemble {
                rovib::ensemble::scene::parse_ensemble(&scene).map_err(|e| e.to_string())?;
            }
            Ok(())
        }
        // The generator requires the name to be the file's stem: the block stands for
        // molecules/NAME.toml.
        "molecule" => rovib_codegen::generate_molecule(&molecule_path(&block.text), &block.text)
            .map(|_| ())
            .map_err(|errors| errors.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("\n")),
        _ => unreachable!("markers are checked by toml_marker"),
    }
}

#[test]
fn every_marked_scene_and_molecule_block_parses() {
    let (mut scenes, mut molecules) = (0, 0);
    let mut failures = Vec::new();
    for doc in documents() {
        for block in blocks(&doc, &read(&doc)) {
            let Some(marker) = toml_marker(&block) else { continue };
            match marker {
                "scene" => scenes += 1,
                _ => molecules += 1,
            }
            if let Err(e) = check_block(&block, marker) {
                failures.push(format!("{}:{} (```toml {marker}):\n{e}", block.file, block.line));
            }
        }
    }
    assert!(failures.is_empty(), "blocks that do not parse:\n\n{}", failures.join("\n\n"));
    // The README's scene, the tutorials' scenes and definitions: a marker lost in an edit would
    // otherwise make this test pass on nothing.
    assert!(scenes >= 5 && molecules >= 2, "only {scenes} scene and {molecules} molecule blocks found");
}

#[test]
fn a_broken_block_is_caught() {
    let scene = Block {
        file: "example.md".into(),
        line: 1,
        info: "toml scene".into(),
        text: "molecule = \"h2o\"\n[initial]\nq = { r1 = 1.0 }\n[run]\nend = 10.0\noutput_intervall = 1.0\n".into(),
    };
    let e = check_block(&scene, "scene").expect_err("a misspelt key");
    assert!(e.contains("output_intervall"), "{e}");
    let molecule = Block {
        file: "example.md".into(),
        line: 1,
        info: "toml molecule".into(),
        text: read("molecules/h2o.toml").replace("r1 * sin(half * alpha)", "r1 * sin(half * alpah)"),
    };
    let e = check_block(&molecule, "molecule").expect_err("an unknown name");
    assert!(e.contains("alpah"), "{e}");
}

#[test]
#[should_panic(expected = "unknown marker `scnee`")]
fn a_misspelt_marker_is_an_error() {
    let block = Block { file: "example.md".into(), line: 3, info: "toml scnee".into(), text: String::new() };
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
