//! Scene files: what `rovib run` integrates and what it writes.
//!
//! A scene names a molecule, an initial condition, an integrator, the end time, the output
//! interval and the outputs. Every key is documented in the guide (docs/src/reference/scene.md); a short
//! example:
//!
//! ```toml
//! molecule = "h2o"
//!
//! [units]                 # of the numbers in this file (not of the output, which is atomic)
//! length = "angstrom"     # bohr | angstrom (default: q in each coordinate's declared unit,
//! angle = "deg"           # rad | deg        positions in bohr, Euler angles in rad)
//! time = "fs"             # au | fs | ps
//!
//! [initial]               # internal form: q, p or qdot, euler, pe or j
//! q = { r1 = 1.0, r2 = 0.95, alpha = 100.0 }
//! p = { r1 = 0.0 }        # ħ/bohr or ħ; missing entries are 0
//! euler = [0, 90, 0]
//! j = [0, 0, 10]          # body-frame angular momentum, ħ
//!
//! [integrator]
//! method = "dop853"       # dop853 | gauss-legendre | rk4
//! rtol = 1e-10
//! atol = 1e-10
//!
//! [run]
//! end = 500.0
//! output_interval = 1.0
//! outputs = ["trajectory", "lab", "summary"]
//! ```
//!
//! The lab form of `[initial]` gives `positions` (and optionally `velocities`) of every atom,
//! keyed by atom label. Parsing checks everything that does not depend on the molecule; the
//! rest (coordinate and atom names) is checked when the scene is bound to its molecule, with
//! errors that still point into the file.

use std::ops::Range;

use toml::Spanned;

use crate::runtime::diagnostic::{Compact, FileError, Source};
use crate::runtime::hamiltonian::{MIN_SIN_THETA, PIVOT_TOLERANCE};
use crate::runtime::integrate::{Dop853Options, Method};
use crate::runtime::units::{AU_TIME_IN_FS, AngleUnit, CoordinateUnit, LengthUnit};

pub mod chart;
mod integrator;
pub mod potential;
pub(crate) mod raw;
mod run_keys;
pub(crate) mod spanned;
pub mod variant;

use integrator::integrator;
use raw::{RawInitial, RawTable};

/// A unit of time accepted in scenes.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum TimeUnit {
    /// The atomic unit of time, ħ/E_h ≈ 0.024 189 fs.
    Au,
    /// Femtoseconds.
    Fs,
    /// Picoseconds.
    Ps,
}

impl TimeUnit {
    /// How many atomic units of time one of this unit is.
    pub fn in_au(self) -> f64 {
        match self {
            TimeUnit::Au => 1.0,
            TimeUnit::Fs => 1.0 / AU_TIME_IN_FS,
            TimeUnit::Ps => 1000.0 / AU_TIME_IN_FS,
        }
    }

    /// The unit whose [`TimeUnit::in_au`] is exactly `scale`, if any.
    pub fn of_scale(scale: f64) -> Option<TimeUnit> {
        [TimeUnit::Au, TimeUnit::Fs, TimeUnit::Ps].into_iter().find(|u| u.in_au() == scale)
    }

    /// The spelling used in files and column names.
    pub fn name(self) -> &'static str {
        match self {
            TimeUnit::Au => "au",
            TimeUnit::Fs => "fs",
            TimeUnit::Ps => "ps",
        }
    }
}

/// Which files a run writes.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct Outputs {
    /// The files written at every output time (`crate::report::OUTPUTS`: `trajectory.csv`,
    /// `lab.xyz`, `dipole.csv`).
    pub files: crate::report::Selection,
    /// `summary.json`: work counters and conservation diagnostics.
    pub summary: bool,
    /// `restart.json`: the final state, to continue the run (`rovib run --resume`).
    pub restart: bool,
}

impl Outputs {
    /// Nothing written.
    pub const NONE: Outputs = Outputs { files: crate::report::Selection::EMPTY, summary: false, restart: false };
}

/// A name in the file with its place.
pub type Named<T> = (Spanned<String>, T);

/// The initial condition, with names still to be matched to the molecule.
///
/// Everything whose unit the scene alone determines is in atomic units: the Euler angles, `p`,
/// `pe`, `j`, and the lab-frame positions and velocities. `q` and `qdot` stay in the scene's
/// units, because whether a coordinate is a length or an angle is known only with the
/// molecule; [`CoordinateScale::coordinate_to_au`] and [`CoordinateScale::velocity_to_au`] convert them
/// (in [`crate::start::initial_state`]).
#[derive(Clone, Debug)]
pub enum Initial {
    /// Internal coordinates, their momenta or velocities, the orientation and its momenta.
    Internal {
        /// q by coordinate name, in the scene's length or angle unit; missing ones default to
        /// the reference geometry.
        q: Vec<Named<f64>>,
        /// Conjugate momenta (atomic units) or velocities q̇ (the scene's units), by name;
        /// missing ones are 0.
        momenta: Momenta,
        /// Euler angles (φ, θ, ψ) in rad.
        euler: [f64; 3],
        /// The initial angular momentum.
        rotation: InitialAngularMomentum,
    },
    /// Lab-frame Cartesian positions (bohr) and velocities (bohr per a.u. of time) by label.
    Lab {
        /// Positions by atom label.
        positions: Vec<Named<[f64; 3]>>,
        /// Velocities by atom label; missing ones are 0.
        velocities: Vec<Named<[f64; 3]>>,
        /// Where the `positions` table is, for errors about missing atoms.
        span: Range<usize>,
    },
}

/// How the internal motion is given.
#[derive(Clone, Debug)]
pub enum Momenta {
    /// Conjugate momenta p (ħ/bohr or ħ).
    P(Vec<Named<f64>>),
    /// Velocities q̇ (the scene's length or angle unit per its time unit).
    Qdot(Vec<Named<f64>>),
}

/// How the initial angular momentum is given.
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum InitialAngularMomentum {
    /// The momenta conjugate to the Euler angles, ħ.
    Pe([f64; 3]),
    /// The body-frame angular momentum J, ħ.
    J([f64; 3]),
}

/// A validated scene, in atomic units.
#[derive(Clone, Debug)]
pub struct Scene {
    /// The file as the user named it.
    pub path: String,
    /// Its text, for errors found later.
    pub text: String,
    /// The molecule's name and where it is written.
    pub molecule: Spanned<String>,
    /// One-line description.
    pub description: String,
    /// The initial condition (the reference geometry at rest for an ensemble scene without
    /// `[initial]`).
    pub initial: Initial,
    /// Whether the scene has an `[ensemble]` table: `rovib ensemble` parses it and
    /// `[statistics]` (`crate::ensemble::scene`); here they are only let through.
    pub ensemble: bool,
    /// The integrator.
    pub method: Method,
    /// End time, a.u. (the run starts at 0).
    pub t_end: f64,
    /// Time between outputs, a.u.
    pub output_interval: f64,
    /// The unit the file used for time, also used for the `t` column of the output.
    pub time_unit: TimeUnit,
    /// The file's units as scale factors to atomic units.
    pub units: CoordinateScale,
    /// What to write.
    pub outputs: Outputs,
    /// Internal coordinates held fixed (names, checked against the molecule later).
    pub frozen: Vec<Spanned<String>>,
    /// The smallest relative pivot of the kinetic metric a run accepts before it stops as
    /// ill-conditioned (see `ReducedSystem::with_min_pivot`).
    pub min_metric_pivot: f64,
    /// The largest relative energy error `|H(t) − H(0)| / |H(0)|` a run accepts at an output
    /// time before it stops as unstable or too loosely integrated.
    pub max_energy_error: f64,
    /// Whether trajectory.csv also gets continuous (unwrapped) φ and ψ columns.
    pub euler_unwrapped: bool,
    /// `run.cartesian_fallback` (default true): whether `rovib run` continues in the Cartesian
    /// chart near a linear geometry (`runtime::charts`) rather than stop at `min_metric_pivot`.
    pub cartesian_fallback: bool,
    /// `run.chart` (default internal): the chart ensemble trajectories are integrated in, and
    /// the key's place when given (`chart`).
    pub chart: (chart::RunChart, Option<Range<usize>>),
    /// `[potential.parameters]`: values that replace the definition's compiled-in parameters
    /// for this run (names checked against the molecule when the run starts).
    pub parameters: Vec<Named<f64>>,
    /// `[potential] library`: a shared library with the C ABI of `ffi/include/rovib_surface.h`
    /// whose potential replaces the molecule's, as written (its place for errors) and resolved
    /// against the scene file's directory (see `crate::surfaces`).
    pub library: Option<(Spanned<String>, std::path::PathBuf)>,
    /// `[potential] grid` and `outside`: a tabulated surface that replaces the molecule's
    /// potential (see `crate::surfaces::grid`).
    pub grid: Option<potential::SceneGrid>,
    /// `[potential] gradient = "central-differences"`: the library's ∂U/∂q by central
    /// differences of its energy (`crate::surface_gradient`).
    pub central_differences: bool,
    /// Stop conditions: the run stops (status "stopped") at the first output time at which a
    /// named coordinate is outside `[low, high]` (the scene's units, as q; checked against the
    /// molecule when the run starts).
    pub stop_outside: Vec<Named<[f64; 2]>>,
    /// The tables the readers after the single run's take, from the one parse of `text`.
    pub(crate) tables: raw::Tables,
}

impl Scene {
    /// The scene's source, for errors found after parsing.
    pub fn source(&self) -> Source<'_> {
        Source { path: &self.path, text: &self.text }
    }
}

/// The largest number of output times a scene may ask for unless `run.max_outputs` raises it:
/// a million rows of trajectory.csv for water is about 0.5 GB.
pub const DEFAULT_MAX_OUTPUTS: u64 = 1_000_000;

/// The smallest relative tolerance DOP853 accepts: 10·ε ≈ 2.2e-15 (as in `dop853.f`); below
/// it the error estimate is round-off.
pub const MIN_RTOL: f64 = 10.0 * f64::EPSILON;

/// The default smallest relative pivot of the kinetic metric (see `STABILITY.md`).
pub const DEFAULT_MIN_METRIC_PIVOT: f64 = PIVOT_TOLERANCE;

/// The default largest relative energy error at an output time: a run whose energy has moved by
/// 1 % is unstable or far too loosely integrated (the shipped scenes stay below 1e-8).
pub const DEFAULT_MAX_ENERGY_ERROR: f64 = 1e-2;

/// serde's message for a TOML error, as every scene message is written: without a final full stop.
pub(crate) fn toml_message(e: &toml::de::Error) -> String {
    e.message().trim_end().trim_end_matches('.').to_owned()
}

/// A TOML error of a scene file at its place (the whole file when it has none), with `help`.
pub(crate) fn toml_error(src: &Source<'_>, e: &toml::de::Error, help: &str) -> FileError {
    let message = toml_message(e);
    match e.span() {
        Some(span) => src.error(span, message, help),
        None => src.whole_file(message, help),
    }
}

/// An error reading a table kept with its places ([`spanned`]) at its place (the whole file when
/// it has none), with `help`.
pub(crate) fn spanned_error(src: &Source<'_>, e: &spanned::Error, help: &str) -> FileError {
    let message = e.message.trim_end().trim_end_matches('.').to_owned();
    match &e.span {
        Some(span) => src.error(span.clone(), message, help),
        None => src.whole_file(message, help),
    }
}

/// Parses and validates a scene file. `path` names it in messages.
pub fn parse_scene(path: &str, text: &str) -> Result<Scene, FileError> {
    let src = Source { path, text };
    let (raw, tables) = raw::parse(text).map_err(|e| {
        let message = toml_message(&e);
        let help = if message.starts_with("unknown field") || message.starts_with("missing field") {
            "docs/src/reference/scene.md (the guide's scene reference) lists every key"
        } else {
            "see the TOML syntax at https://toml.io and the shipped scenes/ for examples"
        };
        toml_error(&src, &e, help)
    })?;

    let (length, angle, time) = units(&src, &raw.units)?;
    let (l, a, t) = (length.map_or(1.0, LengthUnit::in_bohr), angle.map_or(1.0, AngleUnit::in_rad), time.in_au());
    let initial = match (&raw.initial, &raw.ensemble) {
        (Some(i), _) => initial(&src, i, l, a, t)?,
        // An ensemble draws its own initial states.
        (None, Some(_)) => Initial::Internal {
            q: Vec::new(),
            momenta: Momenta::P(Vec::new()),
            euler: [0.0, std::f64::consts::FRAC_PI_2, 0.0],
            rotation: InitialAngularMomentum::J([0.0; 3]),
        },
        (None, None) => {
            return Err(src.whole_file(
                "missing field `initial`",
                "add an [initial] table (one trajectory) or an [ensemble] table (many), see docs/src/reference/scene.md",
            ));
        }
    };
    ensemble_tables_need_ensemble(&src, &raw)?;
    let run = raw.run.get_ref();
    let keys = run_keys::read(&src, run, t)?;
    let method = match &raw.integrator {
        None => Method::Dop853(Dop853Options::default()),
        Some(i) => integrator(&src, i, t, keys.t_end, keys.output_interval)?,
    };
    no_velocity_for_frozen(&src, &initial, &run.frozen)?;
    let potential = potential::scene_potential(&src, raw.potential.as_ref())?;
    Ok(Scene {
        path: path.to_owned(),
        text: text.to_owned(),
        tables,
        molecule: raw.molecule,
        description: raw.description.unwrap_or_default(),
        initial,
        ensemble: raw.ensemble.is_some(),
        method,
        t_end: keys.t_end,
        output_interval: keys.output_interval,
        time_unit: time,
        units: CoordinateScale {
            length: length.map(LengthUnit::in_bohr),
            angle: angle.map(AngleUnit::in_rad),
            time: t,
        },
        outputs: keys.outputs,
        frozen: run.frozen.clone(),
        min_metric_pivot: keys.min_metric_pivot,
        max_energy_error: keys.max_energy_error,
        euler_unwrapped: run.euler_unwrapped,
        cartesian_fallback: run.cartesian_fallback.unwrap_or(true),
        chart: chart::parse(&src, run.chart.as_ref())?,
        parameters: potential.parameters,
        library: potential.library,
        grid: potential.grid,
        central_differences: potential.central_differences,
        stop_outside: keys.stop_outside,
    })
}

/// The `[units]` table: length and angle (`None` without the key: each coordinate's declared
/// unit), time (atomic units by default).
fn units(
    src: &Source<'_>,
    raw: &raw::RawUnits,
) -> Result<(Option<LengthUnit>, Option<AngleUnit>, TimeUnit), FileError> {
    // Without [units], lengths and angles of coordinates are in each coordinate's declared unit
    // (`None`); Cartesian positions and velocities in bohr, Euler angles in rad.
    let length = match &raw.length {
        None => None,
        Some(_) => Some(unit(
            src,
            raw.length.as_ref(),
            LengthUnit::Bohr,
            LengthUnit::parse,
            "length",
            "\"bohr\", \"angstrom\"",
        )?),
    };
    let angle = match &raw.angle {
        None => None,
        Some(_) => Some(unit(src, raw.angle.as_ref(), AngleUnit::Rad, AngleUnit::parse, "angle", "\"rad\", \"deg\"")?),
    };
    let time = unit(
        src,
        raw.time.as_ref(),
        TimeUnit::Au,
        |s| match s {
            "au" => Some(TimeUnit::Au),
            "fs" => Some(TimeUnit::Fs),
            "ps" => Some(TimeUnit::Ps),
            _ => None,
        },
        "time",
        "\"au\", \"fs\", \"ps\"",
    )?;
    Ok((length, angle, time))
}

/// Refuses `[spectrum]`, `[collision]`, `[pairs]` and `[statistics]` without `[ensemble]`.
fn ensemble_tables_need_ensemble(src: &Source<'_>, raw: &raw::RawScene) -> Result<(), FileError> {
    if raw.ensemble.is_some() {
        return Ok(());
    }
    let refusal =
        |table: &str, help: &str| Err(src.whole_file(format!("a [{table}] table without an [ensemble] table"), help));
    if raw.spectrum.is_some() {
        return refusal(
            "spectrum",
            "add [ensemble] (see the README's \"Ensembles\") or remove [spectrum]; `rovib run` writes dipole.csv with \
             run.outputs = [..., \"dipole\"]",
        );
    }
    if raw.collision.is_some() {
        return refusal(
            "collision",
            "add [ensemble] with method = \"collision\" (see docs/src/howto/collisions.md) or remove [collision]",
        );
    }
    if raw.pairs.is_some() {
        return refusal(
            "pairs",
            "add [ensemble] (pair states classify an ensemble's sampled states) or remove [pairs]",
        );
    }
    if raw.statistics.is_some() {
        return refusal("statistics", "add [ensemble] (see docs/src/reference/ensemble.md) or remove [statistics]");
    }
    Ok(())
}

/// A frozen coordinate has zero velocity; a velocity or momentum given for it would leak into the
/// others through the metric: refuses it where it is written.
fn no_velocity_for_frozen(src: &Source<'_>, initial: &Initial, frozen: &[Spanned<String>]) -> Result<(), FileError> {
    let Initial::Internal { momenta, .. } = initial else { return Ok(()) };
    let (given, what) = match momenta {
        Momenta::P(p) => (p, "p"),
        Momenta::Qdot(qd) => (qd, "qdot"),
    };
    for (name, value) in given {
        if *value != 0.0 && frozen.iter().any(|f| f.get_ref() == name.get_ref()) {
            return Err(src.error(
                name.span(),
                format!("`{}` is frozen (run.frozen) but {what} gives it {}", name.get_ref(), Compact(*value)),
                format!(
                    "a frozen coordinate has zero velocity: remove `{}` from {what}, or unfreeze it",
                    name.get_ref()
                ),
            ));
        }
    }
    Ok(())
}

fn unit<U: Copy>(
    src: &Source<'_>,
    given: Option<&Spanned<String>>,
    default: U,
    parse: impl Fn(&str) -> Option<U>,
    what: &str,
    allowed: &str,
) -> Result<U, FileError> {
    match given {
        None => Ok(default),
        Some(s) => parse(s.get_ref()).ok_or_else(|| {
            src.error(s.span(), format!("unknown {what} unit `{}`", s.get_ref()), format!("use one of {allowed}"))
        }),
    }
}

fn positive(src: &Source<'_>, x: &Spanned<f64>, what: &str) -> Result<f64, FileError> {
    let v = *x.get_ref();
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(src.error(
            x.span(),
            format!("`{what}` must be a positive finite number, got {}", Compact(v)),
            "write a number greater than 0",
        ))
    }
}

fn finite(src: &Source<'_>, x: &Spanned<f64>, what: &str) -> Result<f64, FileError> {
    let v = *x.get_ref();
    if v.is_finite() {
        Ok(v)
    } else {
        Err(src.error(x.span(), format!("`{what}` is not a finite number"), "write a finite number"))
    }
}

fn triple(src: &Source<'_>, v: &Spanned<Vec<f64>>, what: &str, scale: f64) -> Result<[f64; 3], FileError> {
    let values = v.get_ref();
    if values.len() != 3 {
        return Err(src.error(
            v.span(),
            format!("`{what}` has {} entries, expected 3", values.len()),
            format!("write {what} = [x, y, z]"),
        ));
    }
    if values.iter().any(|x| !x.is_finite()) {
        return Err(src.error(v.span(), format!("`{what}` has a non-finite entry"), "write finite numbers"));
    }
    let au = [values[0] * scale, values[1] * scale, values[2] * scale];
    if au.iter().any(|x| !x.is_finite()) {
        return Err(src.error(
            v.span(),
            format!("`{what}` overflows in atomic units ([{}])", au.map(|x| Compact(x).to_string()).join(", ")),
            "write numbers that stay finite in atomic units (bohr, ħ, bohr per ħ/E_h)",
        ));
    }
    Ok(au)
}

/// A table of numbers by name, unscaled (the scale of each entry depends on the coordinate,
/// which is known only with the molecule), checked finite.
fn named_numbers(src: &Source<'_>, table: &RawTable<f64>, what: &str) -> Result<Vec<Named<f64>>, FileError> {
    table.get_ref().iter().map(|(k, v)| Ok((k.clone(), finite(src, v, &format!("{what}.{}", k.get_ref()))?))).collect()
}

fn named_triples(
    src: &Source<'_>,
    table: &RawTable<Vec<f64>>,
    what: &str,
    scale: f64,
) -> Result<Vec<Named<[f64; 3]>>, FileError> {
    table
        .get_ref()
        .iter()
        .map(|(k, v)| Ok((k.clone(), triple(src, v, &format!("{what}.{}", k.get_ref()), scale)?)))
        .collect()
}

/// The scene's units as factors to atomic units. Numbers given per coordinate (q, qdot) are
/// kept in the scene's units until the molecule tells which coordinates are lengths and which
/// are angles, and in which unit each is declared.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct CoordinateScale {
    /// Bohr per scene length unit; `None` when the scene gives no `units.length`: then each
    /// coordinate's value is in the unit its definition declares (e.g. Å for water's r1).
    pub length: Option<f64>,
    /// Radians per scene angle unit; `None`: each coordinate's declared unit (e.g. degrees).
    pub angle: Option<f64>,
    /// Atomic units of time per scene time unit.
    pub time: f64,
}

impl CoordinateScale {
    /// A value of a coordinate declared with `unit`, given in the scene's length or angle unit
    /// (without one, in `unit`), in atomic units (bohr or rad).
    pub fn coordinate_to_au(&self, unit: CoordinateUnit, value: f64) -> f64 {
        value * self.factor(unit)
    }

    /// A velocity of a coordinate declared with `unit`, given in the scene's length or angle
    /// unit (without one, in `unit`) per its time unit, in atomic units (bohr or rad per ħ/E_h).
    pub fn velocity_to_au(&self, unit: CoordinateUnit, value: f64) -> f64 {
        value * self.factor(unit) / self.time
    }

    fn factor(&self, unit: CoordinateUnit) -> f64 {
        match unit {
            CoordinateUnit::Length(_) => self.length.unwrap_or(unit.in_atomic_units()),
            CoordinateUnit::Angle(_) => self.angle.unwrap_or(unit.in_atomic_units()),
        }
    }
}

fn initial(src: &Source<'_>, raw: &Spanned<RawInitial>, l: f64, a: f64, t: f64) -> Result<Initial, FileError> {
    let r = raw.get_ref();
    let internal_keys =
        r.q.is_some() || r.p.is_some() || r.qdot.is_some() || r.euler.is_some() || r.pe.is_some() || r.j.is_some();
    if let Some(positions) = &r.positions {
        if internal_keys {
            return Err(src.error(
                raw.span(),
                "the initial condition mixes the lab form (positions) with the internal form (q, p, qdot, euler, pe, j)",
                "give either lab-frame positions (and velocities) or internal coordinates, not both",
            ));
        }
        let velocities = match &r.velocities {
            Some(v) => named_triples(src, v, "velocities", l / t)?,
            None => Vec::new(),
        };
        return Ok(Initial::Lab {
            positions: named_triples(src, positions, "positions", l)?,
            velocities,
            span: positions.span(),
        });
    }
    if let Some(v) = &r.velocities {
        return Err(src.error(
            v.span(),
            "velocities without positions",
            "give the lab-frame positions of every atom too",
        ));
    }
    let momenta = match (&r.p, &r.qdot) {
        (Some(_), Some(qd)) => {
            return Err(src.error(
                qd.span(),
                "both p and qdot are given",
                "give the internal momenta p or the velocities qdot, not both",
            ));
        }
        (_, Some(qd)) => Momenta::Qdot(named_numbers(src, qd, "qdot")?),
        (Some(p), None) => Momenta::P(named_numbers(src, p, "p")?),
        (None, None) => Momenta::P(Vec::new()),
    };
    let rotation = match (&r.pe, &r.j) {
        (Some(_), Some(j)) => {
            return Err(src.error(
                j.span(),
                "both pe and j are given",
                "give the Euler momenta pe or the body-frame angular momentum j, not both",
            ));
        }
        (Some(pe), None) => InitialAngularMomentum::Pe(triple(src, pe, "pe", 1.0)?),
        (None, Some(j)) => InitialAngularMomentum::J(triple(src, j, "j", 1.0)?),
        (None, None) => InitialAngularMomentum::J([0.0; 3]),
    };
    let euler = match &r.euler {
        Some(e) => triple(src, e, "euler", a)?,
        // θ = π/2 keeps the default orientation far from gimbal lock.
        None => [0.0, std::f64::consts::FRAC_PI_2, 0.0],
    };
    // θ = 0 or π is an ordinary orientation for a run (the quaternion has no singularity), but
    // there the Euler momenta do not determine J (J = W p_e, and W is singular).
    if let (Some(pe), InitialAngularMomentum::Pe(values)) = (&r.pe, rotation)
        && values != [0.0; 3]
        && euler[1].sin().abs() < MIN_SIN_THETA
    {
        return Err(src.error(
            pe.span(),
            format!(
                "at θ = {} rad (|sin θ| < {}) the Euler momenta pe do not determine the angular momentum",
                Compact(euler[1]),
                Compact(MIN_SIN_THETA)
            ),
            "give the body-frame angular momentum j = [Jx, Jy, Jz] instead (it is defined at every orientation)",
        ));
    }
    let q = match &r.q {
        Some(q) => named_numbers(src, q, "q")?,
        None => Vec::new(),
    };
    Ok(Initial::Internal { q, momenta, euler, rotation })
}

/// The closest of `candidates` to `word` by edit distance (Levenshtein, `strsim`, ignoring
/// case), if it is close enough to be a typo.
pub fn did_you_mean<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let (best, d) = candidates
        .into_iter()
        .map(|c| (c, strsim::levenshtein(&word.to_lowercase(), &c.to_lowercase())))
        .min_by_key(|x| x.1)?;
    (d <= 2.max(word.len() / 3)).then_some(best)
}
