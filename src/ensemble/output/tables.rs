//! The CSV tables of an ensemble (ensemble.csv, histograms.csv, correlations.csv) as lines, and
//! the panels of their plots. Times are divided by `ts` (a.u. per unit) and named `tu`.

use crate::ensemble::EnsembleReport;
use crate::ensemble::plot::{Content, Panel};
use crate::ensemble::runner::{Accumulators, Plan};
use crate::runtime::Molecule;

/// The scene's time unit: its name and a.u. per unit.
type TimeUnit<'a> = (&'a str, f64);

/// ensemble.csv: each output time, the trajectories observed then and every quantity's mean and
/// standard error.
pub(super) fn means_csv<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    report: &EnsembleReport,
    (tu, ts): TimeUnit<'_>,
) -> Vec<String> {
    let acc = &report.outcome.statistics;
    let nm = plan.n_means;
    let mut lines = Vec::with_capacity(plan.times.len() + 1);
    let mut header = vec![format!("t_{tu}"), "n".to_owned()];
    for (name, unit) in report.quantities.iter().zip(&report.units) {
        header.push(format!("{name}_mean_{unit}"));
        header.push(format!("{name}_stderr_{unit}"));
    }
    lines.push(header.join(","));
    for (k, t) in plan.times.iter().enumerate() {
        // The trajectories observed at this time: all completed ones, less those stopped earlier.
        let mut row = format!("{:?},{}", t / ts, report.outcome.lifetimes.observed(k));
        for j in 0..nm {
            let m = &acc.means[k * nm + j];
            row.push_str(&format!(",{:?},{:?}", m.mean(), m.standard_error()));
        }
        lines.push(row);
    }
    lines
}

/// histograms.csv (one line per bin of each histogram at each of its times) and a panel per
/// histogram.
pub(super) fn histograms<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
    (tu, ts): TimeUnit<'_>,
) -> (Vec<String>, Vec<Panel>) {
    let mut lines = vec![format!("quantity,unit,t_{tu},bin_low,bin_high,count,density")];
    let mut h = 0;
    let mut panels = Vec::new();
    for (qi, _, _, at) in &plan.histograms {
        let (name, unit) = (plan.quantities[*qi].name(m), plan.quantities[*qi].unit(m));
        for &k in at {
            let hist = &acc.histograms[h];
            let mut bars = Vec::new();
            for (i, &c) in hist.counts().iter().enumerate() {
                let lo = hist.low() + i as f64 * hist.width();
                let hi = if i + 1 == hist.counts().len() { hist.high() } else { lo + hist.width() };
                let density = if hist.total() == 0 { 0.0 } else { hist.density(i) };
                lines.push(format!("{name},{unit},{:?},{lo:?},{hi:?},{c},{density:?}", plan.times[k] / ts));
                bars.push((lo, hi, density));
            }
            panels.push(Panel {
                title: format!("{name} at t = {} {tu}", tick_time(plan.times[k] / ts)),
                x_label: format!("{name} ({unit})"),
                y_label: format!("probability density (1/{unit})"),
                content: Content::Bars(bars),
            });
            h += 1;
        }
    }
    (lines, panels)
}

/// correlations.csv ([`crate::ensemble::tables::correlations`]): every number with round-trip
/// precision, `n` as an integer.
pub(super) fn correlations_csv<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
    (tu, ts): TimeUnit<'_>,
) -> Vec<String> {
    let table = crate::ensemble::tables::correlations(m, plan, acc, tu, ts);
    let mut lines = vec![table.names.join(",")];
    let rows = table.columns.first().map_or(0, Vec::len);
    for r in 0..rows {
        let mut row = format!("{:?},{}", table.columns[0][r], table.columns[1][r] as u64);
        for column in &table.columns[2..] {
            row.push_str(&format!(",{:?}", column[r]));
        }
        lines.push(row);
    }
    lines
}

/// A panel per mean: ⟨quantity⟩ ± standard error against time.
#[cfg(feature = "svg")]
pub(super) fn mean_panels<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    report: &EnsembleReport,
    (tu, ts): TimeUnit<'_>,
) -> Vec<Panel> {
    let acc = &report.outcome.statistics;
    let nm = plan.n_means;
    (0..nm)
        .map(|j| Panel {
            title: format!("⟨{}⟩ ± standard error", report.quantities[j]),
            x_label: format!("t ({tu})"),
            y_label: format!("{} ({})", report.quantities[j], report.units[j]),
            content: Content::Band(
                plan.times
                    .iter()
                    .enumerate()
                    .map(|(k, t)| {
                        let m = &acc.means[k * nm + j];
                        (t / ts, m.mean(), m.standard_error())
                    })
                    .collect(),
            ),
        })
        .collect()
}

fn tick_time(t: f64) -> String {
    let s = format!("{t:.6}");
    s.trim_end_matches('0').trim_end_matches('.').to_owned()
}
