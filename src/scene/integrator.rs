//! The `[integrator]` table: one variant per method, selected by `method`, each a serde struct
//! of the keys it takes (`#[serde(deny_unknown_fields)]`, one `Option<Spanned<T>>` field per
//! key) checked by its own [`Keys::into_method`] where the file can point at each value. The
//! defaults are the runtime's own (`Dop853Options::default()` and the others: rtol = atol =
//! 1e-10, `max_steps` = [`DEFAULT_MAX_STEPS`]), and what this accepts the solver accepts.
//!
//! The table is read as a variant table ([`super::variant`]): the tag first, then the rest of
//! the table into the variant's struct. A key another method takes is refused at the key,
//! naming the methods that take it; any other unknown key at the key with a did-you-mean and
//! the method's keys; an unknown method at its value with a did-you-mean.
//!
//! # Adding an integrator
//!
//! Three files of code, and the scene reference:
//!
//! 1. `runtime/src/integrate/NAME.rs`: the solver, its options and their `validate`.
//! 2. `runtime/src/integrate/mod.rs`: its `mod` line, a `Method` variant (with its arms in
//!    `Method::name`, `Method::validate` and the `Serialize` of summary.json) and an
//!    `Integrator` variant (its arms in `Integrator::new` and `Integrator::integrate`).
//! 3. This file: a keys struct deriving `Deserialize` with `deny_unknown_fields`, its
//!    [`Keys`] implementation (`NAME`, `SUMMARY`, `KIND`, `into_method`: each value checked at
//!    its place, [`max_steps`] and [`fixed_step`] for the keys methods share), and its line in
//!    `integrators!`. The refusal of other methods' keys, the did-you-mean and the list of
//!    methods in the messages follow from these.
//!
//! Its keys then go into the guide's scene reference (`docs/src/reference/scene.md`). Nothing
//! else in the workspace matches every method: the other matches on `Method` single out DOP853
//! (the chart switch, SIMD lanes, `--resume`) and let every other method through.

use std::ops::Range;

use serde::Deserialize;
use serde::de::DeserializeOwned;
use toml::Spanned;

use crate::runtime::diagnostic::{Compact, FileError, Source};
use crate::runtime::integrate::{
    DEFAULT_MAX_STEPS, Dop853Options, GaussLegendreOptions, Method, Rk4Options, fixed_step_count,
};

use super::variant::{RawVariantTable, Variant, VariantTable, fields};
use super::{MIN_RTOL, positive};

/// Where the guide lists every key: the help of a key no method takes and of a missing `method`.
const KEYS_HELP: &str = "docs/src/reference/scene.md (the guide's scene reference) lists every key";

/// How a method chooses its steps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    /// By error control, to tolerances.
    Adaptive,
    /// A fixed step given in the scene.
    FixedStep,
}

impl Kind {
    /// As messages name it.
    fn word(self) -> &'static str {
        match self {
            Kind::Adaptive => "adaptive",
            Kind::FixedStep => "fixed-step",
        }
    }

    /// The keys that set how a method of this kind steps: a method of the other kind refuses
    /// them naming its own kind ("`step` does not apply to the adaptive dop853 method").
    fn step_keys(self) -> &'static [&'static str] {
        match self {
            Kind::Adaptive => &["rtol", "atol", "min_step"],
            Kind::FixedStep => &["step"],
        }
    }

    fn other(self) -> Self {
        match self {
            Kind::Adaptive => Kind::FixedStep,
            Kind::FixedStep => Kind::Adaptive,
        }
    }
}

/// What a method's keys are checked against: the scene's time unit and run, where the table and
/// its `method` are written.
struct Context<'a> {
    src: &'a Source<'a>,
    /// a.u. of time per scene time unit.
    t: f64,
    /// The run's end and output interval, a.u.
    t_end: f64,
    output_interval: f64,
    /// Where `method = ...` is written (a missing required key is reported there).
    name_span: Range<usize>,
}

/// One method of `[integrator]`: the struct of the keys it takes (besides `method`).
trait Keys: DeserializeOwned {
    /// Its `method = "..."`.
    const NAME: &'static str;
    /// What it is, in the list of methods of the unknown-method help.
    const SUMMARY: &'static str;
    /// How it chooses its steps.
    const KIND: Kind;

    /// Checks the keys, each error at its place, into the runtime's method.
    fn into_method(self, cx: &Context<'_>) -> Result<Method, FileError>;

    /// The refusal of a key of another method.
    fn not_applicable(key: &str) -> String {
        let kind = Self::KIND;
        if kind.other().step_keys().contains(&key) {
            format!("`{key}` does not apply to the {} {} method", kind.word(), Self::NAME)
        } else {
            format!("`{key}` does not apply to the {} method", Self::NAME)
        }
    }
}

/// Defines, for the methods listed (`Variant(KeysType)`, in the order messages list them),
/// [`Integrator`] (the table read: one variant per method), [`METHODS`] and the dispatch.
macro_rules! integrators {
    ($($variant:ident($keys:ty)),* $(,)?) => {
        /// The `[integrator]` table read into the keys of the method it names.
        enum Integrator {
            $($variant($keys),)*
        }

        /// The methods a scene names.
        const METHODS: &[&str] = &[$(<$keys as Keys>::NAME),*];

        /// Every method's name and keys.
        fn variants() -> Vec<Variant> {
            vec![$(Variant { name: <$keys as Keys>::NAME, keys: fields::<$keys>() }),*]
        }

        /// Every method's name and what it is, for the unknown-method help.
        const SUMMARIES: &[(&str, &str)] = &[$((<$keys as Keys>::NAME, <$keys as Keys>::SUMMARY)),*];

        impl Integrator {
            /// The keys of the method `table` names.
            fn read(table: &VariantTable<'_>) -> Result<Self, FileError> {
                let every = variants();
                $(
                    if table.name() == <$keys as Keys>::NAME {
                        let keys = table.keys::<$keys>(&every, <$keys as Keys>::not_applicable, KEYS_HELP)?;
                        return Ok(Self::$variant(keys));
                    }
                )*
                let listed: Vec<String> = SUMMARIES.iter().map(|(n, s)| format!("\"{n}\" ({s})")).collect();
                let listed: Vec<&str> = listed.iter().map(String::as_str).collect();
                Err(table.unknown("integrator", METHODS, &format!("use {}", or_list(&listed))))
            }

            /// The runtime's method ([`Keys::into_method`]).
            fn into_method(self, cx: &Context<'_>) -> Result<Method, FileError> {
                match self {
                    $(Self::$variant(keys) => keys.into_method(cx),)*
                }
            }
        }
    };
}

integrators! {
    Dop853(Dop853Keys),
    GaussLegendre(GaussLegendreKeys),
    Rk4(Rk4Keys),
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
    let table = VariantTable::read(src, raw, "method", KEYS_HELP)?;
    let cx = Context { src, t, t_end, output_interval, name_span: table.name_span() };
    let method = Integrator::read(&table)?.into_method(&cx)?;
    // Everything the solver checks has been checked above with its place; this is the backstop
    // that keeps the two in step (a failure here is a bug of this module).
    method.validate().map_err(|e| {
        src.error(table.span(), format!("invalid integrator settings: {e}"), "see docs/src/reference/scene.md")
    })?;
    Ok(method)
}

/// `a`, `a or b`, `a, b or c`.
fn or_list(items: &[&str]) -> String {
    match items {
        [] => String::new(),
        [one] => (*one).to_owned(),
        [init @ .., last] => format!("{} or {last}", init.join(", ")),
    }
}

// ---------------------------------------------------------------------------------------------
// The keys every method or every fixed-step method takes

/// `max_steps`, at least 1, or the default.
fn max_steps(cx: &Context<'_>, given: &Option<Spanned<u64>>) -> Result<u64, FileError> {
    match given {
        Some(x) if *x.get_ref() == 0 => Err(cx.src.error(
            x.span(),
            "`integrator.max_steps` is 0",
            format!("give at least 1, or leave it out for the default {DEFAULT_MAX_STEPS}"),
        )),
        Some(x) => Ok(*x.get_ref()),
        None => Ok(DEFAULT_MAX_STEPS),
    }
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

/// The step of the fixed-step method `name`, which it needs, in a.u.; refused if the run would
/// take more than `max_steps` (written at `max_steps_span`, if it is) of them.
fn fixed_step(
    cx: &Context<'_>,
    name: &str,
    step: &Option<Spanned<f64>>,
    max_steps: u64,
    max_steps_span: Option<Range<usize>>,
) -> Result<f64, FileError> {
    let Some(step) = step else {
        return Err(cx.src.error(
            cx.name_span.clone(),
            format!("the {name} method needs a step"),
            "add step = ... (in the scene's time unit) to [integrator]",
        ));
    };
    let h = time(cx.src, step, "integrator.step", cx.t)?;
    // The steps the run will take, exactly as the solver will cut the output intervals.
    let needed = fixed_step_count(0.0, cx.t_end, cx.output_interval, h);
    if needed > max_steps {
        return Err(cx.src.error(
            max_steps_span.unwrap_or(step.span()),
            format!(
                "the run needs {needed} steps of at most {} a.u. (run.end / integrator.step, output \
                 intervals cut into whole steps), more than integrator.max_steps = {max_steps}",
                Compact(h),
            ),
            "lengthen integrator.step, shorten run.end, or raise integrator.max_steps if you mean it",
        ));
    }
    Ok(h)
}

// ---------------------------------------------------------------------------------------------
// The methods

/// `method = "dop853"`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Dop853Keys {
    rtol: Option<Spanned<f64>>,
    atol: Option<Spanned<f64>>,
    min_step: Option<Spanned<f64>>,
    max_steps: Option<Spanned<u64>>,
}

impl Keys for Dop853Keys {
    const NAME: &'static str = "dop853";
    const SUMMARY: &'static str = "adaptive, tolerances";
    const KIND: Kind = Kind::Adaptive;

    fn into_method(self, cx: &Context<'_>) -> Result<Method, FileError> {
        let src = cx.src;
        let mut o = Dop853Options { max_steps: max_steps(cx, &self.max_steps)?, ..Default::default() };
        if let Some(x) = self.rtol {
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
        if let Some(x) = self.atol {
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
        if let Some(x) = self.min_step {
            o.min_step = time(src, &x, "integrator.min_step", cx.t)?;
            if o.min_step >= cx.t_end {
                return Err(src.error(
                    x.span(),
                    format!(
                        "`integrator.min_step` ({} a.u.) is not shorter than the run ({} a.u.)",
                        Compact(o.min_step),
                        Compact(cx.t_end)
                    ),
                    "min_step is the smallest step before the run stops as stiff: give a small fraction of run.end",
                ));
            }
        }
        Ok(Method::Dop853(o))
    }
}

/// `method = "gauss-legendre"`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct GaussLegendreKeys {
    step: Option<Spanned<f64>>,
    stages: Option<Spanned<u32>>,
    compensated: Option<Spanned<bool>>,
    max_steps: Option<Spanned<u64>>,
}

impl Keys for GaussLegendreKeys {
    const NAME: &'static str = "gauss-legendre";
    const SUMMARY: &'static str = "symplectic, fixed step";
    const KIND: Kind = Kind::FixedStep;

    fn into_method(self, cx: &Context<'_>) -> Result<Method, FileError> {
        let limit = max_steps(cx, &self.max_steps)?;
        let step = fixed_step(cx, Self::NAME, &self.step, limit, self.max_steps.map(|m| m.span()))?;
        let mut o = GaussLegendreOptions { step, max_steps: limit, ..Default::default() };
        if let Some(s) = self.stages {
            if !matches!(*s.get_ref(), 2 | 3) {
                return Err(cx.src.error(
                    s.span(),
                    format!("Gauss–Legendre with {} stages is not available", s.get_ref()),
                    "use stages = 2 (order 4) or stages = 3 (order 6)",
                ));
            }
            o.stages = *s.get_ref() as usize;
        }
        if let Some(x) = self.compensated {
            o.compensated = *x.get_ref();
        }
        Ok(Method::GaussLegendre(o))
    }
}

/// `method = "rk4"`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Rk4Keys {
    step: Option<Spanned<f64>>,
    max_steps: Option<Spanned<u64>>,
}

impl Keys for Rk4Keys {
    const NAME: &'static str = "rk4";
    const SUMMARY: &'static str = "fixed step";
    const KIND: Kind = Kind::FixedStep;

    fn into_method(self, cx: &Context<'_>) -> Result<Method, FileError> {
        let limit = max_steps(cx, &self.max_steps)?;
        let step = fixed_step(cx, Self::NAME, &self.step, limit, self.max_steps.map(|m| m.span()))?;
        Ok(Method::Rk4(Rk4Options { step, max_steps: limit }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_has_its_own_name_and_the_messages_list_them() {
        let every = variants();
        assert_eq!(every.iter().map(|v| v.name).collect::<Vec<_>>(), METHODS);
        assert_eq!(every[0].keys, ["rtol", "atol", "min_step", "max_steps"]);
        for (i, v) in every.iter().enumerate() {
            assert!(every[..i].iter().all(|w| w.name != v.name), "two methods are called {}", v.name);
            assert!(!v.keys.contains(&"method"), "{}: `method` is the tag", v.name);
        }
        assert_eq!(or_list(&["a", "b", "c"]), "a, b or c");
        assert_eq!(or_list(&["a"]), "a");
    }

    #[test]
    fn a_key_of_the_other_kind_names_the_kind() {
        assert_eq!(Dop853Keys::not_applicable("step"), "`step` does not apply to the adaptive dop853 method");
        assert_eq!(Dop853Keys::not_applicable("stages"), "`stages` does not apply to the dop853 method");
        assert_eq!(Rk4Keys::not_applicable("rtol"), "`rtol` does not apply to the fixed-step rk4 method");
        assert_eq!(Rk4Keys::not_applicable("compensated"), "`compensated` does not apply to the rk4 method");
    }
}
