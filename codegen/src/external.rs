//! A potential from source files named by the definition instead of an expression:
//!
//! ```toml
//! [potential]
//! energy_unit = "hartree"
//! rust = "arn2_surface.rs"          # a Rust file, compiled into the generated module
//! # or C, C++ and Fortran sources, compiled into rovib-ffi by its build script (the `cc` crate):
//! # c = ["surf.c"], cpp = ["surf.cpp"], fortran = ["surf.f90"]
//! ```
//!
//! The Rust file defines `pub fn energy_gradient(q: &[f64; N], grad: &mut [f64; N]) -> f64`
//! (∂U/∂q into `grad`, U returned, hartree); it is compiled as a module of the generated code, so
//! the crate's `forbid(unsafe_code)` holds for it. Compiled sources export
//! `double NAME_gradient(const double *q, double *grad)` and `double NAME_energy(const double *q)`
//! (`NAME` the molecule's name; C and C++ get `SURFACE(x)` defined as `NAME_##x`, so the same
//! file serves as a shared library with the names of `rovib_surface.h`). The calls into them
//! are made by rovib-ffi, whose build script finds them with [`compiled_sources`].

use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

/// Where a definition's potential comes from when it is not an expression.
#[derive(Clone, Debug, PartialEq)]
pub enum ExternalPotential {
    /// A Rust file (absolute path), `#[path]`-included as a module of the generated code.
    Rust(PathBuf),
    /// C, C++ or Fortran compiled into rovib-ffi, reached as `rovib_ffi::compiled::NAME()`.
    Compiled,
}

/// The sources one definition asks rovib-ffi to compile.
#[derive(Clone, Debug, PartialEq)]
pub struct CompiledSources {
    /// The molecule's name: the prefix of its functions.
    pub molecule: String,
    /// The definition file, as shown in messages.
    pub definition: String,
    /// Its number of internal coordinates.
    pub coordinates: usize,
    /// C sources (absolute), and the 1-based line of the `c` key.
    pub c: (Vec<PathBuf>, usize),
    /// C++ sources and the line of `cpp`.
    pub cpp: (Vec<PathBuf>, usize),
    /// Fortran sources and the line of `fortran`.
    pub fortran: (Vec<PathBuf>, usize),
}

#[derive(Deserialize)]
struct File {
    name: String,
    #[serde(default)]
    coordinates: Vec<toml::Value>,
    potential: Option<Sources>,
}

#[derive(Deserialize)]
struct Sources {
    #[serde(default)]
    c: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    cpp: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    fortran: Option<Spanned<Vec<String>>>,
}

/// The compiled sources named by the definitions (`*.toml`) of `dirs`, for rovib-ffi's build
/// script. A file that does not read or parse is skipped: the generator reports it.
pub fn compiled_sources(dirs: &[&Path]) -> Vec<CompiledSources> {
    let mut out = Vec::new();
    for dir in dirs {
        let Ok(entries) = std::fs::read_dir(dir) else { continue };
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        files.sort();
        for path in files {
            let Ok(text) = std::fs::read_to_string(&path) else { continue };
            let Ok(file) = toml::from_str::<File>(&text) else { continue };
            let Some(sources) = file.potential else { continue };
            let base = path.parent().unwrap_or(Path::new(""));
            let list = |s: &Option<Spanned<Vec<String>>>| match s {
                None => (Vec::new(), 0),
                Some(s) => (
                    s.get_ref().iter().map(|f| base.join(f)).collect(),
                    text[..s.span().start].matches('\n').count() + 1,
                ),
            };
            let c = list(&sources.c);
            let cpp = list(&sources.cpp);
            let fortran = list(&sources.fortran);
            if c.0.is_empty() && cpp.0.is_empty() && fortran.0.is_empty() {
                continue;
            }
            out.push(CompiledSources {
                molecule: file.name,
                definition: path.display().to_string(),
                coordinates: file.coordinates.len(),
                c,
                cpp,
                fortran,
            });
        }
    }
    out
}

impl CompiledSources {
    /// The functions rovib calls (`NAME_energy`, `NAME_gradient`) that none of `symbols` (the
    /// names the compiled sources define, e.g. [`archive_symbols`]) is, in that order. A name
    /// with a leading `_` (the C names on macOS) counts as the name.
    pub fn missing_functions(&self, symbols: &[String]) -> Vec<String> {
        ["energy", "gradient"]
            .iter()
            .map(|f| format!("{}_{f}", self.molecule))
            .filter(|f| !symbols.iter().any(|s| s == f || s.strip_prefix('_') == Some(f.as_str())))
            .collect()
    }

    /// The key (`c`, `cpp`, `fortran`) and line of the first list that names files.
    pub fn first_key(&self) -> (&'static str, usize) {
        [("c", &self.c), ("cpp", &self.cpp), ("fortran", &self.fortran)]
            .into_iter()
            .find(|(_, (files, _))| !files.is_empty())
            .map_or(("c", 0), |(key, (_, line))| (key, *line))
    }
}

/// The global names a static library (an `ar` archive) defines, from its symbol table (the
/// GNU / System V `/` or `/SYM64/` member, which `ar` writes by default and the `cc` crate
/// always asks for); `None` if the bytes are not such an archive or have no such table (a
/// BSD-style archive: then nothing is checked and a missing function is left to the linker).
pub fn archive_symbols(bytes: &[u8]) -> Option<Vec<String>> {
    let rest = bytes.strip_prefix(b"!<arch>\n")?;
    // The first member's 60-byte header: name (16), date, uid, gid, mode, size (10), "`\n".
    let header = rest.get(..60)?;
    let name = std::str::from_utf8(&header[..16]).ok()?.trim_end();
    let size: usize = std::str::from_utf8(&header[48..58]).ok()?.trim().parse().ok()?;
    let table = rest.get(60..60 + size)?;
    let width = match name {
        "/" => 4,
        "/SYM64/" => 8,
        _ => return None,
    };
    let number = |at: usize| -> Option<usize> {
        let b = table.get(at..at + width)?;
        usize::try_from(b.iter().fold(0u64, |n, &x| (n << 8) | u64::from(x))).ok()
    };
    let count = number(0)?;
    let names = table.get(width.checked_mul(count.checked_add(1)?)?..)?;
    let symbols: Vec<String> =
        names.split(|&b| b == 0).filter(|n| !n.is_empty()).map(|n| String::from_utf8_lossy(n).into_owned()).collect();
    (symbols.len() == count).then_some(symbols)
}

/// The generated items of a potential from source files: a module (the Rust file) before the
/// `impl`, and the `potential`, `potential_gradient` and (with `lanes`) lane-by-lane
/// `potential_gradient_lanes` methods that call it.
pub(crate) fn items(
    external: &ExternalPotential,
    molecule: &str,
    n: usize,
    lanes: bool,
) -> (proc_macro2::TokenStream, proc_macro2::TokenStream) {
    use proc_macro2::{Ident, Literal, Span};
    use quote::quote;
    let nn = Literal::usize_unsuffixed(n);
    let (module, call) = match external {
        ExternalPotential::Rust(path) => {
            let path = path.display().to_string();
            (
                quote! {
                    /// The potential's Rust source file, named by the definition.
                    #[path = #path]
                    mod external_surface;
                },
                quote!(external_surface::energy_gradient(&q, &mut g)),
            )
        }
        ExternalPotential::Compiled => {
            let f = Ident::new(molecule, Span::call_site());
            (quote!(), quote!(::rovib_ffi::compiled::#f(&q, &mut g)))
        }
    };
    let lanes = if lanes {
        quote! {
            /// The potential from source files, one lane at a time.
            fn potential_gradient_lanes<T: Real>(&self, q: &[T; #nn], grad: &mut [T; #nn]) -> T {
                let all = q;
                let mut u = T::splat(0.0);
                for lane in 0..T::LANES {
                    let q: [f64; #nn] = ::core::array::from_fn(|k| all[k].lane(lane));
                    let mut g = [0.0; #nn];
                    u.set_lane(lane, #call);
                    for k in 0..#nn {
                        grad[k].set_lane(lane, g[k]);
                    }
                }
                u
            }
        }
    } else {
        quote!()
    };
    let methods = quote! {
        /// The potential energy U(q) in hartree, from the definition's source files.
        fn potential(&self, q: &SVector<f64, #nn>) -> f64 {
            let q: [f64; #nn] = ::core::array::from_fn(|k| q[k]);
            let mut g = [0.0; #nn];
            #call
        }

        /// ∂U/∂q from the definition's source files; returns U.
        fn potential_gradient(&self, q: &SVector<f64, #nn>, grad: &mut SVector<f64, #nn>) -> f64 {
            let q: [f64; #nn] = ::core::array::from_fn(|k| q[k]);
            let mut g = [0.0; #nn];
            let u = #call;
            *grad = SVector::from(g);
            u
        }

        #lanes
    };
    (module, methods)
}

#[cfg(test)]
mod tests {
    use crate::definition::parse_definition_in;
    use std::path::Path;

    const MOLECULE: &str = "name = \"pair\"\n\
        [[coordinates]]\nname = \"r\"\nunit = \"bohr\"\nreference = 2.0\n\
        [[atoms]]\nlabel = \"H1\"\nposition = [0, 0, 0]\n\
        [[atoms]]\nlabel = \"H2\"\nposition = [0, 0, \"r\"]\n\
        [potential]\nenergy_unit = \"hartree\"\n";

    fn dir() -> &'static Path {
        Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/surfaces"))
    }

    fn error(potential: &str) -> crate::DefinitionError {
        let text = format!("{MOLECULE}{potential}\n");
        match parse_definition_in("pair.toml", &text, Some(dir())) {
            Err(e) => e.into_iter().next().unwrap(),
            Ok(_) => panic!("accepted: {potential}"),
        }
    }

    #[test]
    fn a_rust_file_is_the_potential_and_is_an_input_of_the_build() {
        let text = format!("{MOLECULE}rust = \"arn2_surface.rs\"\n");
        let def = parse_definition_in("pair.toml", &text, Some(dir())).unwrap();
        match &def.external {
            Some(super::ExternalPotential::Rust(p)) => assert!(p.is_absolute() && p.ends_with("arn2_surface.rs")),
            other => panic!("{other:?}"),
        }
        assert!(def.data_files.iter().any(|p| p.ends_with("arn2_surface.rs")));
        let text = format!("{MOLECULE}fortran = [\"arn2_spline.f90\"]\n");
        let def = parse_definition_in("pair.toml", &text, Some(dir())).unwrap();
        assert_eq!(def.external, Some(super::ExternalPotential::Compiled));
    }

    #[test]
    fn routes_are_exclusive_and_files_must_exist() {
        let line = MOLECULE.lines().count() + 1;
        let e = error("");
        assert!(e.message.contains("no `expression`") && e.help.contains("rust ="), "{e:?}");
        let e = error("expression = \"r\"\nrust = \"arn2_surface.rs\"");
        assert!(e.line == line + 1 && e.message.contains("both give the potential"), "{e:?}");
        let e = error("rust = \"arn2_surface.rs\"\nc = [\"x.c\"]");
        assert!(e.line == line + 1 && e.message.contains("`potential.c` and `potential.rust`"), "{e:?}");
        let e = error("rust = \"nowhere.rs\"");
        assert!(e.line == line && e.message.contains("nowhere.rs") && e.message.contains("not a file"), "{e:?}");
        let e = error("fortran = []");
        assert!(e.line == line && e.message.contains("lists no files"), "{e:?}");
        let e = error("rust = \"arn2_surface.rs\"\nparameters = { a = 1.0 }");
        assert!(e.message.contains("parameters"), "{e:?}");
        let text = format!("{}rust = \"arn2_surface.rs\"\n", MOLECULE.replace("\"hartree\"", "\"cm-1\""));
        let Err(mut e) = parse_definition_in("pair.toml", &text, Some(dir())) else { panic!("cm-1 accepted") };
        let e = e.remove(0);
        assert!(e.message.contains("in hartree"), "{e:?}");
    }

    /// Compiles `source` with gcc into an object and archives it with `ar` in a fresh `dir`.
    fn archive(dir: &str, source: &str) -> Vec<u8> {
        use std::process::Command;
        let dir = std::env::temp_dir().join(format!("rovib-codegen-archive-{dir}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("s.c"), source).unwrap();
        let ok = |c: &mut Command| assert!(c.current_dir(&dir).status().expect("this test needs gcc and ar").success());
        ok(Command::new("gcc").args(["-c", "-fPIC", "-o", "s.o", "s.c"]));
        ok(Command::new("ar").args(["crs", "libs.a", "s.o"]));
        let bytes = std::fs::read(dir.join("libs.a")).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        bytes
    }

    #[test]
    fn a_misspelt_function_of_the_compiled_sources_is_found_before_linking() {
        let sources = super::CompiledSources {
            molecule: "pair".into(),
            definition: "pair.toml".into(),
            coordinates: 1,
            c: (vec!["s.c".into()], 9),
            cpp: (Vec::new(), 0),
            fortran: (Vec::new(), 0),
        };
        assert_eq!(sources.first_key(), ("c", 9));
        let good = archive(
            "good",
            "static double half(double x) { return 0.5 * x; }\n\
             double pair_energy(const double *q) { return half(q[0]); }\n\
             double pair_gradient(const double *q, double *g) { g[0] = 0.5; return half(q[0]); }\n",
        );
        let symbols = super::archive_symbols(&good).expect("a GNU archive has a symbol table");
        assert!(symbols.contains(&"pair_energy".to_owned()) && !symbols.contains(&"half".to_owned()), "{symbols:?}");
        assert!(sources.missing_functions(&symbols).is_empty());
        let misspelt = archive(
            "misspelt",
            "double pair_energy(const double *q) { return q[0]; }\n\
             double pair_gradeint(const double *q, double *g) { g[0] = 1; return q[0]; }\n\
             double use_missing(const double *q) { extern double pair_gradient(const double *, double *); \
             double g[1]; return pair_gradient(q, g); }\n",
        );
        let symbols = super::archive_symbols(&misspelt).unwrap();
        assert_eq!(sources.missing_functions(&symbols), vec!["pair_gradient".to_owned()], "{symbols:?}");
        assert_eq!(super::archive_symbols(b"not an archive"), None);
        assert_eq!(super::archive_symbols(&good[..70]), None);
    }

    #[test]
    fn the_build_script_finds_the_compiled_sources_with_their_lines() {
        let found = super::compiled_sources(&[dir()]);
        let fortran = found.iter().find(|s| s.molecule == "arn2_fortran").expect("tests/surfaces/arn2_fortran.toml");
        assert_eq!(fortran.coordinates, 2);
        assert!(fortran.fortran.0[0].ends_with("arn2_spline.f90") && fortran.fortran.1 > 1);
        assert!(fortran.c.0.is_empty() && fortran.cpp.0.is_empty());
        assert!(!found.iter().any(|s| s.molecule == "arn2_rust"), "a Rust file is not compiled by rovib-ffi");
    }
}
