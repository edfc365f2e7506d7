//! The molecules compiled in from `molecules/*.toml`, one module each, generated at build time.
//!
//! `build.rs` runs `rovib-codegen` on every definition; the generated sources live in `OUT_DIR`
//! and are included here. Each module holds a unit struct implementing
//! [`Molecule`](crate::runtime::Molecule); [`visit`] finds one by name for code that is generic
//! over the molecule.
#![allow(
    unused_variables,
    clippy::approx_constant,
    clippy::excessive_precision,
    clippy::let_and_return,
    clippy::neg_multiply,
    clippy::unreadable_literal,
    clippy::too_many_lines,
    clippy::similar_names,
    clippy::many_single_char_names
)]

// The library's own unit tests use no molecule: compiled for them (`cfg(test)`), the crate
// holds none, so that `cargo test` does not compile every molecule's runs a second time. The
// integration tests and every other build use the library with all of them.
#[cfg(not(test))]
include!(concat!(env!("OUT_DIR"), "/molecules.rs"));

/// The names of all compiled-in molecules: none in the library's unit-test build.
#[cfg(test)]
pub const NAMES: [&str; 0] = [];

/// Calls `visitor` with the molecule called `name`: in the library's unit-test build there is
/// none, and this returns `None`.
#[cfg(test)]
pub fn visit<V: crate::runtime::MoleculeVisitor>(name: &str, visitor: V) -> Option<V::Output> {
    let _ = (name, visitor);
    None
}
include!(concat!(env!("OUT_DIR"), "/molecule_notes.rs"));

/// The notes on the molecule called `name` (e.g. that its reference geometry is linear), which
/// `rovib list` prints; empty for a molecule without notes or an unknown name.
pub fn notes(name: &str) -> impl Iterator<Item = &'static str> {
    NOTES.iter().filter(move |(molecule, _)| *molecule == name).map(|(_, note)| *note)
}
