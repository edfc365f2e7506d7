//! The `[run]` table's times, outputs and limits, checked where they are written (the chart,
//! frozen coordinates and the fallback switch are read by `parse_scene` directly).

use toml::Spanned;

use super::raw::RawRun;
use super::{
    DEFAULT_MAX_ENERGY_ERROR, DEFAULT_MAX_OUTPUTS, DEFAULT_MIN_METRIC_PIVOT, Named, Outputs, did_you_mean, positive,
};
use crate::runtime::diagnostic::{Compact, FileError, Source};
use crate::runtime::hamiltonian::PIVOT_TOLERANCE;

/// What `[run]` gives, in atomic units.
pub(super) struct RunKeys {
    /// `run.end` (a.u. of time).
    pub(super) t_end: f64,
    /// `run.output_interval` (a.u. of time; `end / 100` by default).
    pub(super) output_interval: f64,
    /// `run.outputs`.
    pub(super) outputs: Outputs,
    /// `run.min_metric_pivot`.
    pub(super) min_metric_pivot: f64,
    /// `run.max_energy_error`.
    pub(super) max_energy_error: f64,
    /// `run.stop_outside`.
    pub(super) stop_outside: Vec<Named<[f64; 2]>>,
}

/// Reads `run`, with `t` atomic units of time per scene unit of time.
pub(super) fn read(src: &Source<'_>, run: &RawRun, t: f64) -> Result<RunKeys, FileError> {
    let (t_end, output_interval) = times(src, run, t)?;
    Ok(RunKeys {
        t_end,
        output_interval,
        outputs: outputs(src, run.outputs.as_ref())?,
        min_metric_pivot: match &run.min_metric_pivot {
            Some(x) => min_metric_pivot(src, x)?,
            None => DEFAULT_MIN_METRIC_PIVOT,
        },
        max_energy_error: match &run.max_energy_error {
            Some(x) => positive(src, x, "run.max_energy_error")?,
            None => DEFAULT_MAX_ENERGY_ERROR,
        },
        stop_outside: match &run.stop_outside {
            None => Vec::new(),
            Some(table) => table.get_ref().iter().map(|(name, v)| interval(src, name, v)).collect::<Result<_, _>>()?,
        },
    })
}

/// `run.end` and `run.output_interval` in atomic units, finite and non-zero, with no more
/// output times than `run.max_outputs`.
fn times(src: &Source<'_>, run: &RawRun, t: f64) -> Result<(f64, f64), FileError> {
    let t_end = positive(src, &run.end, "run.end")? * t;
    let output_interval = match &run.output_interval {
        Some(dt) => positive(src, dt, "run.output_interval")? * t,
        None => t_end / 100.0,
    };
    let interval_span = run.output_interval.as_ref().map_or(run.end.span(), |d| d.span());
    for (x, what, span) in
        [(t_end, "run.end", run.end.span()), (output_interval, "run.output_interval", interval_span.clone())]
    {
        if !x.is_finite() || x == 0.0 {
            return Err(src.error(
                span,
                format!("`{what}` is {} in atomic units of time", Compact(x)),
                "give a time that is finite and non-zero in atomic units (1 a.u. = 0.0242 fs)",
            ));
        }
    }
    let max_outputs = run.max_outputs.as_ref().map_or(DEFAULT_MAX_OUTPUTS, |m| *m.get_ref());
    let outputs_asked = (t_end / output_interval).ceil() + 1.0;
    if outputs_asked > max_outputs as f64 {
        return Err(src.error(
            interval_span,
            format!(
                "the run asks for {outputs_asked:.3e} output times (end / output_interval + 1), more than {max_outputs}"
            ),
            "lengthen run.output_interval, shorten run.end, or raise run.max_outputs if you mean it",
        ));
    }
    Ok((t_end, output_interval))
}

/// `run.outputs`: the files of `crate::report::OUTPUTS`, `summary` and `restart` (the defaults
/// without the key).
fn outputs(src: &Source<'_>, list: Option<&Spanned<Vec<Spanned<String>>>>) -> Result<Outputs, FileError> {
    let Some(list) = list else {
        return Ok(Outputs { files: crate::report::Selection::defaults(), summary: true, restart: true });
    };
    let mut o = Outputs::NONE;
    for name in list.get_ref() {
        match name.get_ref().as_str() {
            "summary" => o.summary = true,
            "restart" => o.restart = true,
            other if o.files.insert(other) => {}
            other => {
                let names = crate::report::describe_outputs();
                return Err(src.error(
                    name.span(),
                    format!("unknown output `{other}`"),
                    match did_you_mean(other, crate::report::output_names()) {
                        Some(m) => format!("did you mean \"{m}\"? outputs are {names}"),
                        None => format!("outputs are {names}"),
                    },
                ));
            }
        }
    }
    Ok(o)
}

/// `run.min_metric_pivot`: a relative pivot (over the block's scale) in `[PIVOT_TOLERANCE, 1)`;
/// the runtime cannot go below `PIVOT_TOLERANCE` (it would raise a smaller threshold silently).
fn min_metric_pivot(src: &Source<'_>, x: &Spanned<f64>) -> Result<f64, FileError> {
    let v = *x.get_ref();
    if (PIVOT_TOLERANCE..1.0).contains(&v) {
        return Ok(v);
    }
    Err(src.error(
        x.span(),
        format!("`run.min_metric_pivot` must lie in [{}, 1), got {}", Compact(PIVOT_TOLERANCE), Compact(v)),
        format!(
            "a relative pivot below {} cannot be told from a singular matrix, and 1 or more stops every run; leave it \
             out for the default {}",
            Compact(PIVOT_TOLERANCE),
            Compact(DEFAULT_MIN_METRIC_PIVOT)
        ),
    ))
}

/// One `run.stop_outside` entry: `[low, high]` with `low < high`.
fn interval(src: &Source<'_>, name: &Spanned<String>, v: &Spanned<Vec<f64>>) -> Result<Named<[f64; 2]>, FileError> {
    match v.get_ref().as_slice() {
        &[low, high] if !low.is_nan() && !high.is_nan() && low < high => Ok((name.clone(), [low, high])),
        _ => Err(src.error(
            v.span(),
            format!("`run.stop_outside.{}` must be [low, high] with low < high", name.get_ref()),
            "write the interval the coordinate may stay in, e.g. [0.5, 3.0] (inf allowed)",
        )),
    }
}
