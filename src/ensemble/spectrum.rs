//! The classical infrared spectrum of an ensemble: `spectrum.csv` and `spectrum.svg`, written
//! when the scene's `[statistics] correlations` include `mu_x`, `mu_y` and `mu_z` (the lab-frame
//! dipole of a molecule with a dipole surface).
//!
//! C(τ) = ⟨μ_lab(0)·μ_lab(τ)⟩ is the sum of the three components' autocorrelations, each of
//! the Hann-tapered fluctuation about its trajectory's time mean
//! ([`crate::runtime::ensemble::CorrelationWorkspace::tapered_autocorrelation`]), averaged over
//! trajectories; the transform and quantum corrections are [`crate::runtime::spectrum`]'s
//! (docs/src/reference/equations.md, section 11).

use std::path::{Path, PathBuf};

#[cfg(feature = "svg")]
use super::plot::{Content, Panel, svg};
use super::quantity::Quantity;
use super::runner::{Accumulators, Plan};
use crate::error::Error;
use crate::output::OutputFile;
use crate::runtime::Molecule;
use crate::runtime::spectrum::{QuantumCorrection, Spectrum};

/// The grid is this many times finer than 1/(2T) (zero padding; interpolation only).
pub const PADDING: usize = 4;

/// The highest wavenumber written by default, cm⁻¹ (`[spectrum] max_wavenumber`; also limited by
/// the output interval's Nyquist limit).
pub const MAX_WAVENUMBER: f64 = super::spectrum_scene::DEFAULT_MAX_WAVENUMBER;

/// Loschmidt's number, the number density of an ideal gas at 273.15 K and 101 325 Pa (one
/// amagat), per cm³ (CODATA 2018).
pub const LOSCHMIDT_PER_CM3: f64 = 2.686_780_111e19;

/// Whether the plan correlates the three lab-frame dipole components (and so has a spectrum).
pub fn dipole_correlated<M, const N: usize, const NA: usize>(plan: &Plan<'_, M, N, NA>) -> bool {
    (0..3).all(|axis| plan.correlations.iter().any(|&qi| plan.quantities[qi] == Quantity::LabDipole(axis)))
}

/// The summed dipole autocorrelation ⟨μ_lab(0)·μ_lab(τ)⟩ (e²·bohr²) per lag, if the plan
/// correlates all three components and some trajectory completed: the lags on the uniform grid
/// (`Plan::correlation_lags`) that some trajectory spans.
pub fn dipole_correlation<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
) -> Option<Vec<f64>> {
    // The lags some trajectory spans (trajectories stopped by `run.stop_outside` span fewer):
    // the counts fall with the lag, so these are the first lags.
    let spanned = acc.correlations.first().map_or(0, |c| c.iter().take_while(|m| m.count() > 0).count());
    let mut c = vec![0.0; spanned.min(plan.correlation_lags())];
    for axis in 0..3 {
        let ci = plan.correlations.iter().position(|&qi| plan.quantities[qi] == Quantity::LabDipole(axis))?;
        for (sum, m) in c.iter_mut().zip(&acc.correlations[ci]) {
            *sum += m.mean();
        }
    }
    (!c.is_empty()).then_some(c)
}

/// The spectrum of the plan's dipole correlation, if it has one.
pub fn spectrum<M, const N: usize, const NA: usize>(plan: &Plan<'_, M, N, NA>, acc: &Accumulators) -> Option<Spectrum> {
    if plan.spectrum.pair() {
        return super::pair::spectrum(plan, acc);
    }
    let c = dipole_correlation(plan, acc)?;
    Some(Spectrum::from_correlation(&c, plan.interval, plan.spectrum.max_wavenumber, PADDING))
}

/// The columns of `spectrum.csv`, if the plan has a spectrum: their names and values
/// (wavenumber in cm⁻¹, the line shape and, with a temperature, the cross section under each
/// quantum correction; for a pair ensemble with its pair volume, the binary absorption
/// coefficient under each), with the spectrum they come from.
pub fn columns<M, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
    temperature: Option<f64>,
) -> Option<(Spectrum, Vec<String>, Vec<Vec<f64>>)> {
    let s = spectrum(plan, acc)?;
    let mut header = vec!["wavenumber_cm-1".to_owned(), "lineshape_e2bohr2_per_hartree".to_owned()];
    let sigmas: Vec<Vec<f64>> = match temperature {
        Some(t) => QuantumCorrection::ALL.iter().map(|&c| s.cross_section(t, c)).collect(),
        None => Vec::new(),
    };
    for (c, _) in QuantumCorrection::ALL.iter().zip(&sigmas) {
        header.push(format!("sigma_{}_cm2", c.name()));
    }
    // The binary absorption coefficient α/(ρ_A ρ_B) = σ V n₀² (cm⁻¹ amagat⁻²) of a pair
    // ensemble with its pair volume V (docs/src/reference/equations.md, section 13).
    let binary: Vec<Vec<f64>> = match plan.spectrum.pair_volume {
        Some(v) => {
            let volume_cm3 = v * (crate::runtime::units::BOHR_IN_ANGSTROM * 1e-8).powi(3);
            let scale = volume_cm3 * LOSCHMIDT_PER_CM3 * LOSCHMIDT_PER_CM3;
            sigmas.iter().map(|sigma| sigma.iter().map(|x| x * scale).collect()).collect()
        }
        None => Vec::new(),
    };
    for (c, _) in QuantumCorrection::ALL.iter().zip(&binary) {
        header.push(format!("alpha_over_rho2_{}_cm-1_amagat-2", c.name()));
    }
    let mut columns = vec![s.wavenumber.clone(), s.lineshape.clone()];
    columns.extend(sigmas);
    columns.extend(binary);
    Some((s, header, columns))
}

/// Writes `spectrum.csv` (the [`columns`]) and `spectrum.svg`; returns their paths.
pub fn write<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    plan: &Plan<'_, M, N, NA>,
    acc: &Accumulators,
    temperature: Option<f64>,
    dir: &Path,
) -> Result<Vec<PathBuf>, Error> {
    let Some((s, header, columns)) = columns(plan, acc, temperature) else { return Ok(Vec::new()) };
    let mut f = OutputFile::create(dir, "spectrum.csv")?;
    if plan.spectrum.pair() {
        f.line(&format!(
            "# pair estimator: <mu(0).mu(tau)> for tau in [-T; T] with T = {:?} a.u.; flat-top window (1 for |tau| <= \
             T/2; cos^2 taper to 0 at T); the lineshape is the spectral density per pair of the sampled region",
            plan.interval * plan.correlation_lags().saturating_sub(1) as f64
        ))?;
    } else {
        f.line(&format!("# resolution (FWHM) {:?} cm-1, Hann taper over T = {:?} a.u.", s.resolution(), s.length))?;
    }
    f.line(&header.join(","))?;
    for j in 0..s.wavenumber.len() {
        let row: Vec<String> = columns.iter().map(|c| format!("{:?}", c[j])).collect();
        f.line(&row.join(","))?;
    }
    f.flush()?;
    // The plot needs the `svg` feature; spectrum.csv holds the same figures.
    #[cfg(feature = "svg")]
    {
        let sigmas = if temperature.is_some() { QuantumCorrection::ALL.len() } else { 0 };
        Ok(vec![f.path().to_owned(), write_svg(&s, &columns[2..2 + sigmas], temperature, dir)?])
    }
    #[cfg(not(feature = "svg"))]
    Ok(vec![f.path().to_owned()])
}

/// Writes `spectrum.svg`: the cross section under the harmonic correction with a temperature,
/// else the line shape.
#[cfg(feature = "svg")]
fn write_svg(s: &Spectrum, sigmas: &[Vec<f64>], temperature: Option<f64>, dir: &Path) -> Result<PathBuf, Error> {
    let (y, label, values) = match (&sigmas.get(1), temperature) {
        (Some(sigma), Some(t)) => {
            ("σ (cm²/molecule)", format!("IR absorption at {t} K (harmonic correction)"), (*sigma).clone())
        }
        _ => ("I(ω) (e² bohr²/hartree)", "dipole line shape".to_owned(), s.lineshape.clone()),
    };
    let panel = Panel {
        title: label,
        x_label: "wavenumber (cm⁻¹)".to_owned(),
        y_label: y.to_owned(),
        // Plotted every ~resolution/6 (the file has every grid point): the plot stays small.
        content: Content::Band(
            s.wavenumber.iter().zip(&values).step_by(plot_stride(s)).map(|(&x, &v)| (x, v, 0.0)).collect(),
        ),
    };
    let path = dir.join("spectrum.svg");
    std::fs::write(&path, svg(&[panel])).map_err(|e| Error::io("cannot write", &path, e))?;
    Ok(path)
}

/// The step through the grid for the plot: points about a sixth of the resolution apart.
#[cfg(feature = "svg")]
fn plot_stride(s: &Spectrum) -> usize {
    let spacing = s.wavenumber.get(1).map_or(1.0, |w| w - s.wavenumber[0]);
    ((s.resolution() / 6.0 / spacing).floor() as usize).max(1)
}
