//! Snapshots of the generated source of two small shipped molecules.
//!
//! A snapshot is a regression guard, not evidence of correctness (the numbers are checked
//! against finite differences and closed forms in the workspace's `tests/`). It makes every
//! change to the generated code visible in review: run `cargo insta review` after an intended
//! change. CI runs with `INSTA_UPDATE=no`, so a stale snapshot fails instead of being rewritten.

fn generated(name: &str) -> String {
    let path = format!("{}/../molecules/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).expect("shipped molecule");
    rovib_codegen::generate_molecule(&format!("molecules/{name}.toml"), &text).expect("valid").source
}

#[test]
fn h2o_generated_source() {
    insta::assert_snapshot!("h2o", generated("h2o"));
}

#[test]
fn h2o_rigid_generated_source() {
    insta::assert_snapshot!("h2o_rigid", generated("h2o_rigid"));
}

#[test]
fn generation_is_deterministic() {
    // Byte for byte, run after run: emission order never depends on hash-map iteration.
    for name in ["h2o", "h2o_rigid"] {
        assert_eq!(generated(name), generated(name));
    }
}
