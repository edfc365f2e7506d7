//! Generates Rust for every molecule definition in `molecules/` (see `rovib-codegen`).
//!
//! Thin on purpose: it calls `rovib_codegen::generate_dirs`, prints one `rerun-if-changed` per
//! definition, warns (`cargo::warning`) about molecules whose generated code is large enough to
//! make rustc slow or whose definition is probably mistaken, writes the molecules' notes for
//! `rovib list` (`molecule_notes.rs`), and on a bad definition prints readable errors and exits
//! 1 (never a panic).
//!
//! `ROVIB_MOLECULES_DIR`, if set, adds the definitions of that directory to the shipped
//! `molecules/` (a molecule defined in both is an error naming both files);
//! `ROVIB_MOLECULES_ONLY=1` builds that directory's molecules alone. `ROVIB_KINETIC_JACOBIAN=generated` also generates
//! the symbolic `kinetic_jacobian` (the reference path's ∂a/∂q, ∂A/∂q, ∂I/∂q) instead of the
//! runtime's default, which assembles them from the generated ∂T/∂q; it grows like n³ and is
//! meant for small molecules. `ROVIB_LARGE_MOLECULE_FORMS=expanded` generates large molecules
//! without their size-dependent forms (reverse-mode ∂T/∂q, run-time centre of mass), for
//! measuring what those gain.

use std::path::{Path, PathBuf};

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out_dir = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=ROVIB_MOLECULES_DIR");
    println!("cargo::rerun-if-env-changed=ROVIB_MOLECULES_ONLY");
    println!("cargo::rerun-if-env-changed=ROVIB_KINETIC_JACOBIAN");
    println!("cargo::rerun-if-env-changed=ROVIB_LARGE_MOLECULE_FORMS");
    if let Err(message) = report_registry(&manifest.join("src/report"), &out_dir.join("reporters.rs")) {
        eprintln!("rovib: {message}");
        std::process::exit(1);
    }
    if let Err(e) = ensemble_methods(&manifest, &out_dir) {
        eprintln!("rovib: {e}");
        std::process::exit(1);
    }
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
    let shipped = (manifest.join("molecules"), "molecules".to_owned());
    let user = match std::env::var("ROVIB_MOLECULES_DIR") {
        Ok(d) if !d.is_empty() => Some((PathBuf::from(&d), d)),
        _ => None,
    };
    let dirs = match (std::env::var("ROVIB_MOLECULES_ONLY").as_deref(), user) {
        (Ok("") | Ok("0") | Err(_), user) => std::iter::once(shipped).chain(user).collect::<Vec<_>>(),
        (Ok("1"), Some(user)) => vec![user],
        (Ok("1"), None) => {
            eprintln!(
                "rovib: ROVIB_MOLECULES_ONLY=1 needs ROVIB_MOLECULES_DIR, the directory whose molecules to build"
            );
            std::process::exit(1);
        }
        (Ok(other), _) => {
            eprintln!(
                "rovib: ROVIB_MOLECULES_ONLY={other:?} is not understood; use `1` (only the molecules of \
                 ROVIB_MOLECULES_DIR) or `0` (the default: the shipped molecules and those of ROVIB_MOLECULES_DIR)"
            );
            std::process::exit(1);
        }
    };
    // With the `surface-demos` feature, the definitions whose potentials are source files in
    // Rust, Fortran and C++ (their tests need gfortran and g++).
    let mut dirs = dirs;
    if std::env::var_os("CARGO_FEATURE_SURFACE_DEMOS").is_some() {
        dirs.push((manifest.join("tests/surfaces"), "tests/surfaces".to_owned()));
    }
    // The directories themselves, so that adding a definition reruns generation.
    for (dir, _) in &dirs {
        println!("cargo::rerun-if-changed={}", dir.display());
    }
    let dirs: Vec<(&Path, &str)> = dirs.iter().map(|(d, name)| (d.as_path(), name.as_str())).collect();
    match rovib_codegen::generate_dirs(&dirs, &out_dir, &options) {
        Ok(report) => {
            for input in &report.inputs {
                println!("cargo::rerun-if-changed={}", input.display());
            }
            for warning in report.molecules.iter().filter_map(|m| m.size_warning()) {
                println!("cargo::warning={warning}");
            }
            for warning in report.molecules.iter().flat_map(|m| &m.warnings) {
                println!("cargo::warning={warning}");
            }
            // Notes are facts about a molecule, not problems of the build: `rovib list` shows them.
            let notes: Vec<String> = report
                .molecules
                .iter()
                .flat_map(|m| m.notes.iter().map(move |note| format!("    ({:?}, {:?}),\n", m.name, note)))
                .collect();
            let source = format!(
                "/// Notes on the compiled-in molecules, (molecule, note), for `rovib list`.\n\
                 pub const NOTES: &[(&str, &str)] = &[\n{}];\n",
                notes.concat()
            );
            if let Err(message) = write_if_changed(&out_dir.join("molecule_notes.rs"), &source) {
                eprintln!("rovib: {message}");
                std::process::exit(1);
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

/// Writes `reporters.rs`, included by `src/report/mod.rs`: one module per file of `src/report/`
/// (other than `mod.rs`), in the order of the files' names, and `OUTPUTS`, their `OUTPUT`
/// constants in that order (`rovib_codegen::folder_registry`). Adding an output is adding its
/// file; the folder is watched, so a new or changed file reruns this script (0.3 s with the
/// molecules, whose generated files are rewritten only if their text changed).
fn report_registry(dir: &Path, out: &Path) -> Result<(), String> {
    println!("cargo::rerun-if-changed={}", dir.display());
    let registry = rovib_codegen::folder_registry::Registry {
        folder: "src/report/",
        constant: "OUTPUT",
        ty: "Output",
        list: "OUTPUTS",
        example: "src/report/dipole_csv.rs",
    };
    write_if_changed(out, &rovib_codegen::folder_registry::folder_registry(dir, &registry)?)
}

/// Finds the sampling methods of `[ensemble]`, one file each in `src/ensemble/method/` (every
/// `NAME.rs` but `mod.rs`, its type the CamelCase of NAME; `rovib_codegen::folder_registry`
/// lists them), and writes `ensemble_methods.rs`: their `mod` lines and the `methods!` call that
/// gathers them (`src/ensemble/method/mod.rs` includes it). Deterministic: the files in the
/// order of their names.
fn ensemble_methods(manifest: &Path, out_dir: &Path) -> Result<(), String> {
    let dir = manifest.join("src/ensemble/method");
    println!("cargo::rerun-if-changed={}", dir.display());
    let files = rovib_codegen::folder_registry::folder_modules(&dir, "src/ensemble/method/")?;
    let mut source = String::from(
        "// @generated by build.rs (`ensemble_methods`) from the files of src/ensemble/method/; do not edit.\n",
    );
    let mut list = String::new();
    for (name, path) in &files {
        let camel: String = name.split('_').map(|w| w[..1].to_ascii_uppercase() + &w[1..]).collect();
        source.push_str(&format!("\n#[path = {path:?}]\npub mod {name};\n"));
        list.push_str(&format!("    {camel} = {name}::{camel},\n"));
    }
    source.push_str(&format!("\nmethods! {{\n{list}}}\n"));
    write_if_changed(&out_dir.join("ensemble_methods.rs"), &source)
}

/// Writes `text` to `path` unless the file already holds it (so that its time stamp, and what
/// cargo rebuilds from it, changes only with its text).
fn write_if_changed(path: &Path, text: &str) -> Result<(), String> {
    if std::fs::read_to_string(path).ok().as_deref() != Some(text) {
        std::fs::write(path, text)
            .map_err(|e| format!("cannot write {}: {e}; check that OUT_DIR is writable", path.display()))?;
    }
    Ok(())
}
