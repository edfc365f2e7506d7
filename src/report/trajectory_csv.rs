//! `trajectory.csv` (and its `trajectory.units.json`): the phase-space state at each output time.

use std::path::Path;

use serde_json::{Value, json};

use super::{Frame, Needs, Open, Output, Reporter};
use crate::error::Error;
use crate::output_file::{OutputFile, write_atomically};
use crate::restart::Restart;
use crate::runtime::Coordinate;

/// `trajectory.csv`: one row per output time, with its units in `trajectory.units.json`.
///
/// Columns (no name can collide with another, whatever the coordinates are called: every
/// coordinate column has a `q_` or `p_` prefix, and the fixed names have none of them):
/// `t` (the scene's time unit), `q_NAME` per coordinate (bohr or rad), `p_NAME` per coordinate
/// (ħ/bohr or ħ), `euler_phi`, `euler_theta`, `euler_psi` (rad, z-x-z), `pe_phi`, `pe_theta`,
/// `pe_psi` (the momenta conjugate to the Euler angles, ħ), `Jx`, `Jy`, `Jz` (the body-frame
/// angular momentum, ħ: the Euler momenta do not determine it at θ = 0 or π, so a row is a
/// complete state everywhere), `H` (hartree), and with
/// `run.euler_unwrapped = true` also `euler_phi_unwrapped`, `euler_psi_unwrapped` (rad,
/// continuous: each output adds the change since the last one, taken in (−π, π]).
pub struct TrajectoryCsv {
    file: OutputFile,
    row: String,
    /// The unwrapped φ and ψ and the last raw values, when asked for.
    unwrap: Option<Unwrapper>,
}

/// The file that states the units of `trajectory.csv`'s columns.
pub const TRAJECTORY_UNITS_FILE: &str = "trajectory.units.json";

/// The header of `trajectory.csv` and the unit of each column (see [`TrajectoryCsv`]).
/// `coordinates` are the molecule's coordinates, `time_unit` the scene's.
pub fn trajectory_columns(
    coordinates: &[Coordinate],
    time_unit: &str,
    euler_unwrapped: bool,
) -> Vec<(String, &'static str)> {
    let unit = |c: &Coordinate| c.unit.atomic().name();
    let time: &'static str = match time_unit {
        "au" => "au",
        "fs" => "fs",
        "ps" => "ps",
        _ => "unknown",
    };
    let mut columns = vec![("t".to_owned(), time)];
    columns.extend(coordinates.iter().map(|c| (format!("q_{}", c.name), unit(c))));
    columns.extend(coordinates.iter().map(|c| {
        let momentum = if unit(c) == "rad" { "hbar" } else { "hbar/bohr" };
        (format!("p_{}", c.name), momentum)
    }));
    for name in ["euler_phi", "euler_theta", "euler_psi"] {
        columns.push((name.to_owned(), "rad"));
    }
    for name in ["pe_phi", "pe_theta", "pe_psi", "Jx", "Jy", "Jz"] {
        columns.push((name.to_owned(), "hbar"));
    }
    columns.push(("H".to_owned(), "hartree"));
    if euler_unwrapped {
        columns.push(("euler_phi_unwrapped".to_owned(), "rad"));
        columns.push(("euler_psi_unwrapped".to_owned(), "rad"));
    }
    columns
}

/// Continuous φ and ψ from values wrapped into an interval of length 2π.
#[derive(Clone, Copy, Debug)]
struct Unwrapper {
    /// The last raw (φ, ψ) and the unwrapped ones; `None` before the first output.
    last: Option<([f64; 2], [f64; 2])>,
}

impl Unwrapper {
    /// The unwrapped (φ, ψ) for raw ones: the first output as given, then each adds the change
    /// since the last output reduced to (−π, π] (so the output interval must be short enough
    /// that φ and ψ turn by less than π between outputs).
    fn next(&mut self, raw: [f64; 2]) -> [f64; 2] {
        use std::f64::consts::{PI, TAU};
        let unwrapped = match self.last {
            None => raw,
            Some((last_raw, last)) => std::array::from_fn(|i| {
                let mut d = (raw[i] - last_raw[i]) % TAU;
                if d > PI {
                    d -= TAU;
                } else if d <= -PI {
                    d += TAU;
                }
                last[i] + d
            }),
        };
        self.last = Some((raw, unwrapped));
        unwrapped
    }
}

impl TrajectoryCsv {
    /// Creates `trajectory.csv` with its header and `trajectory.units.json` (written at once and
    /// whole: `{"file", "time_unit", "columns": {NAME: UNIT}, "order": [NAME, ...], "euler"}`).
    pub fn create(
        dir: &Path,
        coordinates: &[Coordinate],
        time_unit: &str,
        euler_unwrapped: bool,
    ) -> Result<Self, Error> {
        let columns = trajectory_columns(coordinates, time_unit, euler_unwrapped);
        let units = json!({
            "file": "trajectory.csv",
            "time_unit": time_unit,
            "columns": columns.iter().map(|(n, u)| (n.clone(), Value::from(*u))).collect::<serde_json::Map<_, _>>(),
            "order": columns.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(),
            "euler": "z-x-z, body to lab R = Rz(phi) Rx(theta) Rz(psi); pe are the momenta conjugate to phi, theta, psi",
        });
        write_atomically(dir, TRAJECTORY_UNITS_FILE, &units)?;
        let mut file = OutputFile::create(dir, "trajectory.csv")?;
        let header: Vec<&str> = columns.iter().map(|(n, _)| n.as_str()).collect();
        file.line(&header.join(","))?;
        Ok(TrajectoryCsv { file, row: String::new(), unwrap: euler_unwrapped.then_some(Unwrapper { last: None }) })
    }

    /// Opens an existing `trajectory.csv` to append rows (a resumed run), after checking that its
    /// header is the one this run would write. `last_euler` is the raw and unwrapped (φ, ψ) of
    /// the last row written, for the unwrapped columns.
    pub fn append(
        dir: &Path,
        coordinates: &[Coordinate],
        time_unit: &str,
        last_euler: Option<([f64; 2], [f64; 2])>,
        rows: usize,
    ) -> Result<Self, Error> {
        let euler_unwrapped = last_euler.is_some();
        let columns = trajectory_columns(coordinates, time_unit, euler_unwrapped);
        let header: Vec<&str> = columns.iter().map(|(n, _)| n.as_str()).collect();
        let header = header.join(",");
        let file = OutputFile::append(dir, "trajectory.csv", &header, rows + 1)?;
        Ok(TrajectoryCsv {
            file,
            row: String::new(),
            unwrap: euler_unwrapped.then_some(Unwrapper { last: last_euler }),
        })
    }

    /// Writes one row: time (scene unit), q, p, the Euler angles, their momenta, the body-frame J
    /// and H, then the unwrapped φ and ψ if asked for. Numbers are written with full round-trip
    /// precision.
    pub fn state_row(
        &mut self,
        t: f64,
        q: &[f64],
        p: &[f64],
        euler: [f64; 3],
        pe: [f64; 3],
        j: [f64; 3],
        energy: f64,
    ) -> Result<(), Error> {
        use std::fmt::Write as _;
        self.row.clear();
        let _ = write!(self.row, "{t:?}");
        for v in q.iter().chain(p).chain(&euler).chain(&pe).chain(&j).chain([&energy]) {
            let _ = write!(self.row, ",{v:?}");
        }
        if let Some(u) = &mut self.unwrap {
            let [phi, psi] = u.next([euler[0], euler[2]]);
            let _ = write!(self.row, ",{phi:?},{psi:?}");
        }
        let row = std::mem::take(&mut self.row);
        let result = self.file.line(&row);
        self.row = row;
        result
    }

    /// The raw and unwrapped (φ, ψ) of the last row, if the unwrapped columns are written.
    pub fn last_unwrapped(&self) -> Option<([f64; 2], [f64; 2])> {
        self.unwrap.and_then(|u| u.last)
    }

    /// Flushes to disk.
    pub fn flush(&mut self) -> Result<(), Error> {
        self.file.flush()
    }
}

const NEEDS: Needs = Needs { lab: false, dipole: false, orientation: true };

/// `"trajectory"` in `run.outputs`.
pub(super) const OUTPUT: Output = Output {
    name: "trajectory",
    files: &["trajectory.csv", TRAJECTORY_UNITS_FILE],
    by_default: true,
    needs: NEEDS,
    open,
};

fn open(o: &Open<'_>) -> Result<Box<dyn Reporter>, Error> {
    Ok(Box::new(match o.records() {
        None => TrajectoryCsv::create(o.dir, o.coordinates, o.time_unit, o.euler_unwrapped)?,
        Some(rows) => {
            let last_euler = o.resume.and_then(|r| r.euler_unwrapped);
            TrajectoryCsv::append(o.dir, o.coordinates, o.time_unit, last_euler, rows)?
        }
    }))
}

impl Reporter for TrajectoryCsv {
    fn needs(&self) -> Needs {
        NEEDS
    }

    fn report(&mut self, f: &Frame<'_>) -> Result<(), Error> {
        self.state_row(f.t, f.q, f.p, f.euler, f.pe, f.j, f.energy)
    }

    fn flush(&mut self) -> Result<(), Error> {
        TrajectoryCsv::flush(self)
    }

    /// The unwrapped φ and ψ continue from the last row's.
    fn continuation(&self, restart: &mut Restart) {
        restart.euler_unwrapped = self.last_unwrapped();
    }
}
