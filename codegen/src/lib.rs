//! rovib's build-time code generator: molecule definitions to straight-line Rust.
//!
//! The modules read as the pipeline, in order:
//!
//! 1. [`definition`]: the TOML file, validated, with errors that name file, line and fix;
//! 2. [`parse`]: expressions (syn) into the [`expr`] graph, a hash-consed DAG;
//! 3. [`diff`]: symbolic derivatives ([`adjoint`]: directional derivatives and gradients);
//! 4. [`kinetic`]: positions to the kinetic matrices a, A, I and all derivatives ([`dipole`]: the
//!    dipole moment surface and its derivatives, for a definition with a `[dipole]` table);
//! 5. [`emit`]: CSE, lowering and printing with quote and prettyplease ([`scopes`]: long functions
//!    grouped into blocks so that rustc's debug information never overflows its stack);
//! 6. [`template`]: what a generated molecule file (and the `molecules.rs` registry) contains.
//!
//! This file is the crate's face: [`generate`] runs the pipeline for a directory of definitions
//! (build scripts call it), [`generate_molecule`] for one, and they report what they made.
//! The shared diagnostics and units come from `rovib-base`.
//! The generated code implements `rovib_runtime::Molecule`, the one contract with the runtime.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub mod adjoint;
pub mod arrays;
pub mod cartesian;
pub mod definition;
pub mod definition_error;
pub mod diff;
pub mod dipole;
pub mod elements;
pub mod emit;
pub mod emit_lanes;
pub mod expr;
pub mod external;
pub mod folder_registry;
pub mod kinetic;
pub mod library;
pub mod names;
pub mod parametric;
pub mod parse;
pub mod piecewise;
pub mod scopes;
pub mod special;
pub mod template;
pub mod zmatrix;

pub use definition::{Definition, parse_definition};
pub use definition_error::DefinitionError;
pub use emit::FunctionStats;
pub use kinetic::{GradientMethod, Options};
pub use names::type_name;
pub use rovib_base::{diagnostic, units};

/// Generated files longer than this get a build warning ([`GeneratedMolecule::size_warning`]).
pub const WARN_LINES: usize = 100_000;

/// Generated code with more operations than this (after CSE) gets a build warning.
pub const WARN_OPERATIONS: u64 = 200_000;

/// The generated source of one molecule and what it cost.
#[derive(Clone, Debug)]
pub struct GeneratedMolecule {
    /// Molecule (and module) name.
    pub name: String,
    /// The generated type's name, e.g. `H2o`.
    pub type_name: String,
    /// Number of internal coordinates.
    pub coordinates: usize,
    /// Number of atoms.
    pub atoms: usize,
    /// The formatted Rust source.
    pub source: String,
    /// Operation counts per generated function.
    pub stats: Vec<FunctionStats>,
    /// Nodes in the expression graph when generation finished.
    pub graph_nodes: usize,
    /// Wall time from reading the definition to formatted source.
    pub codegen_time: Duration,
    /// The definition file as named in messages, e.g. `molecules/h2o.toml`.
    pub path: String,
    /// Facts about the molecule worth knowing before a run (not errors), e.g. a reference
    /// geometry where the Euler chart is singular ([`singular_reference_note`]). `rovib list`
    /// prints them; the build does not.
    pub notes: Vec<String>,
    /// What is probably a mistake in the definition but not an error, e.g. a piecewise potential
    /// whose branches do not meet ([`piecewise::jump_notes`]). The build prints them as warnings.
    pub warnings: Vec<String>,
    /// (atom, coordinate) pairs whose raw position depends on the coordinate: the sparsity the
    /// generated code exploits (out of `atoms · coordinates`).
    pub nonzero_derivatives: usize,
    /// The data files the definition read (CSV files of `[arrays]`).
    pub data_files: Vec<PathBuf>,
}

impl GeneratedMolecule {
    /// Lines of generated source.
    pub fn lines(&self) -> usize {
        self.source.lines().count()
    }

    /// Operations in the generated code, after common-subexpression elimination, over all
    /// functions.
    pub fn operations(&self) -> u64 {
        self.stats.iter().map(|f| f.ops_emitted).sum()
    }

    /// A warning with the figures if the generated code is large enough that compiling it
    /// takes rustc noticeable time and memory (more than [`WARN_LINES`] lines or
    /// [`WARN_OPERATIONS`] operations), else `None`.
    pub fn size_warning(&self) -> Option<String> {
        let (lines, ops) = (self.lines(), self.operations());
        (lines > WARN_LINES || ops > WARN_OPERATIONS).then(|| {
            format!(
                "molecule `{}` generates {lines} lines and {ops} operations ({} coordinates, {} atoms; \
                 generation took {:.1} s): expect rustc to need roughly {:.0} s and {:.1} GB to compile it in a \
                 release build and {:.0} s and {:.1} GB in the test profile (per 10,000 lines about 2.8 s and \
                 0.11 GB, and 8 s and 0.56 GB, measured for hexane compiled alone); fewer coordinates (freeze \
                 some) or a simpler potential make it smaller",
                self.name,
                self.coordinates,
                self.atoms,
                self.codegen_time.as_secs_f64(),
                lines as f64 * 2.8e-4,
                lines as f64 * 1.1e-5,
                lines as f64 * 8e-4,
                lines as f64 * 5.6e-5,
            )
        })
    }

    /// A short table of the operation counts, one row per function.
    pub fn stats_table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:<26} {:>8} {:>6} {:>14} {:>12} {:>10} {:>6}",
            "function", "outputs", "zeros", "ops (trees)", "ops (each)", "ops (CSE)", "lets"
        );
        for f in &self.stats {
            let _ = writeln!(
                s,
                "{:<26} {:>8} {:>6} {:>14.4e} {:>12} {:>10} {:>6}",
                f.name, f.outputs, f.zero_outputs, f.ops_tree, f.ops_per_output, f.ops_emitted, f.temporaries
            );
        }
        s
    }
}

/// Parses, validates and generates one molecule. `path` names the file in messages and in the
/// generated header (e.g. `molecules/h2o.toml`). Every problem of the file is reported, in file
/// order (see [`parse_definition`]).
pub fn generate_molecule(path: &str, text: &str) -> Result<GeneratedMolecule, Vec<DefinitionError>> {
    generate_molecule_with(path, text, &Options::default())
}

/// [`generate_molecule`] with [`Options`] (e.g. the symbolic `kinetic_jacobian`).
pub fn generate_molecule_with(
    path: &str,
    text: &str,
    options: &Options,
) -> Result<GeneratedMolecule, Vec<DefinitionError>> {
    generate_molecule_in(path, text, options, Path::new(path).parent())
}

/// [`generate_molecule_with`] with the directory that data files named in the definition (CSV
/// files of `[arrays]`) are relative to (`path` is then used in messages only).
pub fn generate_molecule_in(
    path: &str,
    text: &str,
    options: &Options,
    base: Option<&Path>,
) -> Result<GeneratedMolecule, Vec<DefinitionError>> {
    let start = Instant::now();
    let mut def = definition::parse_definition_in(path, text, base)?;
    let exprs = kinetic::build(&mut def, options);
    let nonzero_derivatives = exprs.nonzero_derivatives;
    let notes: Vec<String> = singular_reference_note(&def, &exprs).into_iter().collect();
    let warnings = if piecewise::has_branches(&def.graph) {
        piecewise::jump_notes(&def, exprs.potential, &exprs.potential_gradient)
    } else {
        Vec::new()
    };
    // Variables: coordinates, ω, velocities (kinetic), then positions (cartesian), then the
    // parameters (parametric, last); the dipole adds none.
    let mut cartesian = cartesian::build(&mut def);
    let dipole = dipole::build(&mut def, &exprs.positions);
    let parametric = parametric::build(&mut def);
    if let (Some(c), Some(p)) = (&mut cartesian, &parametric) {
        cartesian::with_parameters(&mut def, c, p);
    }
    let (items, stats) =
        template::molecule_items(&def, &exprs, cartesian.as_ref(), parametric.as_ref(), dipole.as_ref());
    let header = format!(
        "// @generated from {path} by rovib-codegen; do not edit.\n\
         // Regenerated by `cargo build` whenever the definition changes."
    );
    let source = emit::format_file(&header, items).map_err(|e| {
        vec![DefinitionError {
            path: path.to_owned(),
            line: 0,
            column: 0,
            message: format!("internal error: generated code does not parse: {e}"),
            help: "this is a bug in rovib-codegen; please report it with the definition file".into(),
            source_line: None,
        }]
    })?;
    Ok(GeneratedMolecule {
        name: def.name.clone(),
        type_name: type_name(&def.name),
        coordinates: def.coordinates.len(),
        atoms: def.atoms.len(),
        source,
        stats,
        graph_nodes: def.graph.len(),
        codegen_time: start.elapsed(),
        path: path.to_owned(),
        notes,
        warnings,
        nonzero_derivatives,
        data_files: def.data_files.clone(),
    })
}

/// A note if the definition's reference geometry is linear (every centred atom position on one
/// line, to 1e-8 relative): the chart of internal coordinates and Euler angles is singular there,
/// whatever the body frame, because the rotation about the axis moves no atom.
pub fn singular_reference_note(def: &Definition, exprs: &kinetic::KineticExprs) -> Option<String> {
    let q: Vec<f64> =
        def.coordinates.iter().map(|c| c.reference.map(|r| r * c.unit.in_atomic_units())).collect::<Option<_>>()?;
    let roots: Vec<expr::ExprId> = exprs.positions.iter().flatten().copied().collect();
    let mut vars = vec![0.0; def.graph.var_count()];
    vars[..q.len()].copy_from_slice(&q);
    let x = def.graph.eval(&roots, &vars);
    let atoms: Vec<[f64; 3]> = x.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
    let norm = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let far = atoms.iter().copied().max_by(|a, b| norm(*a).total_cmp(&norm(*b)))?;
    let size = norm(far);
    if size.is_nan() || size <= 0.0 {
        return None;
    }
    let e = far.map(|c| c / size);
    let off_axis = atoms
        .iter()
        .map(|r| norm([r[1] * e[2] - r[2] * e[1], r[2] * e[0] - r[0] * e[2], r[0] * e[1] - r[1] * e[0]]))
        .fold(0.0, f64::max);
    (off_axis <= 1e-8 * size).then(|| {
        let what_rovib_does = if def.kinds.is_some() {
            "this is supported, not an error: the coordinates are declared by kind, so `rovib run` (method dop853) \
             integrates near linear in lab-frame Cartesian coordinates with U(x) and switches back once the molecule \
             is bent, `rovib eval` at the reference says the chart is singular and prints the energy and the \
             Cartesian quantities, and `rovib freq` gives the 3N - 5 normal modes from the Cartesian Hessian"
        } else {
            "the positions are explicit (no coordinate kinds), so rovib has no Cartesian potential U(x) to continue \
             in: `rovib eval` at the reference prints only the energy and kinetic matrices, and a run that reaches \
             linear stops with a singular-metric error; declare each coordinate's kind (distance, angle, dihedral) \
             to get the Cartesian fallback"
        };
        format!(
            "note: the reference geometry of molecule `{}` ({}) is linear: internal coordinates plus Euler angles are \
             singular there (the rotation about the molecular axis moves no atom); {what_rovib_does} (the guide's \
             docs/src/howto/linear-molecules.md)",
            def.name, def.path
        )
    })
}

/// What [`generate`] produced.
#[derive(Debug)]
pub struct Report {
    /// The molecules, in name order.
    pub molecules: Vec<GeneratedMolecule>,
    /// Every definition and data file read (for `rerun-if-changed`).
    pub inputs: Vec<PathBuf>,
}

/// Generates every `*.toml` in `molecules_dir` into `out_dir`: one `NAME.rs` per molecule and a
/// `molecules.rs` that declares them all. Files are written only when their content changed, so
/// an unchanged definition does not trigger recompilation. `display_dir` is how the directory is
/// named in messages and generated headers (e.g. `molecules`).
///
/// Returns every definition's errors, not just the first file's.
pub fn generate(molecules_dir: &Path, display_dir: &str, out_dir: &Path) -> Result<Report, Vec<DefinitionError>> {
    generate_with(molecules_dir, display_dir, out_dir, &Options::default())
}

/// [`generate`] with [`Options`] for every molecule.
pub fn generate_with(
    molecules_dir: &Path,
    display_dir: &str,
    out_dir: &Path,
    options: &Options,
) -> Result<Report, Vec<DefinitionError>> {
    generate_dirs(&[(molecules_dir, display_dir)], out_dir, options)
}

/// [`generate_with`] for the definitions of several directories together, each given with how
/// it is named in messages (e.g. the shipped `molecules/` and a user's own directory). Two
/// definitions of the same molecule name (or type name), in one directory or in two, are an
/// error naming both files.
pub fn generate_dirs(
    dirs: &[(&Path, &str)],
    out_dir: &Path,
    options: &Options,
) -> Result<Report, Vec<DefinitionError>> {
    let io_error = |path: String, e: std::io::Error, help: &str| DefinitionError {
        path,
        line: 0,
        column: 0,
        message: e.to_string(),
        help: help.to_owned(),
        source_line: None,
    };
    let mut inputs: Vec<(PathBuf, String)> = Vec::new();
    for &(molecules_dir, display_dir) in dirs {
        let mut found: Vec<PathBuf> = std::fs::read_dir(molecules_dir)
            .map_err(|e| {
                vec![io_error(
                    display_dir.to_owned(),
                    e,
                    "create the molecules directory with one NAME.toml per molecule",
                )]
            })?
            .filter_map(|entry| entry.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        found.sort();
        inputs.extend(found.into_iter().map(|p| (p, display_dir.to_owned())));
    }
    let display_dirs: Vec<&str> = dirs.iter().map(|&(_, d)| d).collect();
    let display_dir = display_dirs.join(", ");
    let mut molecules = Vec::new();
    let mut errors = Vec::new();
    for (input, display_dir) in &inputs {
        let file_name = input.file_name().and_then(|s| s.to_str()).unwrap_or_default();
        let display = format!("{display_dir}/{file_name}");
        let text = match rovib_base::input::read_text_capped(input, rovib_base::input::MAX_INPUT_BYTES) {
            Ok(t) => t,
            Err(e) => {
                errors.push(DefinitionError {
                    path: display,
                    line: 0,
                    column: 0,
                    message: e.to_string(),
                    help: "a definition is readable UTF-8 text of at most 16 MiB".into(),
                    source_line: None,
                });
                continue;
            }
        };
        match generate_molecule_in(&display, &text, options, input.parent()) {
            Ok(m) => molecules.push(m),
            Err(e) => errors.extend(e),
        }
    }
    molecules.sort_by(|a, b| a.name.cmp(&b.name));
    let mut inputs: Vec<PathBuf> = inputs.into_iter().map(|(p, _)| p).collect();
    if molecules.is_empty() && errors.is_empty() {
        errors.push(DefinitionError {
            path: display_dir.to_owned(),
            line: 0,
            column: 0,
            message: "no molecule definitions found".into(),
            help: format!(
                "add at least one {}/NAME.toml (see the README)",
                display_dirs.last().unwrap_or(&"molecules")
            ),
            source_line: None,
        });
    }
    // Type names come from molecule names with `_` dropped, so `h2o` and `h_2o` would both be
    // `H2o`; two files may also define the same name: report every such pair, naming both files.
    for (i, m) in molecules.iter().enumerate() {
        if let Some(first) = molecules[..i].iter().find(|f| f.type_name == m.type_name) {
            let (message, help) = if first.name == m.name {
                (
                    format!("`{}` and `{}` both define the molecule `{}`", first.path, m.path, m.name),
                    "remove or rename one of the two; to build only the molecules of ROVIB_MOLECULES_DIR (replacing \
                     the shipped ones), set ROVIB_MOLECULES_ONLY=1",
                )
            } else {
                (
                    format!(
                        "molecules `{}` ({}) and `{}` ({}) both give the type name `{}`",
                        first.name, first.path, m.name, m.path, m.type_name
                    ),
                    "rename one of the two files and its `name`; type names are the names in CamelCase without `_`",
                )
            };
            errors.push(DefinitionError {
                path: m.path.clone(),
                line: 0,
                column: 0,
                message,
                help: help.into(),
                source_line: None,
            });
        }
    }
    if !errors.is_empty() {
        return Err(errors);
    }
    let write = |name: &str, content: &str| -> Result<(), DefinitionError> {
        let path = out_dir.join(name);
        if std::fs::read_to_string(&path).ok().as_deref() != Some(content) {
            std::fs::write(&path, content)
                .map_err(|e| io_error(path.display().to_string(), e, "check that OUT_DIR is writable"))?;
        }
        Ok(())
    };
    for m in &molecules {
        write(&template::file_name(&m.name), &m.source).map_err(|e| vec![e])?;
    }
    write("molecules.rs", &template::registry(&molecules, &display_dir)).map_err(|e| vec![e])?;
    // Data files too, so that a changed CSV file regenerates its molecule.
    inputs.extend(molecules.iter().flat_map(|m| m.data_files.iter().cloned()));
    Ok(Report { molecules, inputs })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn molecule(lines: usize, ops: u64) -> GeneratedMolecule {
        GeneratedMolecule {
            name: "big".into(),
            type_name: "Big".into(),
            coordinates: 84,
            atoms: 30,
            source: "x\n".repeat(lines),
            stats: vec![FunctionStats {
                name: "kinetic",
                outputs: 1,
                zero_outputs: 0,
                ops_tree: ops as f64,
                ops_per_output: ops,
                ops_emitted: ops,
                temporaries: 0,
            }],
            graph_nodes: 0,
            data_files: Vec::new(),
            codegen_time: Duration::from_millis(1500),
            path: "molecules/big.toml".into(),
            notes: Vec::new(),
            warnings: Vec::new(),
            nonzero_derivatives: 0,
        }
    }

    #[test]
    fn large_generated_code_gets_a_warning_with_the_figures() {
        assert_eq!(molecule(WARN_LINES, WARN_OPERATIONS).size_warning(), None);
        let w = molecule(680_000, 1000).size_warning().expect("too many lines");
        assert!(
            w.starts_with("molecule `big` generates 680000 lines and 1000 operations (84 coordinates, 30 atoms"),
            "{w}"
        );
        assert!(w.contains("roughly 190 s and 7.5 GB to compile it in a release build and 544 s and 38.1 GB"), "{w}");
        assert!(molecule(10, WARN_OPERATIONS + 1).size_warning().is_some());
    }
}
