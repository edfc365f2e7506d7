//! `rovib eval`: everything about one state, as one JSON object.

use rovib::runtime::diagnostic::{MAX_INPUT_BYTES, read_capped, read_text_capped};
use std::path::Path;

use serde::Deserialize;
use serde_json::{Value, json};

use rovib::Error;
use rovib::molecules;
use rovib::runtime::cartesian_system::CartesianSystem;
use rovib::runtime::charts::SWITCH_PIVOT;
use rovib::runtime::frames::{CentreOfMass, lab_of_body_any};
use rovib::runtime::hamiltonian::{
    BodyState, HamiltonianError, MetricFactor, PhaseState, body_angular_momentum, evaluate,
};
use rovib::runtime::integrate::OdeSystem;
use rovib::runtime::nalgebra::{SMatrix, SVector, Vector3};
use rovib::runtime::{KineticMatrices, Molecule, MoleculeVisitor};

/// The state file: atomic units; `p` and `pe` default to zero, `euler` to [0, π/2, 0].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StateFile {
    q: Option<Vec<f64>>,
    p: Option<Vec<f64>>,
    euler: Option<Vec<f64>>,
    pe: Option<Vec<f64>>,
}

/// A matrix as JSON: an array of rows.
fn rows<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Value {
    Value::Array((0..R).map(|i| Value::from((0..C).map(|j| m[(i, j)]).collect::<Vec<f64>>())).collect())
}

/// One array of the state file, checked: its length (what each entry is, for the fix) and that
/// every entry is finite. `file` names the state file in messages.
fn vector<const K: usize>(
    file: &str,
    field: &str,
    meaning: &str,
    values: Option<&Vec<f64>>,
    default: SVector<f64, K>,
) -> Result<SVector<f64, K>, Error> {
    let Some(values) = values else { return Ok(default) };
    if values.len() != K {
        return Err(Error::Message(format!(
            "{file}: `{field}` has {} entries, expected {K} ({meaning})",
            values.len()
        )));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::Message(format!("{file}: `{field}[{i}]` is not a finite number ({meaning})")));
    }
    Ok(SVector::from_column_slice(values))
}

struct Eval<'a> {
    state: Option<&'a StateFile>,
    /// The state file's name, for messages.
    file: &'a str,
}

impl MoleculeVisitor for Eval<'_> {
    type Output = Result<Vec<(&'static str, Value)>, Error>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let reference = m.reference_geometry();
        let q_default = reference.unwrap_or_else(SVector::zeros);
        let names: Vec<&str> = m.coordinates().iter().map(|c| c.name).collect();
        let coordinates = format!("one per coordinate of {}: {}, in bohr or rad", m.name(), names.join(", "));
        let momenta = format!("one momentum per coordinate of {}: {}", m.name(), names.join(", "));
        let state = match self.state {
            Some(s) => {
                if s.q.is_none() && reference.is_none() {
                    return Err(Error::Message(format!(
                        "{}: `q` is missing and {} has no reference geometry to default to (give q)",
                        self.file,
                        m.name()
                    )));
                }
                PhaseState {
                    q: vector(self.file, "q", &coordinates, s.q.as_ref(), q_default)?,
                    p: vector(self.file, "p", &momenta, s.p.as_ref(), SVector::zeros())?,
                    euler: vector(
                        self.file,
                        "euler",
                        "phi, theta, psi in rad",
                        s.euler.as_ref(),
                        Vector3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0),
                    )?,
                    pe: vector(self.file, "pe", "p_phi, p_theta, p_psi in hbar", s.pe.as_ref(), Vector3::zeros())?,
                }
            }
            None => PhaseState {
                q: q_default,
                euler: Vector3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0),
                ..PhaseState::zeros()
            },
        };
        let atoms = m.atoms();
        let mut fields = vec![
            ("molecule", json!(m.name())),
            ("units", json!("atomic units: bohr, rad, hartree, electron masses, time in hbar/E_h; masses in Da")),
            ("atoms", json!(atoms.iter().map(|a| a.label).collect::<Vec<_>>())),
            ("coordinates", json!(m.coordinates().iter().map(|c| c.name).collect::<Vec<_>>())),
            ("masses", json!(atoms.iter().map(|a| a.mass_da).collect::<Vec<_>>())),
        ];
        let mut kinetic = KineticMatrices::<N>::default();
        m.kinetic(&state.q, &mut kinetic);
        let chart = EulerChart::of(&kinetic);
        match evaluate(&m, &state) {
            Ok(e) => {
                fields.extend([
                    ("euler_chart", json!(chart.name())),
                    ("positions", rows(&e.positions.transpose())),
                    ("H", json!(e.hamiltonian)),
                    ("U", json!(e.potential)),
                    ("a", rows(&e.kinetic.a)),
                    ("A", rows(&e.kinetic.coriolis)),
                    ("I", rows(&e.kinetic.inertia)),
                    ("G11", rows(&e.g.g11)),
                    ("G12", rows(&e.g.g12)),
                    ("G22", rows(&e.g.g22)),
                    ("J", json!(e.angular_momentum.as_slice())),
                    (
                        "rhs",
                        json!({
                            "q": e.rhs.q.as_slice(),
                            "p": e.rhs.p.as_slice(),
                            "euler": e.rhs.euler.as_slice(),
                            "pe": e.rhs.pe.as_slice(),
                        }),
                    ),
                ]);
                if chart != EulerChart::Regular {
                    fields.push(("note", json!(chart.note(m.name(), false))));
                }
            }
            Err(err @ (HamiltonianError::SingularMetric { .. } | HamiltonianError::IllConditionedMetric { .. })) => {
                // The chart of internal coordinates and Euler angles is singular here (a linear
                // geometry): H, G and Hamilton's equations do not exist in it. Print what does.
                let mut positions = SMatrix::<f64, 3, NA>::zeros();
                m.positions(&state.q, &mut positions);
                let u = m.potential(&state.q);
                fields.extend([
                    ("euler_chart", json!(EulerChart::Singular.name())),
                    (
                        "note",
                        json!(EulerChart::Singular.note(m.name(), state.p.iter().chain(&state.pe).any(|&x| x != 0.0))),
                    ),
                    ("reason", json!(err.to_string())),
                    ("positions", rows(&positions.transpose())),
                    ("U", json!(u)),
                    ("a", rows(&kinetic.a)),
                    ("A", rows(&kinetic.coriolis)),
                    ("I", rows(&kinetic.inertia)),
                ]);
                if let Ok(j) = body_angular_momentum(&state) {
                    fields.push(("J", json!(j.as_slice())));
                }
            }
            Err(e) => return Err(Error::context(format!("cannot evaluate {}", m.name()), e)),
        }
        if let Some(cartesian) = cartesian(&m, &state)? {
            fields.push(("cartesian", cartesian));
        }
        Ok(fields)
    }
}

/// What the chart of internal coordinates and Euler angles is like at a geometry, judged by the
/// kinetic metric's relative pivots as `rovib run` judges them (`runtime::charts`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum EulerChart {
    /// Every relative pivot above `charts::SWITCH_PIVOT`: `rovib run` integrates here.
    Regular,
    /// Invertible but some relative pivot below `charts::SWITCH_PIVOT`: `rovib run` would
    /// integrate this state in the Cartesian chart.
    IllConditioned,
    /// Not invertible (a linear geometry).
    Singular,
}

impl EulerChart {
    fn of<const N: usize>(k: &KineticMatrices<N>) -> Self {
        if MetricFactor::is_regular(k, SWITCH_PIVOT) {
            Self::Regular
        } else if MetricFactor::is_regular(k, 0.0) {
            Self::IllConditioned
        } else {
            Self::Singular
        }
    }

    fn name(self) -> &'static str {
        match self {
            Self::Regular => "regular",
            Self::IllConditioned => "ill-conditioned",
            Self::Singular => "singular",
        }
    }

    /// What this means and what to do, for `molecule`; `moving` if the state has momenta.
    fn note(self, molecule: &str, moving: bool) -> String {
        let what = match self {
            Self::Regular => return String::new(),
            Self::IllConditioned => format!(
                "the chart of internal coordinates and Euler angles is ill-conditioned at this geometry of {molecule} \
                 (a relative pivot of the kinetic metric below {SWITCH_PIVOT:e}, nearly linear): H, G and Hamilton's \
                 equations below are accurate only to about the inverse of that pivot times rounding"
            ),
            Self::Singular => format!(
                "the chart of internal coordinates and Euler angles is singular at this geometry of {molecule} (linear: \
                 the rotation about the molecular axis moves no atom, so the kinetic metric M = [[I, A], [A^T, a]] has \
                 no inverse and there is no H(q, p, euler, pe), G or Hamilton's equations in this chart); printed are \
                 what exists: the positions, U and the kinetic matrices a, A, I{}",
                if moving {
                    " (the momenta give lab velocities only if J has no component along the axis)"
                } else {
                    ""
                }
            ),
        };
        format!(
            "{what}; `cartesian` holds the state in lab-frame Cartesian coordinates where the molecule's coordinates \
             are declared by kind (energy, forces, Newton's equations). `rovib run` (method dop853) integrates such \
             states in that Cartesian chart and switches back once the molecule is bent (the guide's \
             docs/src/howto/linear-molecules.md); for the internal-chart quantities give a bent geometry in --state (e.g. the angle a few \
             degrees from 180)"
        )
    }
}

/// The state in lab-frame Cartesian coordinates (centre of mass at rest at the origin), with
/// the energy, the gradient of U and Newton's equations there, from the closed forms of a
/// definition whose coordinates are declared by kind; `None` for a definition with explicit
/// positions only. At a singular geometry the velocities come from the metric's pseudo-inverse
/// (`frames::lab_of_body_any`); momenta with a component it cannot carry (J along a linear
/// molecule's axis) are an error that says so.
fn cartesian<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    state: &PhaseState<N>,
) -> Result<Option<Value>, Error> {
    let Ok(system) = CartesianSystem::<M, N, NA>::new(m) else { return Ok(None) };
    let body = BodyState::from_phase(state).map_err(|e| Error::context("cannot evaluate the orientation", e))?;
    let lab = lab_of_body_any(m, &body, &CentreOfMass::AT_REST).map_err(|e| {
        Error::context(format!("cannot express this state of {} in lab-frame Cartesian coordinates", m.name()), e)
    })?;
    let mut y = vec![0.0; 6 * NA];
    CartesianSystem::<M, N, NA>::flat(&lab, &mut y);
    let mut system = system;
    let energy = system.energy(&y).map_err(|e| Error::context("cannot evaluate the Cartesian energy", e))?;
    let mut dy = vec![0.0; 6 * NA];
    system.rhs(0.0, &y, &mut dy).map_err(|e| Error::context("cannot evaluate Newton's equations", e))?;
    let masses = m.masses();
    let acceleration = SMatrix::<f64, 3, NA>::from_column_slice(&dy[3 * NA..]);
    let gradient = SMatrix::<f64, 3, NA>::from_fn(|a, i| -masses[i] * acceleration[(a, i)]);
    let u = m.cartesian_potential(&lab.positions).unwrap_or(f64::NAN);
    Ok(Some(json!({
        "frame": "lab, centre of mass at rest at the origin, rotated by the state's Euler angles",
        "positions": rows(&lab.positions.transpose()),
        "velocities": rows(&lab.velocities.transpose()),
        "H": energy,
        "U": u,
        "T": energy - u,
        "J_lab": system.angular_momentum(&y).as_slice(),
        "gradient_U": rows(&gradient.transpose()),
        "acceleration": rows(&acceleration.transpose()),
    })))
}

/// Evaluates `molecule` at the state in `state_path` (or its default state) and returns one
/// JSON object, a key per line.
pub fn eval(molecule: &str, state_path: Option<&Path>) -> Result<String, Error> {
    let file = match state_path {
        Some(p) if p.as_os_str() == "-" => "state on stdin".to_owned(),
        Some(p) => format!("state file {}", p.display()),
        None => "default state".to_owned(),
    };
    let state: Option<StateFile> = match state_path {
        None => None,
        Some(path) => {
            let text = if path.as_os_str() == "-" {
                read_capped(std::io::stdin(), "the state from stdin", MAX_INPUT_BYTES)?
            } else {
                read_text_capped(path, MAX_INPUT_BYTES)?
            };
            Some(serde_json::from_str(&text).map_err(|e| Error::context(format!("invalid {file}"), e))?)
        }
    };
    let fields = molecules::visit(molecule, Eval { state: state.as_ref(), file: &file })
        .ok_or_else(|| Error::unknown_molecule(molecule))??;
    // One key per line, each value compact: matrices read as rows.
    let lines: Vec<String> = fields.iter().map(|(k, v)| format!("  {}: {v}", Value::from(*k))).collect();
    Ok(format!("{{\n{}\n}}", lines.join(",\n")))
}
