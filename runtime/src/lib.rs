//! rovib's run-time numerics: what the generated molecule code plugs into.
//!
//! The pipeline at run time reads, in module order:
//! [`molecule`] (the trait generated code implements) → [`hamiltonian`] (W, the G matrices,
//! H and Hamilton's equations) → [`integrate`] (ODE methods).
//!
//! # Units
//!
//! Atomic units throughout: lengths in bohr, angles in radians, masses in electron masses,
//! energies in hartree, time in ħ/E_h (≈ 0.024 188 fs). See [`units`] for the conversions.

pub mod assembly;
pub mod cartesian_lanes;
pub mod cartesian_modes;
pub mod cartesian_system;
pub mod charts;
pub mod diagnostic;
pub mod dipole;
pub mod ensemble;
pub mod finite_differences;
pub mod frames;
pub mod grid;
pub mod hamiltonian;
pub mod integrate;
pub mod kinetic_matrices;
pub mod lanes;
pub mod modes;
pub mod molecule;
pub mod polarization;
pub mod position_surface;
pub mod rigid_system;
pub mod sample;
pub mod special;
pub mod spectrum;
pub mod surface;
pub mod units;

pub use frames::{
    CentreOfMass, FitOptions, FitReport, FrameError, LabState, from_lab, from_lab_body, to_lab, to_lab_body,
};
pub use hamiltonian::{FastSystem, HamiltonianError, HamiltonianSystem, PhaseState};
/// The lane types' `sin_cos` and `exp` ([`lanes::transcendental`]).
pub use lanes::transcendental;
pub use molecule::{Atom, Coordinate, HasKinematics, Kinematics, KineticMatrices, Molecule, MoleculeVisitor, NoDipole};
pub use nalgebra;
