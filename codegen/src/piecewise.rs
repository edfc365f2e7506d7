//! The definition check for piecewise potentials: jumps in value and gradient at the branch
//! boundaries of `if`/`select` (and `abs`, `min`, `max`), reported as build notes.
//!
//! Each distinct condition `x < y` of the potential is looked for along random segments in the
//! coordinates' box (the declared range around the reference geometry, see `sample_box`): where
//! `x − y` changes sign along a segment, bisection finds the boundary, and the potential and its
//! gradient are compared just before and just after it. A value jump larger than
//! [`VALUE_TOLERANCE`] or a gradient jump larger than [`GRADIENT_TOLERANCE`] (relative to the
//! size of the gradient, plus an absolute floor) gives one note per condition, naming the
//! condition, the jump and the place. A kink (`abs` at 0) is a gradient jump. Conditions that
//! never change sign in the box are not checked; conditions that do not depend on the
//! coordinates never jump.

use crate::definition::Definition;
use crate::expr::{ExprId, Graph, Node};
use rand::{RngExt as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;

/// Segments sampled in the box.
const SEGMENTS: usize = 96;

/// Bisection steps locating a boundary on a segment (2⁻⁴⁸ of the segment).
const BISECTIONS: usize = 48;

/// Conditions examined at most (the first in graph order), so that a surface with thousands of
/// branches does not slow the build.
const MAX_CONDITIONS: usize = 64;

/// A value jump (hartree) above `VALUE_TOLERANCE · (1 + |U|)` is reported.
pub const VALUE_TOLERANCE: f64 = 1e-9;

/// A gradient jump (hartree per atomic unit) above `GRADIENT_TOLERANCE · (1 + |∇U|)` is reported.
pub const GRADIENT_TOLERANCE: f64 = 1e-6;

/// The box the samples are drawn from, per coordinate in atomic units: the declared range, cut
/// to the reference ± max(|reference|, 1) (± π for angles); `None` without a reference geometry.
fn sample_box(def: &Definition) -> Option<Vec<(f64, f64)>> {
    def.coordinates
        .iter()
        .map(|c| {
            let scale = c.unit.in_atomic_units();
            let reference = c.reference? * scale;
            let (low, high) = (c.range.0 * scale, c.range.1 * scale);
            let half = match c.unit {
                crate::units::CoordinateUnit::Angle(_) => std::f64::consts::PI,
                crate::units::CoordinateUnit::Length(_) => reference.abs().max(1.0),
            };
            Some(((reference - half).max(low), (reference + half).min(high)))
        })
        .collect()
}

/// Notes for the build: one per condition of the potential at whose boundary the potential or
/// its gradient jumps. `gradient` is ∂U/∂q (hartree per atomic unit).
pub fn jump_notes(def: &Definition, potential: ExprId, gradient: &[ExprId]) -> Vec<String> {
    let g = &def.graph;
    let reachable = g.reachable(&[potential]);
    let mut conditions: Vec<(ExprId, ExprId, &'static str)> = Vec::new();
    for (i, node) in g.nodes().iter().enumerate() {
        if let (true, Node::Select(cmp, x, y, _, _)) = (reachable[i], *node)
            && !conditions.iter().any(|&(a, b, _)| (a, b) == (x, y))
            && conditions.len() < MAX_CONDITIONS
        {
            conditions.push((x, y, cmp.symbol()));
        }
    }
    let Some(bounds) = sample_box(def).filter(|_| !conditions.is_empty()) else { return Vec::new() };
    let n = def.coordinates.len();
    let vars = |q: &[f64]| {
        let mut v = vec![0.0; g.var_count()];
        v[..n].copy_from_slice(q);
        v
    };
    let differences = |q: &[f64]| -> Vec<f64> {
        let roots: Vec<ExprId> = conditions.iter().flat_map(|&(x, y, _)| [x, y]).collect();
        g.eval(&roots, &vars(q)).chunks(2).map(|p| p[0] - p[1]).collect()
    };
    let mut roots = vec![potential];
    roots.extend_from_slice(gradient);
    let mut rng = ChaCha8Rng::seed_from_u64(0x5eed);
    let mut reported = vec![false; conditions.len()];
    let mut notes = Vec::new();
    for _ in 0..SEGMENTS {
        let a: Vec<f64> = bounds.iter().map(|&(lo, hi)| lo + (hi - lo) * rng.random::<f64>()).collect();
        let b: Vec<f64> = bounds.iter().map(|&(lo, hi)| lo + (hi - lo) * rng.random::<f64>()).collect();
        let at = |t: f64| -> Vec<f64> { a.iter().zip(&b).map(|(x, y)| x + t * (y - x)).collect() };
        let (da, db) = (differences(&a), differences(&b));
        for c in 0..conditions.len() {
            if reported[c] || !(da[c].is_finite() && db[c].is_finite()) || (da[c] < 0.0) == (db[c] < 0.0) {
                continue;
            }
            // Bisect on the sign of x − y.
            let (mut lo, mut hi) = (0.0, 1.0);
            for _ in 0..BISECTIONS {
                let mid = 0.5 * (lo + hi);
                let d = differences(&at(mid))[c];
                if (d < 0.0) == (da[c] < 0.0) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let (before, after) = (g.eval(&roots, &vars(&at(lo))), g.eval(&roots, &vars(&at(hi))));
            if !before.iter().chain(&after).all(|v| v.is_finite()) {
                continue;
            }
            let value_jump = (after[0] - before[0]).abs();
            let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            let gradient_jump = norm(&before[1..].iter().zip(&after[1..]).map(|(x, y)| y - x).collect::<Vec<_>>());
            let gradient_size = norm(&before[1..]).max(norm(&after[1..]));
            let value_jumps = value_jump > VALUE_TOLERANCE * (1.0 + before[0].abs());
            let gradient_jumps = gradient_jump > GRADIENT_TOLERANCE * (1.0 + gradient_size);
            if !(value_jumps || gradient_jumps) {
                continue;
            }
            reported[c] = true;
            let (x, y, symbol) = conditions[c];
            let place: Vec<String> =
                def.coordinates.iter().zip(at(lo)).map(|(c, q)| format!("{} = {q:.6}", c.name)).collect();
            notes.push(format!(
                "molecule `{}`: the potential is not smooth at the boundary of the condition `{} {symbol} {}` \
                 (in atomic units): across it the value jumps by {value_jump:.3e} hartree and the gradient by \
                 {gradient_jump:.3e} hartree/a.u., near {} (bohr, rad). Trajectories crossing it see a kick; make \
                 the branches meet there (value and gradient) if that is not intended",
                def.name,
                g.display(x),
                g.display(y),
                place.join(", ")
            ));
        }
    }
    notes
}

/// Whether any node of `g` is a branch (for callers that skip the check otherwise).
pub fn has_branches(g: &Graph) -> bool {
    g.nodes().iter().any(|n| matches!(n, Node::Select(..)))
}
