//! Tests of the generated molecules and the dynamics on the library: derivatives, frames, the fast
//! path, lanes, cross-checks against the Cartesian propagation, stability.
//!
//! One test binary of several modules (each module a former `tests/NAME.rs`), so that the
//! library with every generated molecule is linked once per group rather than once per file:
//! `cargo test --test numerics MODULE::` runs one module.

#[path = "../common/mod.rs"]
mod common;

mod bench_units;
mod cartesian;
mod cartesian_lanes;
mod cartesian_potential;
#[cfg(feature = "surface-demos")]
mod compiled_surfaces;
mod contract;
mod cross_check_molecules;
mod dipole_output;
mod fast_path;
mod frames;
mod freq;
mod generated_code;
mod grid_surfaces;
mod hamiltonian;
mod lanes;
mod linear_charts;
mod molecules;
mod position_surfaces;
mod rigid_collinear;
mod stability;
mod surfaces;
