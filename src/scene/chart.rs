//! `run.chart`: the chart of phase space an ensemble's trajectories are integrated in.
//!
//! `auto` (the default) chooses one of the two below for the molecule, by a fixed rule (the same
//! on every MPI rank and on resume; `crate::ensemble` applies it): the Cartesian chart for a
//! molecule whose reference geometry is linear (where the internal chart is singular: a thermal
//! ensemble stays near it and keeps switching charts), when the Cartesian chart is available and
//! `run.cartesian_fallback` is on; the internal chart otherwise. The rule comes from measurement
//! (BENCHMARKS.md, "The chart of an ensemble").
//! `internal` integrates in internal coordinates and orientation, switching to a
//! lab-frame chart near linear geometries as `run.cartesian_fallback` says (`runtime::charts`).
//! `cartesian` integrates every trajectory in the lab-frame Cartesian chart
//! (`runtime::cartesian_system`, on SIMD lanes with `runtime::cartesian_lanes`); the
//! observations come from the internal state converted at each output time, as the fallback
//! chart hands its states to the observers. Only for ensembles of molecules with a Cartesian
//! potential (coordinates declared by kind) and no frozen coordinates: the rest are refused at
//! the key (`crate::ensemble`).

use std::ops::Range;

use toml::Spanned;

use crate::runtime::diagnostic::{FileError, Source};

/// The chart a scene's ensemble trajectories are integrated in.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub enum RunChart {
    /// Chosen for the molecule by the rule of the module documentation (a scene's value only:
    /// an ensemble's plan holds the chart chosen).
    #[default]
    Auto,
    /// Internal coordinates and orientation (with the fallback chart near linear geometries).
    Internal,
    /// Lab-frame Cartesian positions and velocities for the whole trajectory.
    Cartesian,
}

impl RunChart {
    /// The key's value for this chart (as summary.json and the checkpoint write it).
    pub fn name(self) -> &'static str {
        match self {
            RunChart::Auto => "auto",
            RunChart::Internal => "internal",
            RunChart::Cartesian => "cartesian",
        }
    }
}

/// The values `run.chart` accepts.
pub const NAMES: [&str; 3] = ["auto", "internal", "cartesian"];

/// `run.chart` as given (its place, for errors found once the molecule is known), or the default.
pub fn parse(src: &Source<'_>, given: Option<&Spanned<String>>) -> Result<(RunChart, Option<Range<usize>>), FileError> {
    let Some(s) = given else { return Ok((RunChart::default(), None)) };
    let chart = match s.get_ref().as_str() {
        "auto" => RunChart::Auto,
        "internal" => RunChart::Internal,
        "cartesian" => RunChart::Cartesian,
        other => {
            let hint = match super::did_you_mean(other, NAMES) {
                Some(m) => format!("did you mean \"{m}\"? "),
                None => String::new(),
            };
            return Err(src.error(
                s.span(),
                format!("unknown `run.chart` \"{other}\""),
                format!(
                    "{hint}use \"auto\" (the default: the Cartesian chart for a molecule linear at its reference \
                     geometry, the internal chart otherwise), \"internal\" (internal coordinates, the Cartesian chart \
                     only near linear geometries) or \"cartesian\" (every ensemble trajectory in lab-frame \
                     Cartesians; BENCHMARKS.md says which is faster for which molecule)"
                ),
            ));
        }
    };
    Ok((chart, Some(s.span())))
}
