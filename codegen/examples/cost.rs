//! The cost of generating each molecule: codegen time, lines of generated Rust, and operation
//! counts per generated function before and after common-subexpression elimination.
//!
//! ```text
//! cargo run --release -p rovib-codegen --features examples --example cost -- molecules/*.toml
//! cargo run --release -p rovib-codegen --features examples --example cost -- --kinetic-jacobian molecules/*.toml
//! cargo run --release -p rovib-codegen --features examples --example cost -- --expanded molecules/*.toml
//! cargo run --release -p rovib-codegen --features examples --example cost -- --write DIR molecules/*.toml
//! ```
//!
//! `--kinetic-jacobian` also generates the symbolic `kinetic_jacobian` (off by default, see
//! `rovib_codegen::Options`). `--expanded` generates every molecule without the large-molecule
//! forms (∂T/∂q from explicit second derivatives, centre-of-mass term of `a` expanded), as
//! `ROVIB_LARGE_MOLECULE_FORMS=expanded` does in a build. The column "dr nz" counts the (atom, coordinate) pairs whose raw
//! position derivative is not a structural zero, out of atoms × coordinates.
//!
//! "max lets" is the largest function's count of `let` temporaries, "let depth" the deepest
//! chain of nested `let` scopes in the generated file (`rovib_codegen::scopes`: rustc's debug
//! information overflows its stack at about 2 500).
//!
//! Prints one summary row per molecule, then each molecule's per-function table
//! (`GeneratedMolecule::stats_table`). Codegen time is the wall time of
//! `rovib_codegen::generate_molecule` (parse, differentiate, CSE, format), taken as the best of
//! a few runs so that a cold cache or a busy core does not inflate it.

use std::process::ExitCode;
use std::time::Duration;

use rovib_codegen::{GeneratedMolecule, Options, generate_molecule_with};

/// Generation runs per molecule; the fastest is reported.
const RUNS: usize = 3;

fn main() -> ExitCode {
    let mut paths: Vec<String> = std::env::args().skip(1).collect();
    let mut options =
        Options { kinetic_jacobian: paths.iter().any(|p| p == "--kinetic-jacobian"), ..Options::default() };
    if paths.iter().any(|p| p == "--expanded") {
        options.kinetic_gradient = rovib_codegen::GradientMethod::Direct;
        options.run_time_centre_of_mass_from = usize::MAX;
    }
    // `--write DIR`: also write each generated source to DIR/NAME.rs (for compiling one molecule
    // alone, docs/src/history/benchmarks.md "Generated code: rustc per molecule").
    let write_dir = paths.iter().position(|p| p == "--write").map(|i| {
        let dir = paths.get(i + 1).cloned().unwrap_or_default();
        paths.drain(i..(i + 2).min(paths.len()));
        dir
    });
    paths.retain(|p| p != "--kinetic-jacobian" && p != "--expanded");
    if paths.is_empty() {
        eprintln!(
            "usage: cost MOLECULE.toml...   (e.g. cargo run --release -p rovib-codegen --features examples --example cost -- molecules/*.toml)"
        );
        return ExitCode::FAILURE;
    }
    let mut generated: Vec<(GeneratedMolecule, Duration)> = Vec::new();
    for path in &paths {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("{path}: {e}");
                return ExitCode::FAILURE;
            }
        };
        let mut best: Option<(GeneratedMolecule, Duration)> = None;
        for _ in 0..RUNS {
            match generate_molecule_with(path, &text, &options) {
                Ok(m) => {
                    let t = m.codegen_time;
                    if best.as_ref().is_none_or(|(_, b)| t < *b) {
                        best = Some((m, t));
                    }
                }
                Err(errors) => {
                    for e in errors {
                        eprintln!("{e}\n");
                    }
                    return ExitCode::FAILURE;
                }
            }
        }
        generated.extend(best);
    }

    println!(
        "{:<12} {:>3} {:>3} {:>9} {:>11} {:>8} {:>12} {:>14} {:>11} {:>9} {:>9}",
        "molecule",
        "N",
        "NA",
        "dr nz",
        "codegen ms",
        "lines",
        "graph nodes",
        "ops (each)",
        "ops (CSE)",
        "max lets",
        "let depth"
    );
    for (m, t) in &generated {
        let per_output: u64 = m.stats.iter().map(|s| s.ops_per_output).sum();
        let emitted: u64 = m.stats.iter().map(|s| s.ops_emitted).sum();
        let max_lets = m.stats.iter().map(|s| s.temporaries).max().unwrap_or(0);
        let depth = syn::parse_file(&m.source).map_or(0, |f| rovib_codegen::scopes::max_let_depth(&f));
        println!(
            "{:<12} {:>3} {:>3} {:>9} {:>11.1} {:>8} {:>12} {:>14} {:>11} {:>9} {:>9}",
            m.name,
            m.coordinates,
            m.atoms,
            format!("{}/{}", m.nonzero_derivatives, m.coordinates * m.atoms),
            t.as_secs_f64() * 1e3,
            m.lines(),
            m.graph_nodes,
            per_output,
            emitted,
            max_lets,
            depth
        );
    }
    if let Some(dir) = &write_dir {
        for (m, _) in &generated {
            let path = std::path::Path::new(dir).join(format!("{}.rs", m.name));
            if let Err(e) = std::fs::write(&path, &m.source) {
                eprintln!("{}: {e}", path.display());
                return ExitCode::FAILURE;
            }
        }
    }
    for (m, _) in &generated {
        println!("\n{} ({} coordinates, {} atoms, {} lines)", m.name, m.coordinates, m.atoms, m.lines());
        print!("{}", m.stats_table());
    }
    ExitCode::SUCCESS
}
