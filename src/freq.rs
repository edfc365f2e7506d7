//! `rovib freq --molecule NAME [--json]`: the stationary point near the reference geometry, its
//! harmonic wavenumbers and normal-mode vectors (Wilson's GF method, `runtime::modes`) and the
//! rotational constants A ≥ B ≥ C from the principal moments of inertia there.
//!
//! At a linear stationary point (HCN, CO2) the chart of internal coordinates and Euler angles is
//! singular and Wilson's GF method with it: there the modes come from the mass-weighted Cartesian
//! Hessian of `U(x)` (`runtime::cartesian_modes`), `3N − 5` of them with each bend doubly
//! degenerate, and the one rotational constant B of a linear rotor.

use std::fmt::Write as _;

use serde_json::json;

use crate::error::Error;
use crate::molecules;
use crate::runtime::cartesian_modes::{CartesianModes, is_linear};
use crate::runtime::modes::{ModesError, NormalModes, STATIONARY_TOLERANCE, stationary_point};
use crate::runtime::nalgebra::{SMatrix, SVector};
use crate::runtime::units::HARTREE_IN_WAVENUMBERS;
use crate::runtime::{KineticMatrices, Molecule, MoleculeVisitor};

/// The frequency of one hartree, E_h/h, in MHz (CODATA 2018: 6.579 683 920 502 × 10¹⁵ Hz).
pub const HARTREE_IN_MHZ: f64 = 6.579_683_920_502e9;

/// What `rovib freq` found, in the units it prints.
#[derive(Clone, Debug, PartialEq)]
pub struct Frequencies {
    /// The molecule.
    pub molecule: String,
    /// Coordinate names, in order.
    pub coordinates: Vec<String>,
    /// The stationary point, bohr and rad.
    pub q0: Vec<f64>,
    /// U there, hartree.
    pub u0: f64,
    /// Whether the stationary point is linear: then the modes are Cartesian (3N − 5 of them) and
    /// the rotor is linear (A infinite, B = C).
    pub linear: bool,
    /// Harmonic wavenumbers, cm⁻¹, ascending (empty when not a minimum): 3N − 6, or 3N − 5 at a
    /// linear stationary point.
    pub wavenumbers: Vec<f64>,
    /// Mode vectors, one per mode: in q (`δq = Σ_k l_k Q_k`, `Lᵀ G⁻¹ L = 1`), or at a linear
    /// stationary point Cartesian displacements (x, y, z of each atom in turn, in the body frame
    /// of [`Kinematics::positions`](crate::runtime::Kinematics::positions), per unit mass-weighted normal coordinate).
    pub vectors: Vec<Vec<f64>>,
    /// Principal moments of inertia, electron masses · bohr², descending constants order.
    pub moments: [f64; 3],
    /// Rotational constants A ≥ B ≥ C, cm⁻¹ (`ħ²/(2 I)`; A infinite for a linear molecule).
    pub rotational_cm: [f64; 3],
    /// The same in MHz.
    pub rotational_mhz: [f64; 3],
    /// `None` at a minimum, else why not (the imaginary mode, named).
    pub not_minimum: Option<String>,
}

/// The rotational constants `1/(2 I_k)` hartree of the principal moments of `inertia`
/// (electron masses · bohr²), sorted A ≥ B ≥ C, with those moments; infinite for a zero moment.
pub fn rotational_constants(inertia: &crate::runtime::nalgebra::Matrix3<f64>) -> ([f64; 3], [f64; 3]) {
    let e = inertia.symmetric_eigen().eigenvalues;
    let mut moments = [e[0], e[1], e[2]];
    moments.sort_by(f64::total_cmp);
    (moments, moments.map(|i| 0.5 / i))
}

struct Freq;

impl MoleculeVisitor for Freq {
    type Output = Result<Frequencies, Error>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let start = m
            .reference_geometry()
            .ok_or_else(|| Error::Message(format!("{} has no reference geometry to start from", m.name())))?;
        let q0: SVector<f64, N> = stationary_point(&m, &start).map_err(|e| {
            Error::context(format!("no stationary point of {} near its reference geometry", m.name()), e)
        })?;
        let mut x0 = SMatrix::<f64, 3, NA>::zeros();
        m.positions(&q0, &mut x0);
        let linear = is_linear(&x0);
        let (wavenumbers, vectors, not_minimum) = if linear {
            match CartesianModes::at(&m, &q0) {
                Ok(modes) => {
                    (modes.wavenumbers(), modes.vectors.iter().map(|l| l.iter().copied().collect()).collect(), None)
                }
                Err(e @ ModesError::NotMinimum { .. }) => (Vec::new(), Vec::new(), Some(e.to_string())),
                Err(e) => {
                    return Err(Error::context(
                        format!(
                            "{} is linear at its stationary point, where the internal coordinates and Euler angles are \
                             singular; its normal modes need the Cartesian Hessian",
                            m.name()
                        ),
                        e,
                    ));
                }
            }
        } else {
            match NormalModes::at(&m, &q0) {
                Ok(modes) => (
                    modes.wavenumbers().iter().copied().collect(),
                    (0..N).map(|k| modes.vectors.column(k).iter().copied().collect()).collect(),
                    None,
                ),
                Err(e @ ModesError::NotMinimum { .. }) => (Vec::new(), Vec::new(), Some(e.to_string())),
                Err(e) => return Err(Error::context("no normal modes", e)),
            }
        };
        let mut k = KineticMatrices::default();
        m.kinetic(&q0, &mut k);
        let (mut moments, mut b) = rotational_constants(&k.inertia);
        if linear {
            // The moment about the axis is zero up to rounding: a linear rotor has no A.
            moments[0] = 0.0;
            b[0] = f64::INFINITY;
        }
        Ok(Frequencies {
            molecule: m.name().to_owned(),
            coordinates: m.coordinates().iter().map(|c| c.name.to_owned()).collect(),
            q0: q0.iter().copied().collect(),
            u0: m.potential(&q0),
            linear,
            wavenumbers,
            vectors,
            moments,
            rotational_cm: b.map(|x| x * HARTREE_IN_WAVENUMBERS),
            rotational_mhz: b.map(|x| x * HARTREE_IN_MHZ),
            not_minimum,
        })
    }
}

/// The stationary point, modes and rotational constants of molecule `name`.
pub fn frequencies(name: &str) -> Result<Frequencies, Error> {
    molecules::visit(name, Freq).ok_or_else(|| Error::unknown_molecule(name))?
}

/// The text (or JSON with `json`) that `rovib freq` prints.
pub fn freq(name: &str, json: bool) -> Result<String, Error> {
    let f = frequencies(name)?;
    if json {
        let v = json!({
            "molecule": f.molecule,
            "coordinates": f.coordinates,
            "stationary_point_au": f.q0,
            "stationary_tolerance_au": STATIONARY_TOLERANCE,
            "potential_hartree": f.u0,
            "minimum": f.not_minimum.is_none(),
            "linear": f.linear,
            "mode_vectors_are": if f.linear {
                "Cartesian displacements (x, y, z of each atom), body frame, per unit mass-weighted normal coordinate"
            } else {
                "displacements of the internal coordinates q, L^T G^-1 L = 1"
            },
            "not_minimum_because": f.not_minimum,
            "wavenumbers_cm-1": f.wavenumbers,
            "mode_vectors": f.vectors,
            "principal_moments_me_bohr2": f.moments,
            "rotational_constants_cm-1": f.rotational_cm,
            "rotational_constants_mhz": f.rotational_mhz,
        });
        return Ok(format!("{v:#}\n"));
    }
    let mut s = String::new();
    let _ = writeln!(s, "{}: stationary point (Newton step < {STATIONARY_TOLERANCE:e} bohr or rad)", f.molecule);
    for (c, q) in f.coordinates.iter().zip(&f.q0) {
        let _ = writeln!(s, "  {c} = {q:.8} (bohr or rad)");
    }
    let _ = writeln!(s, "  U = {:.10} hartree", f.u0);
    match &f.not_minimum {
        None if f.linear => {
            let _ = writeln!(
                s,
                "linear: the internal coordinates and Euler angles are singular here, so the modes are those of the \
                 mass-weighted Cartesian Hessian of U(x), 3N - 5 = {}; harmonic wavenumbers, cm-1, with Cartesian \
                 displacements (x, y, z of each atom, per unit mass-weighted normal coordinate):",
                f.wavenumbers.len()
            );
            for (k, (w, v)) in f.wavenumbers.iter().zip(&f.vectors).enumerate() {
                let paired = |j: usize| f.wavenumbers.get(j).is_some_and(|x| (x - w).abs() <= 1e-6 * w);
                let note = if paired(k + 1) || (k > 0 && paired(k - 1)) { "  (doubly degenerate)" } else { "" };
                let _ = writeln!(s, "  {w:10.3}  {v:.6?}{note}");
            }
        }
        None => {
            let _ = writeln!(s, "a minimum; harmonic wavenumbers (GF), cm-1, with mode vectors in q:");
            for (w, v) in f.wavenumbers.iter().zip(&f.vectors) {
                let _ = writeln!(s, "  {w:10.3}  {v:.6?}");
            }
        }
        Some(why) => {
            let _ = writeln!(s, "not a minimum: {why}");
        }
    }
    if f.linear {
        let _ = writeln!(
            s,
            "linear rotor: rotational constant B = {:.4} cm-1 = {:.1} MHz (moment of inertia {:.6} me bohr^2)",
            f.rotational_cm[1], f.rotational_mhz[1], f.moments[1]
        );
    } else {
        let _ = writeln!(
            s,
            "rotational constants A, B, C: {:.4}, {:.4}, {:.4} cm-1 = {:.1}, {:.1}, {:.1} MHz",
            f.rotational_cm[0],
            f.rotational_cm[1],
            f.rotational_cm[2],
            f.rotational_mhz[0],
            f.rotational_mhz[1],
            f.rotational_mhz[2]
        );
    }
    Ok(s)
}
