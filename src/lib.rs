//! rovib: classical rotation-vibration dynamics of polyatomic molecules.
//!
//! A molecule is defined in `molecules/NAME.toml` (atoms, internal coordinates, body-frame
//! positions as expressions, potential); `cargo build` generates straight-line Rust for its
//! kinetic matrices and their derivatives ([`molecules`]), and the [`runtime`] turns them into
//! Hamilton's equations and trajectories. A [`Simulation`] runs one scene's trajectory into a
//! folder, [`ensemble::run_ensemble_with`] an ensemble's; both take a stop flag and a progress
//! callback and never install signal handlers. The `rovib` command (feature `cli`) is a binary
//! on top of this library.
//!
//! ```no_run
//! use std::sync::atomic::AtomicBool;
//! use rovib::Simulation;
//!
//! let sim = Simulation::load("scenes/h2o.toml".as_ref(), Some("out/h2o".as_ref()))?;
//! let stop = AtomicBool::new(false);
//! let report = sim.run(&stop, &mut |p| eprintln!("{}/{} outputs", p.done, p.total))?;
//! println!("{} steps", report.stats.steps);
//! # Ok::<(), rovib::Error>(())
//! ```

pub mod bench;
pub mod cpu;
pub mod dir_lock;
pub mod energy_guard;
pub mod ensemble;
pub mod error;
pub mod external_potential;
pub mod freq;
pub mod memory;
pub mod molecules;
pub mod output;
pub mod output_file;
pub mod parameters;
#[cfg(feature = "svg")]
pub mod plot;
pub mod progress;
pub mod report;
pub mod restart;
pub mod scene;
pub mod scene_molecule;
pub mod simulation;
pub mod start;
pub mod surface_gradient;
pub mod surfaces;

pub use error::Error;
pub use progress::Progress;
pub use rovib_runtime as runtime;
pub use simulation::{RunReport, Simulation};

/// The README's Rust examples, compiled and run as doctests so that they stay true.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;

/// The user guide's Rust examples (docs/src), compiled and run as doctests likewise.
#[cfg(doctest)]
#[doc = include_str!("../docs/src/reference/library.md")]
pub struct GuideLibraryDoctests;

/// The guide's page on outside surfaces: its Rust example, compiled and run likewise.
#[cfg(doctest)]
#[doc = include_str!("../docs/src/howto/outside-surfaces.md")]
pub struct GuideOutsideSurfacesDoctests;
