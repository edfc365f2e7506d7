//! Names that Rust, the prelude or the generated code already use are valid coordinate names:
//! the generated code binds every user-derived local under a mangled name, and molecules whose
//! type names coincide are refused, naming both files.
//!
//! Compiling generated code in a test would be slow; the fixtures here are also built and
//! linted for real by the hostile-names step of `.ci/run`.

use rovib_codegen::names::{coordinate_ident, velocity_ident};
use rovib_codegen::{definition, generate, generate_molecule};

const FIXTURES: [&str; 2] = ["hostile", "hostile_b"];

fn fixture(name: &str) -> String {
    std::fs::read_to_string(format!("{}/tests/fixtures/{name}.toml", env!("CARGO_MANIFEST_DIR"))).expect("fixture")
}

/// Every identifier bound by a `let` in the generated functions.
fn let_bindings(file: &syn::File) -> Vec<String> {
    fn pattern(p: &syn::Pat, out: &mut Vec<String>) {
        match p {
            syn::Pat::Ident(i) => out.push(i.ident.to_string()),
            syn::Pat::Tuple(t) => t.elems.iter().for_each(|p| pattern(p, out)),
            other => panic!("unexpected pattern {}", quote::quote!(#other)),
        }
    }
    let mut out = Vec::new();
    for item in &file.items {
        if let syn::Item::Impl(i) = item {
            for it in &i.items {
                if let syn::ImplItem::Fn(f) = it {
                    for stmt in &f.block.stmts {
                        if let syn::Stmt::Local(l) = stmt {
                            pattern(&l.pat, &mut out);
                        }
                    }
                }
            }
        }
    }
    out
}

#[test]
fn every_user_derived_local_is_mangled() {
    for name in FIXTURES {
        let text = fixture(name);
        let def = definition::parse_definition(&format!("molecules/{name}.toml"), &text).expect("valid");
        let m = generate_molecule(&format!("molecules/{name}.toml"), &text).expect("valid");
        let file = syn::parse_file(&m.source).expect("generated source parses");
        let mangled: Vec<String> = def
            .coordinates
            .iter()
            .enumerate()
            .flat_map(|(k, c)| [coordinate_ident(k, &c.name), velocity_ident(k, &c.name)])
            .collect();
        let template = |id: &str| {
            ["omega", "qdot", "omega_x", "omega_y", "omega_z"].contains(&id)
                || (id.starts_with('t') && id.len() > 1 && id[1..].chars().all(|c| c.is_ascii_digit()))
        };
        let bound = let_bindings(&file);
        for id in &bound {
            assert!(template(id) || mangled.contains(id), "{name}: `{id}` is neither the template's nor mangled");
            assert!(id.chars().all(|c| !c.is_ascii_uppercase()), "{name}: `{id}` is not snake case");
        }
        for (k, c) in def.coordinates.iter().enumerate() {
            let ident = coordinate_ident(k, &c.name);
            assert!(bound.contains(&ident), "{name}: coordinate {} is never loaded as {ident}", c.name);
            assert!(m.source.contains(&format!("let {ident} = q[{k}];")), "{name}: {ident}");
            assert!(m.source.contains(&format!("name: \"{}\"", c.name)), "{name}: the table names {}", c.name);
        }
        // No user name is bound as it is written.
        for c in &def.coordinates {
            // (Unless the template binds that name itself, as `omega_x`, loaded from ω above.)
            assert!(!bound.contains(&c.name) || template(&c.name), "{name}: `{}` bound unmangled", c.name);
        }
    }
}

/// A unique scratch directory under the system's temporary directory.
fn scratch(tag: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("rovib-hostile-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("out")).expect("scratch directory");
    dir
}

#[test]
fn molecules_with_one_type_name_are_refused_naming_both_files() {
    let h2o = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../molecules/h2o_rigid.toml")).unwrap();
    for (a, b, ty) in [("h2o", "h_2o", "H2o"), ("a_b", "a__b", "AB")] {
        let dir = scratch(a);
        for n in [a, b] {
            std::fs::write(
                dir.join(format!("{n}.toml")),
                h2o.replace("name = \"h2o_rigid\"", &format!("name = \"{n}\"")),
            )
            .unwrap();
        }
        let errors = generate(&dir, "molecules", &dir.join("out")).expect_err("colliding type names");
        assert_eq!(errors.len(), 1, "{errors:?}");
        let e = &errors[0];
        // Files are read in name order: `a__b` < `a_b`, `h2o` < `h_2o`.
        let (first, second) = if a < b { (a, b) } else { (b, a) };
        assert_eq!(
            e.message,
            format!(
                "molecules `{first}` (molecules/{first}.toml) and `{second}` (molecules/{second}.toml) both give the type \
                 name `{ty}`"
            )
        );
        assert_eq!(e.path, format!("molecules/{second}.toml"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn a_molecule_named_molecules_does_not_overwrite_the_registry() {
    let h2o = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../molecules/h2o_rigid.toml")).unwrap();
    let dir = scratch("registry");
    std::fs::write(dir.join("molecules.toml"), h2o.replace("name = \"h2o_rigid\"", "name = \"molecules\"")).unwrap();
    generate(&dir, "molecules", &dir.join("out")).expect("valid");
    let registry = std::fs::read_to_string(dir.join("out/molecules.rs")).unwrap();
    assert!(registry.contains("pub const NAMES"), "{registry}");
    let molecule = std::fs::read_to_string(dir.join("out/molecule_molecules.rs")).unwrap();
    assert!(molecule.contains("pub struct Molecules;"));
    let _ = std::fs::remove_dir_all(&dir);
}
