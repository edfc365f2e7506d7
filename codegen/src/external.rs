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
