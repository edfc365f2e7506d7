//! The impact parameter of `[collision]`: `b_max` (b² uniform on [0, b_max²]) or contiguous
//! weighted `strata`, and the check that the initial separation lies beyond it.

use std::ops::Range;

use super::{LENGTH_UNIT, positive};
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::sample::collision::Stratum;
use crate::scene::raw::{RawCollision, RawStratum};

/// The impact-parameter strata in bohr (`length` bohr per scene unit) and whether they were
/// given as `strata` (else one stratum from `b_max`); `span` is where `[collision]` is written.
pub(super) fn strata(
    src: &Source<'_>,
    c: &RawCollision,
    length: f64,
    span: &Range<usize>,
) -> Result<(Vec<Stratum>, bool), FileError> {
    match (&c.b_max, &c.strata) {
        (Some(b), None) => {
            let b_max = positive(src, b, "b_max", LENGTH_UNIT)? * length;
            Ok((vec![Stratum { low: 0.0, high: b_max, weight: 1.0 }], false))
        }
        (None, Some(list)) => {
            if list.get_ref().is_empty() {
                return Err(src.error(list.span(), "`collision.strata` is empty", "give at least one stratum"));
            }
            let mut strata = Vec::new();
            let mut last = 0.0;
            for s in list.get_ref() {
                strata.push(stratum(src, s.get_ref(), &mut last, length)?);
            }
            Ok((strata, true))
        }
        (Some(b), Some(_)) => Err(src.error(
            b.span(),
            "both collision.b_max and collision.strata are given",
            "give b_max (b² uniform on [0, b_max²]) or strata, not both",
        )),
        (None, None) => Err(src.error(
            span.clone(),
            "[collision] needs b_max or strata",
            "add b_max = ... (scene length unit), or strata = [{ b = [low, high], weight = w }, ...]",
        )),
    }
}

/// One stratum, which must start at `last` (the previous one's end, scene units), which it
/// then moves to its own end.
fn stratum(src: &Source<'_>, s: &RawStratum, last: &mut f64, length: f64) -> Result<Stratum, FileError> {
    let b = s.b.get_ref();
    if b.len() != 2 || !b.iter().all(|x| x.is_finite()) || b[0] < 0.0 || b[0] >= b[1] || b[0] != *last {
        return Err(src.error(
            s.b.span(),
            format!("a stratum's b must be [low, high] with 0 ≤ low < high, starting where the previous ends ({last})"),
            "write contiguous strata from 0, e.g. strata = [{ b = [0, 4], weight = 1 }, { b = [4, 10], weight = 2 }]",
        ));
    }
    *last = b[1];
    let w = *s.weight.get_ref();
    if !(w.is_finite() && w > 0.0) {
        return Err(src.error(
            s.weight.span(),
            format!("a stratum's weight must be positive, got {w}"),
            "write the stratum's relative share of the trajectories",
        ));
    }
    Ok(Stratum { low: b[0] * length, high: b[1] * length, weight: w })
}

/// Refuses an initial separation `r0` (bohr) not above the largest impact parameter.
pub(super) fn check_r0_beyond_strata(
    src: &Source<'_>,
    c: &RawCollision,
    strata: &[Stratum],
    r0: f64,
    length: f64,
) -> Result<(), FileError> {
    if let Some(last) = strata.last()
        && last.high >= r0
    {
        return Err(src.error(
            c.r0.span(),
            format!("r0 must be above the largest impact parameter, {} (scene units)", last.high / length),
            "raise r0 (the initial separation) above b_max",
        ));
    }
    Ok(())
}
