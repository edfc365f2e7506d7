//! The two `[[collision.fragment]]` tables: each fragment's atom labels, rotation (thermal or a
//! quantum number J) and vibration (thermal or a quantum number v).

use std::ops::Range;

use toml::Spanned;

use super::positive;
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::sample::collision::{FragmentRotation, FragmentVibration};
use crate::scene::raw::{RawCollision, RawFragment};

/// The labels, rotations and vibrations of the two fragments of each.
type Fragments = ([Vec<Spanned<String>>; 2], [FragmentRotation; 2], [FragmentVibration; 2]);

/// The two fragments of `c`; `span` is where `[collision]` is written.
pub(super) fn parse(src: &Source<'_>, c: &RawCollision, span: Range<usize>) -> Result<Fragments, FileError> {
    let Some(fragments) = &c.fragment else {
        return Err(src.error(
            span,
            "[collision] needs its two fragments",
            "add two [[collision.fragment]] tables, each with atoms = [\"label\", ...]",
        ));
    };
    if fragments.get_ref().len() != 2 {
        return Err(src.error(
            fragments.span(),
            format!("a collision has two fragments, {} are given", fragments.get_ref().len()),
            "give exactly two [[collision.fragment]] tables",
        ));
    }
    let mut labels: [Vec<Spanned<String>>; 2] = [Vec::new(), Vec::new()];
    let mut rotation = [FragmentRotation::None, FragmentRotation::None];
    let mut vibration = [FragmentVibration::None, FragmentVibration::None];
    for (k, f) in fragments.get_ref().iter().enumerate() {
        let f = f.get_ref();
        labels[k] = f.atoms.get_ref().clone();
        if labels[k].is_empty() {
            return Err(src.error(f.atoms.span(), "a fragment has no atoms", "list the fragment's atom labels"));
        }
        rotation[k] = fragment_rotation(src, f)?;
        vibration[k] = fragment_vibration(src, f)?;
    }
    Ok((labels, rotation, vibration))
}

/// A fragment's rotation: `rotation_temperature` or `j`, at most one.
fn fragment_rotation(src: &Source<'_>, f: &RawFragment) -> Result<FragmentRotation, FileError> {
    match (&f.rotation_temperature, &f.j) {
        (Some(t), None) => Ok(FragmentRotation::Thermal(positive(src, t, "fragment.rotation_temperature", "kelvin")?)),
        (None, Some(j)) if (0..=i64::from(u32::MAX)).contains(j.get_ref()) => {
            Ok(FragmentRotation::Quantum(*j.get_ref() as u32))
        }
        (None, Some(j)) => {
            Err(src.error(j.span(), format!("j = {} is not a rotational quantum number", j.get_ref()), "write J ≥ 0"))
        }
        (Some(t), Some(_)) => Err(src.error(
            t.span(),
            "both rotation_temperature and j are given",
            "give rotation_temperature (thermal) or j (quasi-classical), not both",
        )),
        (None, None) => Ok(FragmentRotation::None),
    }
}

/// A fragment's vibration: `vibration_temperature` or `v`, at most one.
fn fragment_vibration(src: &Source<'_>, f: &RawFragment) -> Result<FragmentVibration, FileError> {
    match (&f.vibration_temperature, &f.v) {
        (Some(t), None) => {
            Ok(FragmentVibration::Thermal(positive(src, t, "fragment.vibration_temperature", "kelvin")?))
        }
        (None, Some(v)) if (0..=i64::from(u32::MAX)).contains(v.get_ref()) => {
            Ok(FragmentVibration::Quantum(*v.get_ref() as u32))
        }
        (None, Some(v)) => {
            Err(src.error(v.span(), format!("v = {} is not a vibrational quantum number", v.get_ref()), "write v ≥ 0"))
        }
        (Some(t), Some(_)) => Err(src.error(
            t.span(),
            "both vibration_temperature and v are given",
            "give vibration_temperature (thermal) or v (quasi-classical), not both",
        )),
        (None, None) => Ok(FragmentVibration::None),
    }
}
