//! The Rust identifiers generated code derives from names in a definition, chosen so that no
//! user name can collide with a Rust keyword, a prelude name, the template's own names or
//! another user name, and so that none draws a warning.
//!
//! * A coordinate `NAME` number `k` becomes the local `q{k}_{name}` and its velocity
//!   `qdot{k}_{name}`, where `name` is `NAME` in lowercase with runs of `_` folded: `R1` → `q0_r1`.
//!   The index makes them unique whatever the names are (`R1` and `r1` are different
//!   coordinates), the prefix keeps them apart from keywords, prelude names, parameters (`q`,
//!   `k`, `grad`, `velocities`, ...) and temporaries (`t0`, ...), and lowercase keeps
//!   `non_snake_case` quiet.
//! * A molecule `name` becomes the module `name` (it must not be a keyword) and the type
//!   [`type_name`] (`h2o` → `H2o`), which must not be a name the generated files use; two
//!   molecules whose type names coincide (`h2o`, `h_2o`) are reported by
//!   [`crate::generate`], naming both files.

/// The type name for a molecule name: `h2o` → `H2o`, `co2_model` → `Co2Model`.
pub fn type_name(name: &str) -> String {
    name.split('_')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut c = p.chars();
            c.next().map(|f| f.to_ascii_uppercase().to_string() + c.as_str()).unwrap_or_default()
        })
        .collect()
}

/// `name` in lowercase, runs of `_` folded into one and no `_` at either end.
fn snake(name: &str) -> String {
    let lower = name.to_ascii_lowercase();
    lower.split('_').filter(|p| !p.is_empty()).collect::<Vec<_>>().join("_")
}

/// The local variable of coordinate number `k` called `name`: `q{k}_{name}`.
pub fn coordinate_ident(k: usize, name: &str) -> String {
    match snake(name).as_str() {
        "" => format!("q{k}"),
        s => format!("q{k}_{s}"),
    }
}

/// The local variable of the velocity of coordinate number `k`: `qdot{k}_{name}`.
pub fn velocity_ident(k: usize, name: &str) -> String {
    match snake(name).as_str() {
        "" => format!("qdot{k}"),
        s => format!("qdot{k}_{s}"),
    }
}

/// Names in the type namespace that generated files use or that the prelude provides: a
/// molecule's type must not be one of them.
pub const RESERVED_TYPE_NAMES: &[&str] = &[
    // The template's imports and generic parameter.
    "Atom",
    "Coordinate",
    "KineticMatrices",
    "Molecule",
    "MoleculeVisitor",
    "SMatrix",
    "SVector",
    "Vector3",
    "CoordinateUnit",
    "LengthUnit",
    "AngleUnit",
    "E",
    // The prelude (Rust 2024) and derives.
    "Option",
    "Some",
    "None",
    "Result",
    "Ok",
    "Err",
    "Vec",
    "String",
    "Box",
    "ToString",
    "ToOwned",
    "Copy",
    "Clone",
    "Debug",
    "Default",
    "PartialEq",
    "Eq",
    "PartialOrd",
    "Ord",
    "Hash",
    "Send",
    "Sync",
    "Sized",
    "Unpin",
    "Drop",
    "Fn",
    "FnMut",
    "FnOnce",
    "AsRef",
    "AsMut",
    "From",
    "Into",
    "TryFrom",
    "TryInto",
    "Iterator",
    "IntoIterator",
    "DoubleEndedIterator",
    "ExactSizeIterator",
    "Extend",
    "FromIterator",
    "Future",
    "IntoFuture",
    "AsyncFn",
    "AsyncFnMut",
    "AsyncFnOnce",
    "Self",
];

/// Rust keywords (strict, reserved and those of edition 2024), which cannot name a module.
pub fn is_keyword(name: &str) -> bool {
    const EXTRA: [&str; 4] = ["gen", "try", "async", "await"];
    EXTRA.contains(&name) || syn::parse_str::<syn::Ident>(name).is_err()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coordinate_idents_are_prefixed_indexed_and_snake_case() {
        assert_eq!(coordinate_ident(0, "r1"), "q0_r1");
        assert_eq!(coordinate_ident(3, "R1"), "q3_r1");
        assert_eq!(coordinate_ident(1, "None"), "q1_none");
        assert_eq!(coordinate_ident(2, "a__B_"), "q2_a_b");
        assert_eq!(coordinate_ident(4, "_"), "q4");
        assert_eq!(velocity_ident(0, "Velocities"), "qdot0_velocities");
        // Every result is a plain, non-keyword, snake-case identifier, and distinct indices give
        // distinct names whatever the user names are.
        let names = ["fn", "self", "Self", "gen", "q", "k", "t0", "omega_x", "velocities", "Ok", "A_B", "a_b"];
        let mut all: Vec<String> = names.iter().enumerate().map(|(k, n)| coordinate_ident(k, n)).collect();
        all.extend(names.iter().enumerate().map(|(k, n)| velocity_ident(k, n)));
        for id in &all {
            assert!(!is_keyword(id), "{id}");
            assert!(id.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'), "{id}");
            assert!(!id.contains("__") && !id.ends_with('_'), "{id}");
            assert!(id.starts_with('q'), "{id}");
        }
        let mut unique = all.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), all.len());
    }

    #[test]
    fn keywords_and_type_names() {
        for k in ["fn", "type", "self", "super", "crate", "gen", "try", "async", "await", "dyn", "match", "yield"] {
            assert!(is_keyword(k), "{k}");
        }
        for ok in ["h2o", "water", "union", "default"] {
            assert!(!is_keyword(ok), "{ok}");
        }
        assert_eq!(type_name("h2o"), "H2o");
        assert_eq!(type_name("h_2o"), "H2o");
        assert_eq!(type_name("a__b"), type_name("a_b"));
        assert!(RESERVED_TYPE_NAMES.contains(&type_name("result").as_str()));
    }
}
