//! Snapshots of the generated source of two small shipped molecules.
//!
//! A snapshot is a regression guard, not evidence of correctness (the numbers are checked
//! against finite differences and closed forms in the workspace's `tests/`). It makes every
//! change to the generated code visible in review: run `cargo insta review` after an intended
//! change. CI runs with `INSTA_UPDATE=no`, so a stale snapshot fails instead of being rewritten.
//!
//! The rigid molecule's file is small and snapshotted whole. Flexible water's file is ~850
//! lines, most of them the four kinetic functions that nobody reads line by line: it is
//! snapshotted as an outline (everything but those bodies, which a reader can check by eye)
//! plus a digest (each function's operation counts and a hash of each elided body), so a change
//! in the big bodies shows up as a changed count or hash in a snapshot small enough to review.

/// Functions whose bodies the outline replaces by their digest.
const ELIDED: [&str; 3] = ["kinetic", "kinetic_energy_gradient", "kinetic_and_gradient"];

fn generated(name: &str) -> rovib_codegen::GeneratedMolecule {
    let path = format!("{}/../molecules/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("shipped molecule");
    rovib_codegen::generate_molecule(&format!("molecules/{name}.toml"), &text).expect("valid")
}

/// FNV-1a, 64 bit: a hash that is the same on every platform and toolchain.
fn fnv1a(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3))
}

/// The source with the bodies of the [`ELIDED`] functions replaced by a line giving their
/// length and hash.
fn outline(source: &str) -> String {
    let mut out = String::new();
    let mut lines = source.lines();
    while let Some(line) = lines.next() {
        out.push_str(line);
        out.push('\n');
        let name = line.strip_prefix("    fn ").map(|rest| rest.split(['(', '<']).next().unwrap_or_default());
        if let Some(name) = name.filter(|n| ELIDED.contains(n)) {
            // Skip the rest of the signature, then the body up to the closing brace at indent 4.
            let mut body = String::new();
            let mut open = line.ends_with('{');
            for l in lines.by_ref() {
                if !open {
                    out.push_str(l);
                    out.push('\n');
                    open = l.ends_with('{');
                    continue;
                }
                if l == "    }" {
                    out.push_str(&format!(
                        "        // {name}: {} lines elided, fnv1a64 {:#018x}\n    }}\n",
                        body.lines().count(),
                        fnv1a(&body)
                    ));
                    break;
                }
                body.push_str(l);
                body.push('\n');
            }
        }
    }
    out
}

#[test]
fn h2o_rigid_generated_source() {
    insta::assert_snapshot!("h2o_rigid", generated("h2o_rigid").source);
}

#[test]
fn h2o_generated_outline() {
    let m = generated("h2o");
    let outline = outline(&m.source);
    for name in ELIDED {
        assert!(outline.contains(&format!("// {name}: ")), "{name} was not found to elide");
    }
    insta::assert_snapshot!("h2o_outline", outline);
}

#[test]
fn h2o_generated_digest() {
    let m = generated("h2o");
    let digest = format!("{} lines, fnv1a64 {:#018x}\n\n{}", m.lines(), fnv1a(&m.source), m.stats_table());
    insta::assert_snapshot!("h2o_digest", digest);
}

#[test]
fn generation_is_deterministic() {
    // Byte for byte, run after run: emission order never depends on hash-map iteration.
    for name in ["h2o", "h2o_rigid"] {
        assert_eq!(generated(name).source, generated(name).source);
    }
}
