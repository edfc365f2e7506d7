//! Compiles the C surfaces in `surfaces/` into the crate (linked statically), and the C, C++
//! and Fortran sources that molecule definitions name (`[potential] c`, `cpp`, `fortran`; see
//! `rovib_codegen::external`), with the calls into them written to `OUT_DIR/compiled.rs`.
//!
//! Each surface gets its own symbol prefix: `SURFACE(name)` is defined as `PREFIX_##name`, so a
//! shared library built from the same source (which exports the `rovib_surface_*` names of
//! `include/rovib_surface.h`) never clashes. A definition's prefix is its molecule's name.
//!
//! The definitions are read from the directories the main crate's build script reads
//! (`../molecules`, `ROVIB_MOLECULES_DIR`, `ROVIB_MOLECULES_ONLY`), plus `../tests/surfaces`
//! with the `surface-demos` feature. A compiler that is missing or fails is an error naming the
//! definition, the line of its key and the compiler; a Fortran or C++ compiler is only needed
//! when a definition names such sources.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

fn main() {
    println!("cargo::rerun-if-changed=surfaces/arn2_spline.c");
    println!("cargo::rerun-if-changed=include/rovib_surface.h");
    cc::Build::new()
        .file("surfaces/arn2_spline.c")
        .include("include")
        .define("SURFACE(name)", Some("arn2_spline_##name"))
        .flag_if_supported("-std=c99")
        .warnings(true)
        .compile("rovib_surfaces");
    // The C surfaces call libm (exp, pow, sin, cos).
    if std::env::var("CARGO_CFG_UNIX").is_ok() {
        println!("cargo::rustc-link-lib=m");
    }
    definition_sources();
}

/// The molecule directories, as the main crate's build script chooses them.
fn molecule_dirs() -> Vec<PathBuf> {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let root = manifest.parent().unwrap_or(&manifest).to_path_buf();
    println!("cargo::rerun-if-env-changed=ROVIB_MOLECULES_DIR");
    println!("cargo::rerun-if-env-changed=ROVIB_MOLECULES_ONLY");
    // A relative ROVIB_MOLECULES_DIR is relative to the main crate (where its build script runs).
    let user = std::env::var("ROVIB_MOLECULES_DIR").ok().filter(|d| !d.is_empty()).map(|d| root.join(d));
    let mut dirs = Vec::new();
    if std::env::var("ROVIB_MOLECULES_ONLY").as_deref() != Ok("1") {
        dirs.push(root.join("molecules"));
    }
    dirs.extend(user);
    if std::env::var_os("CARGO_FEATURE_SURFACE_DEMOS").is_some() {
        dirs.push(root.join("tests/surfaces"));
    }
    dirs
}

fn definition_sources() {
    let out_dir = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let dirs = molecule_dirs();
    for d in &dirs {
        println!("cargo::rerun-if-changed={}", d.display());
    }
    let dirs: Vec<&Path> = dirs.iter().map(PathBuf::as_path).collect();
    let mut externs = String::new();
    let mut functions = String::new();
    let mut fortran = false;
    for s in rovib_codegen::external::compiled_sources(&dirs) {
        println!("cargo::rerun-if-changed={}", s.definition);
        let prefix = &s.molecule;
        for (language, (files, line)) in [("c", &s.c), ("cpp", &s.cpp), ("fortran", &s.fortran)] {
            if files.is_empty() {
                continue;
            }
            for f in files {
                println!("cargo::rerun-if-changed={}", f.display());
            }
            let mut build = cc::Build::new();
            build.files(files).include("include").warnings(false).cargo_warnings(false);
            let compiler = match language {
                "fortran" => {
                    println!("cargo::rerun-if-env-changed=FC");
                    let fc = std::env::var("FC").unwrap_or_else(|_| "gfortran".to_owned());
                    // Fortran module files go to OUT_DIR, not the source tree.
                    build.compiler(&fc).flag(format!("-J{}", out_dir.display()));
                    fortran = true;
                    fc
                }
                "cpp" => {
                    build.cpp(true).define("SURFACE(name)", Some(format!("{prefix}_##name").as_str()));
                    build.get_compiler().path().display().to_string()
                }
                _ => {
                    build.define("SURFACE(name)", Some(format!("{prefix}_##name").as_str()));
                    build.get_compiler().path().display().to_string()
                }
            };
            let located = |what: String, help: &str| -> ! {
                eprintln!(
                    "error: {what}\n  --> {}:{line}\n  = help: {help}\n\nrovib: the potential of molecule `{prefix}` \
                     cannot be compiled; fix the above and run cargo build again",
                    s.definition
                );
                std::process::exit(1);
            };
            let debian = match language {
                "fortran" => "gfortran",
                "cpp" => "g++",
                _ => "gcc",
            };
            if std::process::Command::new(&compiler).arg("--version").output().is_err() {
                located(
                    format!("`potential.{language}` needs the compiler `{compiler}`, which is not installed"),
                    &format!(
                        "install it (Debian/Ubuntu: apt-get install {debian}){}, or remove `{language}` from the definition",
                        if language == "fortran" { " or set FC to a Fortran compiler" } else { "" }
                    ),
                );
            }
            if let Err(e) = build.try_compile(&format!("rovib_{prefix}_{language}")) {
                located(
                    format!("`{compiler}` failed on the `potential.{language}` sources: {e}"),
                    "the compiler's messages are above; fix the sources",
                );
            }
        }
        missing_functions(&s, &out_dir);
        let n = s.coordinates;
        let _ = writeln!(
            externs,
            "unsafe extern \"C\" {{\n    fn {prefix}_energy(q: *const f64) -> f64;\n    \
             fn {prefix}_gradient(q: *const f64, grad: *mut f64) -> f64;\n}}\n\n\
             pub(crate) fn gradient_{prefix}(q: &[f64; {n}], grad: &mut [f64; {n}]) -> f64 {{\n    \
             // SAFETY: q and grad hold the {n} values the function reads and writes.\n    \
             unsafe {{ {prefix}_gradient(q.as_ptr(), grad.as_mut_ptr()) }}\n}}\n\n\
             pub(crate) fn energy_{prefix}(q: &[f64; {n}]) -> f64 {{\n    \
             // SAFETY: q holds the {n} values the function reads.\n    \
             unsafe {{ {prefix}_energy(q.as_ptr()) }}\n}}\n"
        );
        let _ = writeln!(
            functions,
            "/// The compiled potential of molecule `{prefix}` ({definition}): ∂U/∂q into `grad`; returns U.\n\
             pub fn {prefix}(q: &[f64; {n}], grad: &mut [f64; {n}]) -> f64 {{\n    \
             crate::raw::compiled::gradient_{prefix}(q, grad)\n}}\n\n\
             /// U(q) of molecule `{prefix}`'s compiled potential (its `{prefix}_energy`).\n\
             pub fn {prefix}_energy(q: &[f64; {n}]) -> f64 {{\n    \
             crate::raw::compiled::energy_{prefix}(q)\n}}\n",
            definition = s.definition.replace('\\', "/"),
        );
    }
    if fortran && std::env::var("CARGO_CFG_UNIX").is_ok() {
        println!("cargo::rustc-link-lib=gfortran");
    }
    write_if_changed(&out_dir.join("compiled_raw.rs"), &externs);
    write_if_changed(&out_dir.join("compiled.rs"), &functions);
}

/// Stops the build with a located error if the sources of `s` (their static libraries, just
/// built in `out_dir`) define neither `NAME_energy` nor `NAME_gradient`, or one of them: else
/// the linker would fail later on the whole of rovib with an undefined symbol and no word of
/// the definition. Archives without a symbol table are not checked.
fn missing_functions(s: &rovib_codegen::external::CompiledSources, out_dir: &Path) {
    let mut symbols = Vec::new();
    for (language, (files, _)) in [("c", &s.c), ("cpp", &s.cpp), ("fortran", &s.fortran)] {
        if files.is_empty() {
            continue;
        }
        let archive = out_dir.join(format!("librovib_{}_{language}.a", s.molecule));
        let Some(found) = std::fs::read(&archive).ok().and_then(|b| rovib_codegen::external::archive_symbols(&b))
        else {
            return;
        };
        symbols.extend(found);
    }
    let missing = s.missing_functions(&symbols);
    if missing.is_empty() {
        return;
    }
    let (key, line) = s.first_key();
    let name = &s.molecule;
    let list = missing.iter().map(|f| format!("`{f}`")).collect::<Vec<_>>().join(" and ");
    eprintln!(
        "error: the sources of `potential.{key}` define no function {list}, which rovib calls for molecule `{name}`\n  \
         --> {}:{line}\n  = help: define `double {name}_energy(const double *q)` and `double {name}_gradient(const double *q, \
         double *grad)` (C and C++: `double SURFACE(energy)(const double *q)` and `double SURFACE(gradient)(const double \
         *q, double *grad)`, in C++ inside extern \"C\"; Fortran: bind(C, name=\"{name}_gradient\")); check the spelling \
         (docs/src/howto/outside-surfaces.md)\n\nrovib: the potential of molecule `{name}` cannot be linked; fix the above \
         and run cargo build again",
        s.definition
    );
    std::process::exit(1);
}

fn write_if_changed(path: &Path, text: &str) {
    if std::fs::read_to_string(path).ok().as_deref() != Some(text) {
        std::fs::write(path, text).unwrap_or_else(|e| panic!("cannot write {}: {e}", path.display()));
    }
}
