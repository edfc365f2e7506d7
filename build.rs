//! Generates Rust for every molecule definition in `molecules/` (see `rovib-codegen`).
//!
//! Thin on purpose: it calls `rovib_codegen::generate`, prints one `rerun-if-changed` per
//! definition, warns (`cargo::warning`) about molecules whose generated code is large enough to
//! make rustc slow, and on a bad definition prints readable errors and exits 1 (never a panic).
//!
//! `ROVIB_MOLECULES_DIR`, if set, replaces `molecules/` (for building a private set of
//! molecules without editing the checkout). `ROVIB_KINETIC_JACOBIAN=generated` also generates
//! the symbolic `kinetic_jacobian` (the reference path's ∂a/∂q, ∂A/∂q, ∂I/∂q) instead of the
//! runtime's default, which assembles them from the generated ∂T/∂q; it grows like n³ and is
//! meant for small molecules. `ROVIB_LARGE_MOLECULE_FORMS=expanded` generates large molecules
//! without their size-dependent forms (reverse-mode ∂T/∂q, run-time centre of mass), for
//! measuring what those gain.

use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=ROVIB_MOLECULES_DIR");
    println!("cargo::rerun-if-env-changed=ROVIB_KINETIC_JACOBIAN");
    println!("cargo::rerun-if-env-changed=ROVIB_LARGE_MOLECULE_FORMS");
    let mut options = match std::env::var("ROVIB_KINETIC_JACOBIAN").as_deref() {
        Ok("generated") => rovib_codegen::Options { kinetic_jacobian: true, ..Default::default() },
        Ok("") | Ok("runtime") | Err(_) => rovib_codegen::Options::default(),
        Ok(other) => {
            eprintln!(
                "rovib: ROVIB_KINETIC_JACOBIAN={other:?} is not understood; use `generated` or `runtime` (the default)"
            );
            std::process::exit(1);
        }
    };
    // For measuring what the large-molecule forms gain (BENCHMARKS.md): `expanded` generates every
    // molecule the way small ones are (explicit second derivatives, centre of mass expanded).
    match std::env::var("ROVIB_LARGE_MOLECULE_FORMS").as_deref() {
        Ok("expanded") => {
            options.kinetic_gradient = rovib_codegen::GradientMethod::Direct;
            options.run_time_centre_of_mass_from = usize::MAX;
        }
        Ok("") | Ok("auto") | Err(_) => {}
        Ok(other) => {
            eprintln!(
                "rovib: ROVIB_LARGE_MOLECULE_FORMS={other:?} is not understood; use `auto` (the default) or `expanded`"
            );
            std::process::exit(1);
        }
    }
    let (dir, display) = match std::env::var("ROVIB_MOLECULES_DIR") {
        Ok(d) if !d.is_empty() => (PathBuf::from(&d), d),
        _ => (manifest.join("molecules"), "molecules".to_owned()),
    };
    // The directory itself, so that adding a definition reruns generation.
    println!("cargo::rerun-if-changed={}", dir.display());
    match rovib_codegen::generate_with(&dir, &display, &out_dir, &options) {
        Ok(report) => {
            for input in &report.inputs {
                println!("cargo::rerun-if-changed={}", input.display());
            }
            for warning in report.molecules.iter().filter_map(|m| m.size_warning()) {
                println!("cargo::warning={warning}");
            }
            for note in report.molecules.iter().flat_map(|m| &m.notes) {
                println!("cargo::warning={note}");
            }
        }
        Err(errors) => {
            for e in &errors {
                eprintln!("{e}\n");
            }
            // Each file may have several errors; count the files.
            let files = errors.iter().map(|e| e.path.as_str()).collect::<std::collections::BTreeSet<_>>().len();
            eprintln!(
                "rovib: {} error{} in {files} molecule definition{}; fix the above and run cargo build again",
                errors.len(),
                if errors.len() == 1 { "" } else { "s" },
                if files == 1 { "" } else { "s" }
            );
            std::process::exit(1);
        }
    }
}
