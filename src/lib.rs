//! rovib: classical rotation-vibration dynamics of polyatomic molecules.
//!
//! A molecule is defined in `molecules/NAME.toml` (atoms, internal coordinates, body-frame
//! positions as expressions, potential); `cargo build` generates straight-line Rust for its
//! kinetic matrices and their derivatives ([`molecules`]), and the [`runtime`] turns them into
//! Hamilton's equations and trajectories. The [`cli`] is the `rovib` command.

pub mod cli;
pub mod cpu;
pub mod dir_lock;
pub mod ensemble;
pub mod interrupt;
pub mod molecules;
pub mod output;
pub mod parameters;
pub mod plot;
pub mod restart;
pub mod scene;
pub mod start;
pub mod surfaces;

pub use rovib_runtime as runtime;

/// The README's Rust examples, compiled and run as doctests so that they stay true.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
