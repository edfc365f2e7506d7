//! What rovib's build-time generator (`rovib-codegen`) and its runtime (`rovib-runtime`) share:
//! errors located in a text file ([`diagnostic`]), units with their conversions ([`units`]),
//! input files read with a size limit ([`input`]) and numbers written compactly in messages
//! ([`number`]).
//!
//! A crate of its own, with no dependencies, so that definition errors (from the build) and
//! scene errors (from `rovib run`) are one type displayed one way, and both sides convert with
//! the same constants. The runtime re-exports both modules as `rovib_runtime::diagnostic` and
//! `rovib_runtime::units`.

pub mod diagnostic;
pub mod input;
pub mod number;
pub mod units;
