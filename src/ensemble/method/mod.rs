//! `[ensemble] method`: how the initial states of an ensemble are drawn. One file per method in
//! this folder; the build script finds them (`ensemble_methods` in build.rs) and this module
//! gathers them into [`MethodSpec`] (a method read from a scene), [`BoundMethod`] (bound to a
//! molecule) and [`METHODS`], with static dispatch: nothing here lists the methods.
//!
//! A method is a type that implements [`Method`]: its name, its keys (a serde struct read from
//! the scene's one parse with every place, nested tables included), the function that checks
//! them ([`Method::read`], each error at its place), the function that binds them to a molecule
//! ([`Method::bind`], coordinate names to indices, energies against the potential), and the
//! sampler it builds ([`BoundSampler::sampler`], a [`Sampler`] of the runtime). A key that is neither
//! one every method takes nor a key of some method is refused at its place as unknown; a key of
//! another method at its place ("does not apply"); an unknown method at its place with a
//! did-you-mean.
//!
//! # Adding a sampler
//!
//! One file, `src/ensemble/method/NAME.rs` (NAME a snake-case Rust name; the type is its
//! CamelCase, `rest.rs` → `Rest`), holding a `Keys` struct (`#[derive(Deserialize)]`, one
//! `Option<Spanned<T>>` field per key, `struct Keys {}` for none), the method's type with its
//! `impl Method` (`NAME`, `read`, `bind`, `sampler`), and its sampler (a type implementing
//! `runtime::sample::Sampler`) unless it uses one of the runtime's. Measured: a toy `rest`
//! method (every trajectory at the reference geometry, at rest) added this way and a
//! 4-trajectory h2o ensemble run with it, `rovib ensemble`, changed that one file and no other
//! (`git diff --stat`: 1 file changed, 61 insertions). A sampler meant for the runtime's users
//! too goes into `runtime/src/sample/` (with its `mod` line there: a second and third file) and
//! the method file calls it. Its keys then go into the guide's ensemble reference
//! (`docs/src/reference/ensemble.md`).
//!
//! Files found by a build script are not reached by `cargo fmt` (it follows `mod` lines, and
//! these are in the generated file): CI formats this folder explicitly (`.ci/run`).

use std::fmt::Debug;
use std::ops::Range;
use std::path::Path;
use std::sync::OnceLock;

use serde::Deserialize;
use serde::de::{self, DeserializeOwned};
use toml::Spanned;

use crate::runtime::Molecule;
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::sample::{Region, SampleError, Sampler, Spec};
use crate::runtime::units::EnergyUnit;
use crate::scene::Scene;
use crate::scene::raw::RawEnsemble;
use crate::scene::spanned::{self, Value};
use crate::scene::variant::fields;

/// A method bound to a molecule of `N` coordinates: it builds the sampler. The runtime's
/// [`Spec`] is one (the built-in samplers); a method with its own sampler binds to its own type.
pub trait BoundSampler<const N: usize>: Clone + Debug {
    /// Its sampler for molecule `m` and the ensemble's `seed`.
    ///
    /// # Errors
    ///
    /// Why it cannot be sampled (the message says what to change).
    fn sampler<'m, M: Molecule<N, NA> + Sync, const NA: usize>(
        &self,
        m: &'m M,
        seed: u64,
    ) -> Result<Box<dyn Sampler<N> + 'm>, SampleError>;

    /// The runtime's [`Spec`] it is, if it is one (`[pairs]` reads the sampled region and the
    /// temperature from it).
    fn spec(&self) -> Option<&Spec<N>> {
        None
    }
}

impl<const N: usize> BoundSampler<N> for Spec<N> {
    fn sampler<'m, M: Molecule<N, NA> + Sync, const NA: usize>(
        &self,
        m: &'m M,
        seed: u64,
    ) -> Result<Box<dyn Sampler<N> + 'm>, SampleError> {
        crate::runtime::sample::sampler(m, self, seed)
    }

    fn spec(&self) -> Option<&Spec<N>> {
        Some(self)
    }
}

/// One sampling method of `[ensemble]`: one file of this folder.
pub trait Method: Clone + Debug + Sized {
    /// Its `method = "..."`.
    const NAME: &'static str;

    /// The keys of `[ensemble]` it takes, besides those every method takes: a serde struct of
    /// `Option<Spanned<T>>` fields (not `deny_unknown_fields`: the table holds the common keys,
    /// and a key of no method is refused before). Its fields' names are the method's keys, in the
    /// order messages list them.
    type Keys: DeserializeOwned;

    /// What [`Method::bind`] makes of it for a molecule of `N` coordinates (the sampler's
    /// parameters in atomic units), which builds the sampler ([`BoundSampler`]; the runtime's
    /// [`Spec`] is one).
    type Bound<const N: usize>: BoundSampler<N>;

    /// Checks its keys, each error at its place (a missing required key at the method's:
    /// [`Context::needs`]), converted to atomic units (energies in hartree, temperatures in
    /// kelvin) with names not yet bound.
    ///
    /// # Errors
    ///
    /// A value out of range or a missing key, at its place.
    fn read(keys: Self::Keys, cx: &Context<'_>) -> Result<Self, FileError>;

    /// Binds it to molecule `m`, with one line saying how the states are drawn (summary.json).
    ///
    /// # Errors
    ///
    /// A name the molecule does not have, or a value impossible for it, at its place.
    fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        cx: &Binding<'_>,
    ) -> Result<(Self::Bound<N>, String), FileError>;

    /// The temperature of a canonical ensemble, kelvin (the spectrum's detailed-balance factor).
    fn temperature(&self) -> Option<f64> {
        None
    }

    /// A file the states are read from: its bytes identify the run with the scene's (checkpoint).
    fn input_file(&self) -> Option<&Path> {
        None
    }
}

/// Defines, for the methods the build script found (`Variant = module::Type`, one per file of
/// this folder, in the order of the files' names), [`METHODS`], [`MethodSpec`], [`BoundMethod`]
/// and their dispatch.
macro_rules! methods {
    ($($variant:ident = $module:ident :: $ty:ident),* $(,)?) => {
        /// The sampling methods as spelt in scenes, one per file of `src/ensemble/method/`.
        pub const METHODS: &[&str] = &[$(<$module::$ty as Method>::NAME),*];

        /// A sampling method with its parameters, read and checked (energies in hartree,
        /// temperatures in kelvin, J in ħ), names not yet bound: one variant per method.
        #[derive(Clone, Debug)]
        pub enum MethodSpec {
            $(
                #[doc = concat!("`src/ensemble/method/", stringify!($module), ".rs`.")]
                $variant($module::$ty),
            )*
        }

        /// A sampling method bound to a molecule of `N` coordinates: one variant per method.
        #[derive(Clone, Debug)]
        pub enum BoundMethod<const N: usize> {
            $(
                #[doc = concat!("`src/ensemble/method/", stringify!($module), ".rs`.")]
                $variant(<$module::$ty as Method>::Bound<N>),
            )*
        }

        impl MethodSpec {
            /// The method called `name`, its keys read; `None` when no method is called so.
            fn read_named(name: &str, cx: &Context<'_>) -> Option<Result<Self, FileError>> {
                $(
                    if name == <$module::$ty as Method>::NAME {
                        return Some(read_method::<$module::$ty>(cx).map(Self::$variant));
                    }
                )*
                None
            }

            /// Every method's name and keys, in the order of [`METHODS`].
            fn every() -> Vec<(&'static str, &'static [&'static str])> {
                vec![$((<$module::$ty as Method>::NAME, fields::<<$module::$ty as Method>::Keys>())),*]
            }

            /// Its `method = "..."`.
            pub fn name(&self) -> &'static str {
                match self {
                    $(Self::$variant(_) => <$module::$ty as Method>::NAME,)*
                }
            }

            /// The temperature of a canonical ensemble ([`Method::temperature`]).
            pub fn temperature(&self) -> Option<f64> {
                match self {
                    $(Self::$variant(x) => x.temperature(),)*
                }
            }

            /// The file the states are read from ([`Method::input_file`]).
            pub fn input_file(&self) -> Option<&Path> {
                match self {
                    $(Self::$variant(x) => x.input_file(),)*
                }
            }

            /// Binds the method to molecule `m` ([`Method::bind`]).
            ///
            /// # Errors
            ///
            /// A name the molecule does not have, or a value impossible for it, at its place.
            pub fn bind<M: Molecule<N, NA>, const N: usize, const NA: usize>(
                &self,
                m: &M,
                cx: &Binding<'_>,
            ) -> Result<(BoundMethod<N>, String), FileError> {
                match self {
                    $(Self::$variant(x) => {
                        x.bind::<M, N, NA>(m, cx).map(|(b, description)| (BoundMethod::$variant(b), description))
                    })*
                }
            }
        }

        impl<const N: usize> BoundMethod<N> {
            /// Its sampler for molecule `m` and the ensemble's `seed` ([`BoundSampler::sampler`]).
            ///
            /// # Errors
            ///
            /// Why it cannot be sampled (the message says what to change).
            pub fn sampler<'m, M: Molecule<N, NA> + Sync, const NA: usize>(
                &self,
                m: &'m M,
                seed: u64,
            ) -> Result<Box<dyn Sampler<N> + 'm>, SampleError> {
                match self {
                    $(Self::$variant(b) => b.sampler::<M, NA>(m, seed),)*
                }
            }

            /// The runtime's [`Spec`] it is, if it is one ([`BoundSampler::spec`]).
            pub fn spec(&self) -> Option<&Spec<N>> {
                match self {
                    $(Self::$variant(b) => b.spec(),)*
                }
            }
        }
    };
}

// The `mod` line of every file of this folder and `methods!` with their types (@generated).
include!(concat!(env!("OUT_DIR"), "/ensemble_methods.rs"));

/// Where the guide lists every key of `[ensemble]` (the help of a key no method takes or of a
/// value of the wrong type).
pub(crate) const KEYS_HELP: &str =
    "docs/src/reference/ensemble.md (the guide's ensemble reference) lists every key of [ensemble] and [statistics]";

/// What a method's [`Method::read`] is given: the scene, its `[ensemble]` table and the keys
/// every method takes.
pub struct Context<'a> {
    scene: &'a Scene,
    src: &'a Source<'a>,
    common: &'a RawEnsemble,
    table: &'a Spanned<Value>,
}

/// What a method's [`Method::bind`] is given: the scene and where its keys are.
pub struct Binding<'a> {
    scene: &'a Scene,
    src: Source<'a>,
    method_span: Range<usize>,
    trajectories: (u64, Range<usize>),
}

/// `region = { energy_cap = ..., limits = { name = [lo, hi] } }` as written (the thermal and
/// microcanonical methods' key).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionKeys {
    energy_cap: Option<Spanned<f64>>,
    #[serde(default)]
    limits: std::collections::BTreeMap<Spanned<String>, Spanned<Vec<f64>>>,
}

/// A region read and checked: the cap in hartree, limits in the scene's units until bound.
#[derive(Clone, Debug, Default)]
pub struct RegionSpec {
    /// The cap on `U(q) − U(q_ref)`, hartree, and where it is written.
    pub energy_cap: Option<(f64, Range<usize>)>,
    /// Limits by coordinate name, in the scene's length or angle unit.
    pub limits: Vec<(Spanned<String>, [f64; 2])>,
}

/// Refuses a key of `[ensemble]` (`table`) that neither every method nor some method takes: at
/// its place, as serde refuses an unknown field.
pub(crate) fn refuse_unknown_keys(src: &Source<'_>, table: &Spanned<Value>) -> Result<(), FileError> {
    let known = every_key();
    for (key, _) in table.get_ref().entries() {
        if !known.contains(&key.get_ref().as_str()) {
            let e = <spanned::Error as de::Error>::unknown_field(key.get_ref(), known);
            return Err(src.error(key.span(), e.message, KEYS_HELP));
        }
    }
    Ok(())
}

/// Every key of `[ensemble]`: those every method takes, then each method's.
fn every_key() -> &'static [&'static str] {
    static KEYS: OnceLock<Vec<&'static str>> = OnceLock::new();
    KEYS.get_or_init(|| {
        let mut all = fields::<RawEnsemble>().to_vec();
        for key in MethodSpec::every().into_iter().flat_map(|(_, keys)| keys.iter()) {
            if !all.contains(key) {
                all.push(key);
            }
        }
        all
    })
}

/// Reads the method of `[ensemble]` (`table`, whose keys every method takes are `common`):
/// an unknown method at its place with a did-you-mean, a key of another method at its place.
pub(crate) fn read(
    scene: &Scene,
    src: &Source<'_>,
    common: &RawEnsemble,
    table: &Spanned<Value>,
) -> Result<MethodSpec, FileError> {
    let cx = Context { scene, src, common, table };
    let name = common.method.get_ref().as_str();
    let every = MethodSpec::every();
    let Some((_, takes)) = every.iter().find(|(n, _)| *n == name) else {
        let help = match crate::scene::did_you_mean(name, METHODS.iter().copied()) {
            Some(m) => format!("did you mean \"{m}\"? the methods are {}", quoted(METHODS)),
            None => format!("the methods are {}", quoted(METHODS)),
        };
        return Err(src.error(common.method.span(), format!("unknown ensemble method `{name}`"), help));
    };
    let shared = fields::<RawEnsemble>();
    for (key, value) in table.get_ref().entries() {
        let key = key.get_ref().as_str();
        if !takes.contains(&key) && !shared.contains(&key) {
            let its = if takes.is_empty() { "no key of its own".to_owned() } else { takes.join(", ") };
            return Err(src.error(
                value.span(),
                format!("`{key}` does not apply to the {name} method"),
                format!("the {name} method takes {its}; remove `{key}` or choose another method"),
            ));
        }
    }
    MethodSpec::read_named(name, &cx).expect("the method was found above")
}

/// Method `T` read from the table.
fn read_method<T: Method>(cx: &Context<'_>) -> Result<T, FileError> {
    let keys = spanned::deserialize::<T::Keys>(cx.table).map_err(|e| cx.serde_error(e))?;
    T::read(keys, cx)
}

fn quoted(names: &[&str]) -> String {
    names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")
}

impl<'a> Context<'a> {
    /// The scene.
    pub fn scene(&self) -> &'a Scene {
        self.scene
    }

    /// The scene's text, for errors at a place.
    pub fn src(&self) -> &'a Source<'a> {
        self.src
    }

    /// The keys every method takes (`trajectories`, `seed`, `method`, `keep_trajectories`, ...).
    pub fn common(&self) -> &'a RawEnsemble {
        self.common
    }

    /// Where `method = ...` is written.
    pub fn method_span(&self) -> Range<usize> {
        self.common.method.span()
    }

    /// A required key missing, at the method's place.
    pub fn needs(&self, what: &str, unit: &str) -> FileError {
        let name = self.common.method.get_ref();
        self.src.error(
            self.method_span(),
            format!("the {name} method needs `{what}`"),
            format!("add {what} = ... ({unit}) to [ensemble]"),
        )
    }

    /// A serde error about the table, at its place.
    fn serde_error(&self, e: spanned::Error) -> FileError {
        crate::scene::spanned_error(self.src, &e, KEYS_HELP)
    }

    /// Hartree per unit of `ensemble.energy_unit` (hartree when it is not given).
    ///
    /// # Errors
    ///
    /// An unknown unit, at its place.
    pub fn hartree(&self, unit: &Option<Spanned<String>>) -> Result<f64, FileError> {
        let unit = match unit {
            None => EnergyUnit::Hartree,
            Some(u) => EnergyUnit::parse(u.get_ref()).ok_or_else(|| {
                let names: Vec<&str> = EnergyUnit::SPELLINGS.iter().map(|s| s.0).collect();
                self.src.error(
                    u.span(),
                    format!("unknown energy unit `{}`", u.get_ref()),
                    format!("use one of {}", names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")),
                )
            })?,
        };
        Ok(unit.in_hartree())
    }

    /// A temperature, kelvin, positive and finite.
    ///
    /// # Errors
    ///
    /// Any other, at its place.
    pub fn temperature(&self, t: &Spanned<f64>) -> Result<f64, FileError> {
        let v = *t.get_ref();
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.src.error(
                t.span(),
                format!("`ensemble.temperature` must be a positive finite number of kelvin, got {v}"),
                "write a temperature above 0 K, e.g. temperature = 300",
            ))
        }
    }

    /// A region, its cap converted with `eh` (hartree per energy unit).
    ///
    /// # Errors
    ///
    /// A cap or a limit that is not valid, at its place.
    pub fn region(&self, r: &Option<Spanned<RegionKeys>>, eh: f64) -> Result<RegionSpec, FileError> {
        let Some(r) = r else { return Ok(RegionSpec::default()) };
        let r = r.get_ref();
        let energy_cap = match &r.energy_cap {
            Some(c) if !(c.get_ref().is_finite() && *c.get_ref() > 0.0) => {
                return Err(self.src.error(
                    c.span(),
                    format!("`region.energy_cap` must be a positive finite energy, got {}", c.get_ref()),
                    "give the largest U(q) − U(reference) to sample, in ensemble.energy_unit",
                ));
            }
            Some(c) => Some((c.get_ref() * eh, c.span())),
            None => None,
        };
        let mut limits = Vec::new();
        for (name, v) in &r.limits {
            let x = v.get_ref();
            if x.len() != 2 || !x.iter().all(|x| x.is_finite()) || x[0] >= x[1] {
                return Err(self.src.error(
                    v.span(),
                    format!(
                        "the limits of `{}` must be two finite numbers [low, high] with low < high",
                        name.get_ref()
                    ),
                    format!("write {} = [low, high] in the scene's length or angle unit", name.get_ref()),
                ));
            }
            limits.push((name.clone(), [x[0], x[1]]));
        }
        Ok(RegionSpec { energy_cap, limits })
    }

    /// An energy in `ensemble.energy_unit` (`eh` hartree each), finite, in hartree.
    ///
    /// # Errors
    ///
    /// A value that is not finite, at its place.
    pub fn finite_energy(&self, x: &Spanned<f64>, what: &str, eh: f64) -> Result<f64, FileError> {
        if x.get_ref().is_finite() {
            Ok(x.get_ref() * eh)
        } else {
            Err(self.src.error(x.span(), format!("`ensemble.{what}` is not a finite number"), "write a finite energy"))
        }
    }
}

impl<'a> Binding<'a> {
    /// For the scene, its method written at `method_span` and its number of trajectories with
    /// their place.
    pub(crate) fn new(scene: &'a Scene, method_span: Range<usize>, trajectories: (u64, Range<usize>)) -> Self {
        Self { scene, src: scene.source(), method_span, trajectories }
    }

    /// The scene.
    pub fn scene(&self) -> &'a Scene {
        self.scene
    }

    /// The scene's text, for errors at a place.
    pub fn src(&self) -> &Source<'a> {
        &self.src
    }

    /// Where `method = ...` is written.
    pub fn method_span(&self) -> Range<usize> {
        self.method_span.clone()
    }

    /// The number of trajectories and where it is written.
    pub fn trajectories(&self) -> (u64, Range<usize>) {
        self.trajectories.clone()
    }

    /// The potential at `m`'s reference geometry, hartree.
    ///
    /// # Errors
    ///
    /// A molecule without one, at the method's place.
    pub fn reference_energy<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
    ) -> Result<f64, FileError> {
        let q = m.reference_geometry().ok_or_else(|| {
            self.src.error(
                self.method_span(),
                format!("{} has no reference geometry to measure energies from", m.name()),
                format!("add `reference` values to the coordinates in {}", m.source()),
            )
        })?;
        Ok(m.potential(&q))
    }

    /// A region bound to `m`: coordinate names to indices, limits in atomic units.
    ///
    /// # Errors
    ///
    /// An unknown coordinate, or limits outside its valid range, at their place.
    pub fn region<M: Molecule<N, NA>, const N: usize, const NA: usize>(
        &self,
        m: &M,
        r: &RegionSpec,
    ) -> Result<Region<N>, FileError> {
        let (src, scene) = (&self.src, self.scene);
        let coords = m.coordinates();
        let mut limits = [None; N];
        for (name, [lo, hi]) in &r.limits {
            let k = coords.iter().position(|c| c.name == name.get_ref()).ok_or_else(|| {
                super::scene::unknown_name(
                    src,
                    name,
                    &format!("{} has no coordinate", m.name()),
                    coords.iter().map(|c| c.name),
                )
            })?;
            let s = scene.units.coordinate_to_au(coords[k].unit, 1.0);
            let (rlo, rhi) = coords[k].range;
            let slack = |x: f64| 1e-12 * x.abs().max(1.0);
            if lo * s < rlo - slack(rlo) || hi * s > rhi + slack(rhi) {
                return Err(src.error(
                    name.span(),
                    format!(
                        "the limits [{lo}, {hi}] of `{}` reach outside its valid range [{}, {}] (scene units)",
                        name.get_ref(),
                        rlo / s,
                        rhi / s
                    ),
                    "give limits within the coordinate's range (a bond angle within [0, π], a length above 0)",
                ));
            }
            limits[k] = Some((lo * s, hi * s));
        }
        Ok(Region { energy_cap: r.energy_cap.as_ref().map(|c| c.0), limits })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_has_its_own_name_and_keys_that_exist() {
        let every = MethodSpec::every();
        assert_eq!(every.iter().map(|m| m.0).collect::<Vec<_>>(), METHODS);
        for (i, (name, keys)) in every.iter().enumerate() {
            assert!(every[..i].iter().all(|m| m.0 != *name), "two methods are called {name}");
            for key in *keys {
                assert!(!fields::<RawEnsemble>().contains(key), "{name}: `{key}` is a key every method takes");
            }
        }
        assert_eq!(fields::<RegionKeys>(), ["energy_cap", "limits"]);
    }
}
