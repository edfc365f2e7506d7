//! What an ensemble with `run.stop_outside` writes about its stopped trajectories:
//! `lifetimes.csv` (per output time: trajectories observed, stopped there by condition and
//! side, the survival fraction), `stops.csv` (the first stopped trajectories by index: time,
//! condition, side, value) and the `stops` part of summary.json.
//!
//! A trajectory is checked at output times: one stopped at output `t_k` left its interval
//! between `t_{k−1}` and `t_k` (an excursion out and back between two outputs is not seen, as
//! in `rovib run`). It is a completed trajectory, in the statistics at `t_0 … t_k` and not after.

use serde_json::json;

use super::quantity::Quantity;
use super::runner::{LISTED_STOPS, Outcome, Plan};
use crate::runtime::Molecule;
use crate::runtime::ensemble::Side;

const SIDES: [Side; 2] = [Side::Below, Side::Above];

/// The lines of `lifetimes.csv`: `t`, `n` (trajectories observed at t), `stopped` (stopped at
/// t: left their interval since the previous output), the survival fraction `S` after t and its
/// standard error, then the stopped count per condition and side (`NAME_below`, `NAME_above`).
/// `tu` is the time unit's name and `ts` its size in a.u.
pub fn lifetimes_csv<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    _m: &M,
    plan: &Plan<'_, M, N, NA>,
    o: &Outcome,
    tu: &str,
    ts: f64,
) -> Vec<String> {
    let l = &o.lifetimes;
    let mut header = vec![format!("t_{tu}"), "n".into(), "stopped".into(), "S".into(), "S_stderr".into()];
    for (_, name, _) in &plan.stops {
        for side in SIDES {
            header.push(format!("{name}_{}", side.name()));
        }
    }
    let mut lines = vec![header.join(",")];
    for (k, t) in plan.times.iter().enumerate() {
        let (s, e) = l.survival(k);
        let mut row = format!("{:?},{},{},{s:?},{e:?}", t / ts, l.observed(k), l.stopped(k));
        for c in 0..plan.stops.len() {
            for side in SIDES {
                row.push_str(&format!(",{}", l.stopped_by(k, c, side)));
            }
        }
        lines.push(row);
    }
    lines
}

/// The lines of `stops.csv`: the first [`LISTED_STOPS`] stopped trajectories by index, with the
/// output time of the stop, the coordinate, the side and its value (a.u.).
pub fn stops_csv<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    plan: &Plan<'_, M, N, NA>,
    o: &Outcome,
    tu: &str,
    ts: f64,
) -> Vec<String> {
    let mut lines = vec![format!("index,t_{tu},coordinate,side,value,unit")];
    for s in &o.first_stops {
        let (i, name, _) = plan.stops[s.condition];
        let unit = Quantity::Coordinate(i).unit(m);
        lines.push(format!("{},{:?},{name},{},{:?},{unit}", s.index, s.time / ts, s.side.name(), s.value));
    }
    lines
}

/// summary.json's `stops`: the conditions, the stopped counts by condition and side, the
/// survivors and where the details are; `null` without stop conditions.
pub fn summary<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    plan: &Plan<'_, M, N, NA>,
    o: &Outcome,
    ts: f64,
) -> serde_json::Value {
    if plan.stops.is_empty() {
        return serde_json::Value::Null;
    }
    let l = &o.lifetimes;
    let last = plan.times.len().saturating_sub(1);
    let listed = o.first_stops.len() as u64;
    json!({
        "checked": "at output times: a trajectory stopped at t left its interval after the previous output time",
        "statistics": "a stopped trajectory is completed: its outputs up to the stop are in the statistics, later \
                       output times are over the trajectories still running (column n of ensemble.csv)",
        "conditions": plan.stops.iter().enumerate().map(|(c, &(i, name, [low, high]))| json!({
            "coordinate": name,
            "bounds": [low, high],
            "unit": Quantity::Coordinate(i).unit(m),
            "stopped_below": l.total_by(c, Side::Below),
            "stopped_above": l.total_by(c, Side::Above),
        })).collect::<Vec<_>>(),
        "stopped": l.total_stopped(),
        "ran_to_end": o.completed - l.total_stopped().min(o.completed),
        "survival_at_end": l.survival(last).0,
        "first_stop_time": (0..plan.times.len()).find(|&k| l.stopped(k) > 0).map(|k| plan.times[k] / ts),
        "lifetimes_file": "lifetimes.csv",
        "stops_file": "stops.csv",
        "stops_listed": listed,
        "stops_listed_cap": LISTED_STOPS,
    })
}
