//! The `[integrator]` table: one variant per method, each taking only its own keys and checking
//! its own settings where the file can point at them. The defaults are the runtime's own
//! (`Dop853Options::default()` and the others: rtol = atol = 1e-10, `max_steps` =
//! [`DEFAULT_MAX_STEPS`]), and what this accepts the solver accepts.
//!
//! A new method adds its keys to [`KEYS`], its name to [`METHODS`], and a function building its
//! [`Method`] from the table, called from [`integrator`].

use crate::runtime::diagnostic::{Compact, FileError, Source};
use crate::runtime::integrate::{
    DEFAULT_MAX_STEPS, Dop853Options, GaussLegendreOptions, Method, Rk4Options, fixed_step_count,
};
use toml::Spanned;

use super::variant::{RawVariantTable, Tagged};
use super::{MIN_RTOL, positive};

/// Every key of `[integrator]`, the tag first, in the order in which a key that does not apply
/// to the method is reported.
const KEYS: &[&str] = &["method", "rtol", "atol", "min_step", "step", "stages", "compensated", "max_steps"];

/// The methods a scene names.
const METHODS: &[&str] = &["dop853", "gauss-legendre", "rk4"];

/// What every method shares: the scene's time unit and run, and the step limit.
struct Common {
    /// a.u. of time per scene time unit.
    t: f64,
    /// The run's end and output interval, a.u.
    t_end: f64,
    output_interval: f64,
    max_steps: u64,
    /// Where `max_steps` is written, if it is.
    max_steps_span: Option<std::ops::Range<usize>>,
}

/// The `[integrator]` table, every setting checked here, where the file can point at it.
/// `t` is a.u. of time per scene time unit; `t_end` and `output_interval` are in a.u.
pub(super) fn integrator(
    src: &Source<'_>,
    raw: &RawVariantTable,
    t: f64,
    t_end: f64,
    output_interval: f64,
) -> Result<Method, FileError> {
    let table =
        Tagged::read(src, raw, KEYS, "docs/src/reference/scene.md (the guide's scene reference) lists every key")?;
    let given = table.get::<u64>("max_steps")?;
    let max_steps = match &given {
        Some(x) if *x.get_ref() == 0 => {
            return Err(src.error(
                x.span(),
                "`integrator.max_steps` is 0",
                format!("give at least 1, or leave it out for the default {DEFAULT_MAX_STEPS}"),
            ));
        }
        Some(x) => *x.get_ref(),
        None => DEFAULT_MAX_STEPS,
    };
    let common = Common { t, t_end, output_interval, max_steps, max_steps_span: given.map(|m| m.span()) };
    let method = match table.name() {
        "dop853" => dop853(src, &table, &common)?,
        "gauss-legendre" => gauss_legendre(src, &table, &common)?,
        "rk4" => rk4(src, &table, &common)?,
        _ => {
            return Err(table.unknown(
                "integrator",
                METHODS,
                "use \"dop853\" (adaptive, tolerances), \"gauss-legendre\" (symplectic, fixed step) or \"rk4\" (fixed step)",
            ));
        }
    };
    // Everything the solver checks has been checked above with its place; this is the backstop
    // that keeps the two in step (a failure here is a bug of this module).
    method.validate().map_err(|e| {
        src.error(table.span(), format!("invalid integrator settings: {e}"), "see docs/src/reference/scene.md")
    })?;
    Ok(method)
}

/// Refuses a key of another method: "`key` does not apply to the {describe(key)} method".
fn only(table: &Tagged<'_>, keys: &[&str], describe: impl Fn(&str) -> String) -> Result<(), FileError> {
    table.only(
        KEYS,
        keys,
        |key| format!("`{key}` does not apply to the {} method", describe(key)),
        "remove it, or choose a method it applies to",
    )
}

/// A time in the scene's unit, positive and finite there and in atomic units.
fn time(src: &Source<'_>, x: &Spanned<f64>, what: &str, t: f64) -> Result<f64, FileError> {
    let au = positive(src, x, what)? * t;
    if !au.is_finite() || au == 0.0 {
        return Err(src.error(
            x.span(),
            format!("`{what}` is {} in atomic units of time", Compact(au)),
            "give a time that is finite and non-zero in atomic units (1 a.u. = 0.0242 fs)",
        ));
    }
    Ok(au)
}

fn dop853(src: &Source<'_>, table: &Tagged<'_>, c: &Common) -> Result<Method, FileError> {
    only(table, &["rtol", "atol", "min_step", "max_steps"], |key| {
        if key == "step" { "adaptive dop853" } else { "dop853" }.to_owned()
    })?;
    let mut o = Dop853Options { max_steps: c.max_steps, ..Default::default() };
    if let Some(x) = table.get::<f64>("rtol")? {
        let v = *x.get_ref();
        if !(v > MIN_RTOL && v <= 1.0) {
            return Err(src.error(
                x.span(),
                format!("`integrator.rtol` must lie in (10·ε, 1] = ({MIN_RTOL:.2e}, 1], got {}", Compact(v)),
                "below 10·ε the error estimate is round-off (1e-13 is about the tightest useful); \
                 above 1 it controls nothing",
            ));
        }
        o.rtol = v;
    }
    if let Some(x) = table.get::<f64>("atol")? {
        let v = positive(src, &x, "integrator.atol")?;
        if v < f64::MIN_POSITIVE {
            return Err(src.error(
                x.span(),
                format!("`integrator.atol` = {} is subnormal (below {})", Compact(v), Compact(f64::MIN_POSITIVE)),
                "give an absolute tolerance of at least 1e-300 (1e-14 is about the tightest useful)",
            ));
        }
        o.atol = v;
    }
    if let Some(x) = table.get::<f64>("min_step")? {
        o.min_step = time(src, &x, "integrator.min_step", c.t)?;
        if o.min_step >= c.t_end {
            return Err(src.error(
                x.span(),
                format!(
                    "`integrator.min_step` ({} a.u.) is not shorter than the run ({} a.u.)",
                    Compact(o.min_step),
                    Compact(c.t_end)
                ),
                "min_step is the smallest step before the run stops as stiff: give a small fraction of run.end",
            ));
        }
    }
    Ok(Method::Dop853(o))
}

/// The step of a fixed-step method, which it needs, in a.u.; refused if the run would take more
/// than `max_steps` of them.
fn fixed_step(src: &Source<'_>, table: &Tagged<'_>, c: &Common) -> Result<f64, FileError> {
    let name = table.name();
    let Some(step) = table.get::<f64>("step")? else {
        return Err(src.error(
            table.name_span(),
            format!("the {name} method needs a step"),
            "add step = ... (in the scene's time unit) to [integrator]",
        ));
    };
    let h = time(src, &step, "integrator.step", c.t)?;
    // The steps the run will take, exactly as the solver will cut the output intervals.
    let needed = fixed_step_count(0.0, c.t_end, c.output_interval, h);
    if needed > c.max_steps {
        return Err(src.error(
            c.max_steps_span.clone().unwrap_or(step.span()),
            format!(
                "the run needs {needed} steps of at most {} a.u. (run.end / integrator.step, output \
                 intervals cut into whole steps), more than integrator.max_steps = {}",
                Compact(h),
                c.max_steps
            ),
            "lengthen integrator.step, shorten run.end, or raise integrator.max_steps if you mean it",
        ));
    }
    Ok(h)
}

fn gauss_legendre(src: &Source<'_>, table: &Tagged<'_>, c: &Common) -> Result<Method, FileError> {
    only(table, &["step", "stages", "compensated", "max_steps"], |_| "fixed-step gauss-legendre".to_owned())?;
    let mut o = GaussLegendreOptions { step: fixed_step(src, table, c)?, max_steps: c.max_steps, ..Default::default() };
    if let Some(s) = table.get::<u32>("stages")? {
        if !matches!(*s.get_ref(), 2 | 3) {
            return Err(src.error(
                s.span(),
                format!("Gauss–Legendre with {} stages is not available", s.get_ref()),
                "use stages = 2 (order 4) or stages = 3 (order 6)",
            ));
        }
        o.stages = *s.get_ref() as usize;
    }
    if let Some(x) = table.get::<bool>("compensated")? {
        o.compensated = *x.get_ref();
    }
    Ok(Method::GaussLegendre(o))
}

fn rk4(src: &Source<'_>, table: &Tagged<'_>, c: &Common) -> Result<Method, FileError> {
    only(table, &["step", "max_steps"], |key| {
        if matches!(key, "stages" | "compensated") { "rk4" } else { "fixed-step rk4" }.to_owned()
    })?;
    Ok(Method::Rk4(Rk4Options { step: fixed_step(src, table, c)?, max_steps: c.max_steps }))
}
