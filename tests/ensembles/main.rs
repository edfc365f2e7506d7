//! Tests of ensembles, samplers, spectra and scene parsing on the library, and the fuzz targets.
//!
//! One test binary of several modules (each module a former `tests/NAME.rs`), so that the
//! library with every generated molecule is linked once per group rather than once per file:
//! `cargo test --test ensembles MODULE::` runs one module.

#[path = "../common/mod.rs"]
mod common;

mod chart_choice;
mod co2ar_example;
mod collision_interrupt;
mod collisions;
mod ensemble;
mod ensemble_fuzz;
mod ensemble_samplers;
mod ensemble_scene;
mod ensemble_stops;
mod fuzz;
mod in_memory;
mod linear_scenes;
mod pair_ensemble;
mod pair_lanes;
mod pair_states;
mod sampling;
mod scene_limits;
mod spectrum;
