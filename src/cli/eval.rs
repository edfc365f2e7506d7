//! `rovib eval`: everything about one state, as one JSON object.

use crate::runtime::diagnostic::{MAX_INPUT_BYTES, read_capped, read_text_capped};
use std::path::Path;

use serde::Deserialize;
use serde_json::{Value, json};

use super::{CliError, unknown_molecule};
use crate::molecules;
use crate::runtime::hamiltonian::{PhaseState, evaluate};
use crate::runtime::nalgebra::{SMatrix, SVector, Vector3};
use crate::runtime::{Molecule, MoleculeVisitor};

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
) -> Result<SVector<f64, K>, CliError> {
    let Some(values) = values else { return Ok(default) };
    if values.len() != K {
        return Err(CliError::Message(format!(
            "{file}: `{field}` has {} entries, expected {K} ({meaning})",
            values.len()
        )));
    }
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(CliError::Message(format!("{file}: `{field}[{i}]` is not a finite number ({meaning})")));
    }
    Ok(SVector::from_column_slice(values))
}

struct Eval<'a> {
    state: Option<&'a StateFile>,
    /// The state file's name, for messages.
    file: &'a str,
}

impl MoleculeVisitor for Eval<'_> {
    type Output = Result<Vec<(&'static str, Value)>, CliError>;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> Self::Output {
        let reference = m.reference_geometry();
        let q_default = reference.unwrap_or_else(SVector::zeros);
        let names: Vec<&str> = m.coordinates().iter().map(|c| c.name).collect();
        let coordinates = format!("one per coordinate of {}: {}, in bohr or rad", m.name(), names.join(", "));
        let momenta = format!("one momentum per coordinate of {}: {}", m.name(), names.join(", "));
        let state = match self.state {
            Some(s) => {
                if s.q.is_none() && reference.is_none() {
                    return Err(CliError::Message(format!(
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
        let e = evaluate(&m, &state).map_err(|e| CliError::context(format!("cannot evaluate {}", m.name()), e))?;
        let atoms = m.atoms();
        let coordinates = m.coordinates();
        Ok(vec![
            ("molecule", json!(m.name())),
            ("units", json!("atomic units: bohr, rad, hartree, electron masses, time in hbar/E_h; masses in Da")),
            ("atoms", json!(atoms.iter().map(|a| a.label).collect::<Vec<_>>())),
            ("coordinates", json!(coordinates.iter().map(|c| c.name).collect::<Vec<_>>())),
            ("masses", json!(atoms.iter().map(|a| a.mass_da).collect::<Vec<_>>())),
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
        ])
    }
}

/// Evaluates `molecule` at the state in `state_path` (or its default state) and returns one
/// JSON object, a key per line.
pub fn eval(molecule: &str, state_path: Option<&Path>) -> Result<String, CliError> {
    let file = match state_path {
        Some(p) if p.as_os_str() == "-" => "state on stdin".to_owned(),
        Some(p) => format!("state file {}", p.display()),
        None => "default state".to_owned(),
    };
    let state: Option<StateFile> = match state_path {
        None => None,
        Some(path) => {
            let text = if path.as_os_str() == "-" {
                read_capped(std::io::stdin(), "the state from stdin", MAX_INPUT_BYTES).map_err(CliError::Message)?
            } else {
                read_text_capped(path, MAX_INPUT_BYTES).map_err(CliError::Message)?
            };
            Some(serde_json::from_str(&text).map_err(|e| CliError::context(format!("invalid {file}"), e))?)
        }
    };
    let fields = molecules::visit(molecule, Eval { state: state.as_ref(), file: &file })
        .ok_or_else(|| unknown_molecule(molecule))??;
    // One key per line, each value compact: matrices read as rows.
    let lines: Vec<String> = fields.iter().map(|(k, v)| format!("  {}: {v}", Value::from(*k))).collect();
    Ok(format!("{{\n{}\n}}", lines.join(",\n")))
}
