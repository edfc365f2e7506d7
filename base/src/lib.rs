//! What rovib's build-time generator (`rovib-codegen`) and its runtime (`rovib-runtime`) share:
//! errors located in a text file ([`diagnostic`]) and units with their conversions ([`units`]).
//!
//! A crate of its own, with no dependencies, so that definition errors (from the build) and
//! scene errors (from `rovib run`) are one type displayed one way, and both sides convert with
//! the same constants. The runtime re-exports both modules as `rovib_runtime::diagnostic` and
//! `rovib_runtime::units`.

pub mod diagnostic;
pub mod units;
