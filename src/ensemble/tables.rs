//! An ensemble's results held in memory ([`super::EnsembleOptions::in_memory`]): the numbers of
//! correlations.csv and spectrum.csv as named columns, for a caller that writes no files. The
//! means and standard errors are the report's ([`super::EnsembleReport::mean`]). Each value is
//! the very `f64` the file would hold (the files write every number with round-trip precision).

use super::runner::{Accumulators, Plan};
use super::scene::EnsembleScene;
use crate::runtime::Molecule;
use crate::scene::Scene;

/// Named columns of numbers, as a CSV file holds them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    /// The column names (the CSV header).
    pub names: Vec<String>,
    /// One vector per column, each as long as the table.
    pub columns: Vec<Vec<f64>>,
}

impl Table {
    /// The column called `name`.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names.iter().position(|n| n == name).map(|j| self.columns[j].as_slice())
    }
}

/// What an ensemble run in memory gives back besides its report.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Tables {
    /// correlations.csv: `tau_UNIT` (the scene's time unit), `n` (the trajectories spanning the
    /// lag), and per correlated quantity `NAME_C_UNIT^2`, `NAME_C_stderr_UNIT^2`,
    /// `NAME_C_normalised`; no rows but the names when nothing is correlated.
    pub correlations: Table,
    /// spectrum.csv ([`super::spectrum::columns`]), when the ensemble has a spectrum.
    pub spectrum: Option<Table>,
}

/// The tables of a finished ensemble.
pub fn tables<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    ensemble: &EnsembleScene,
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
) -> Tables {
    let correlations = correlations(m, plan, acc, scene.time_unit.name(), scene.time_unit.in_au());
    let spectrum = super::spectrum::columns(plan, acc, ensemble.method.temperature())
        .map(|(_, names, columns)| Table { names, columns });
    Tables { correlations, spectrum }
}

/// correlations.csv's columns: each lag (in the time unit `tu`, `ts` a.u. each), the
/// trajectories covering it and every correlated quantity's C(τ), its standard error and
/// C(τ)/C(0).
pub(super) fn correlations<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
    tu: &str,
    ts: f64,
) -> Table {
    let mut names = vec![format!("tau_{tu}"), "n".to_owned()];
    for &qi in &plan.correlations {
        let (name, unit) = (plan.quantities[qi].name(m), plan.quantities[qi].unit(m));
        // A compound unit is squared as a whole: (e*bohr)^2.
        let unit = if unit.contains(['*', '/']) { format!("({unit})") } else { unit.to_owned() };
        names.push(format!("{name}_C_{unit}^2"));
        names.push(format!("{name}_C_stderr_{unit}^2"));
        names.push(format!("{name}_C_normalised"));
    }
    let mut columns = vec![Vec::new(); names.len()];
    // Lags on the uniform grid only (`Plan::correlation_lags`); `n`: the trajectories whose
    // span covers the lag, which every correlated quantity shares.
    // The pair estimator keeps τ from −T to T: row i is lag i − (lags − 1), C(0) at lags − 1.
    let zero = plan.correlation_span() - plan.correlation_lags();
    for lag in 0..plan.correlation_span() {
        let t = if lag >= zero { plan.times[lag - zero] } else { -plan.times[zero - lag] };
        columns[0].push(t / ts);
        columns[1].push(acc.correlations.first().map_or(0, |c| c[lag].count()) as f64);
        for (i, c) in acc.correlations.iter().enumerate() {
            let (mean, c0) = (c[lag].mean(), c[zero].mean());
            columns[2 + 3 * i].push(mean);
            columns[3 + 3 * i].push(c[lag].standard_error());
            columns[4 + 3 * i].push(mean / c0);
        }
    }
    Table { names, columns }
}
