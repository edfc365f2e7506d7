//! Tests that run the `rovib` binary: its commands, scenes, outputs, restarts and failure modes.
//!
//! One test binary of several modules (each module a former `tests/NAME.rs`), so that the
//! library with every generated molecule is linked once per group rather than once per file:
//! `cargo test --test commands MODULE::` runs one module.

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod docs;
mod ensemble_cli;
mod ensemble_resume;
mod ensemble_xyz;
mod library_api;
mod memory_run;
mod parameters;
mod reporters;
mod restart;
mod run_safety;
mod scene_units;
mod scene_variants;
mod scenes;
mod stress_cli;
mod trajectory_columns;
