//! The energy guard of `rovib run` and `rovib ensemble` ([`energy_guard`]) and the conservation
//! diagnostics a run accumulates over its output times ([`Conservation`]).

use serde_json::{Value, json};

/// The smallest energy that relative energy errors are measured against, hartree: about kT at
/// 300 K (9.5e-4 hartree), a thermal energy scale below which H(0) (which can be 0 at a minimum
/// at rest) is no meaningful yardstick for a change. With the default `run.max_energy_error` =
/// 1e-2 a run starting at H(0) = 0 stops when |ΔH| exceeds 1e-5 hartree (2 cm⁻¹).
pub const ENERGY_SCALE_FLOOR: f64 = 1e-3;

/// What an energy change is relative to: max(|H(0)|, [`ENERGY_SCALE_FLOOR`]), hartree.
pub fn energy_scale(h0: f64) -> f64 {
    h0.abs().max(ENERGY_SCALE_FLOOR)
}

/// The energy guard of `rovib run` and `rovib ensemble`: `Err` with the message when
/// `|H − H(0)| / max(|H(0)|, ENERGY_SCALE_FLOOR)` exceeds `max_energy_error` or is NaN (a
/// non-finite energy is a runaway too). The message gives the absolute change, which is what
/// `summary.json` reports as `max_abs_energy_error_hartree`, and the scale it was divided by.
pub fn energy_guard(h0: f64, h: f64, max_energy_error: f64) -> Result<(), EnergyDrift> {
    let drift = (h - h0).abs() / energy_scale(h0);
    if drift.is_nan() || drift > max_energy_error {
        return Err(EnergyDrift { h0, h, max_energy_error });
    }
    Ok(())
}

/// An energy that moved more than `run.max_energy_error` allows ([`energy_guard`]); its message
/// gives the absolute change and the scale it was divided by.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error(
    "the energy changed by {:.3e} hartree from H(0) = {h0} hartree, {:.1e} relative to max(|H(0)|, \
     {ENERGY_SCALE_FLOOR:e} hartree) = {:e} hartree, more than run.max_energy_error = {max_energy_error:e} (the \
     step is too large or the tolerances too loose for this motion; reduce them)",
    (h - h0).abs(),
    (h - h0).abs() / energy_scale(*h0),
    energy_scale(*h0)
)]
pub struct EnergyDrift {
    /// H at the start, hartree.
    pub h0: f64,
    /// H when the guard tripped, hartree.
    pub h: f64,
    /// The allowed relative change.
    pub max_energy_error: f64,
}

/// Conservation diagnostics accumulated over the output times.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Conservation {
    /// H at the first output, hartree.
    pub initial_energy: Option<f64>,
    /// max |H(t) − H(0)| over output times, hartree.
    pub max_energy_error: f64,
    /// |J| at the first output, ħ.
    pub initial_j: f64,
    /// max | |J(t)| − |J(0)| |, ħ.
    pub max_j_change: f64,
    /// p_φ at the first output, ħ.
    pub initial_p_phi: f64,
    /// max |p_φ(t) − p_φ(0)|, ħ.
    pub max_p_phi_change: f64,
    /// The lab-frame angular momentum about the centre of mass at the first output, ħ.
    pub initial_lab_l: [f64; 3],
    /// max |L(t) − L(0)| (vector difference), ħ.
    pub max_lab_l_change: f64,
    /// How many output times contributed.
    pub samples: u64,
}

impl Conservation {
    /// Records one output time.
    pub fn record(&mut self, energy: f64, j_abs: f64, p_phi: f64, lab_l: [f64; 3]) {
        match self.initial_energy {
            None => {
                self.initial_energy = Some(energy);
                self.initial_j = j_abs;
                self.initial_p_phi = p_phi;
                self.initial_lab_l = lab_l;
            }
            Some(h0) => {
                self.max_energy_error = self.max_energy_error.max((energy - h0).abs());
                self.max_j_change = self.max_j_change.max((j_abs - self.initial_j).abs());
                self.max_p_phi_change = self.max_p_phi_change.max((p_phi - self.initial_p_phi).abs());
                let d: f64 = lab_l.iter().zip(&self.initial_lab_l).map(|(a, b)| (a - b) * (a - b)).sum::<f64>().sqrt();
                self.max_lab_l_change = self.max_lab_l_change.max(d);
            }
        }
        self.samples += 1;
    }

    /// max |H(t) − H(0)| / [`energy_scale`]`(H(0))`: the quantity the run's energy guard
    /// (`run.max_energy_error`) compares.
    pub fn max_relative_energy_error(&self) -> f64 {
        self.max_energy_error / energy_scale(self.initial_energy.unwrap_or(0.0))
    }

    /// As JSON, for `summary.json`.
    pub fn to_json(&self) -> Value {
        json!({
            "sampled_at": "output times",
            "samples": self.samples,
            "initial_energy_hartree": self.initial_energy,
            "max_abs_energy_error_hartree": self.max_energy_error,
            "max_relative_energy_error": self.max_relative_energy_error(),
            "relative_to_hartree": energy_scale(self.initial_energy.unwrap_or(0.0)),
            "initial_abs_j_hbar": self.initial_j,
            "max_abs_j_change_hbar": self.max_j_change,
            "initial_p_phi_hbar": self.initial_p_phi,
            "max_p_phi_change_hbar": self.max_p_phi_change,
            "initial_lab_angular_momentum_hbar": self.initial_lab_l,
            "max_lab_angular_momentum_change_hbar": self.max_lab_l_change,
        })
    }
}
