//! Generates Rust for every molecule definition in `molecules/` (see `rovib-codegen`).
//!
//! Thin on purpose: it calls `rovib_codegen::generate`, prints one `rerun-if-changed` per
//! definition, and on a bad definition prints readable errors and exits 1 (never a panic).

use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo::rerun-if-changed=build.rs");
    // The directory itself, so that adding a definition reruns generation.
    println!("cargo::rerun-if-changed=molecules");
    match rovib_codegen::generate(&manifest.join("molecules"), "molecules", &out_dir) {
        Ok(report) => {
            for input in &report.inputs {
                println!("cargo::rerun-if-changed={}", input.display());
            }
        }
        Err(errors) => {
            for e in &errors {
                eprintln!("{e}\n");
            }
            eprintln!(
                "rovib: {} molecule definition{} could not be generated; fix the above and run cargo build again",
                errors.len(),
                if errors.len() == 1 { "" } else { "s" }
            );
            std::process::exit(1);
        }
    }
}
