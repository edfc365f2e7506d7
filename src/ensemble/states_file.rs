//! Initial states from a CSV file (`method = "file"`): one state per row, in atomic units
//! (a `.xyz`/`.extxyz` path is read as extended XYZ by [`super::states_xyz`]).
//!
//! Header: every internal coordinate as `q_NAME` (or plain `NAME`; bohr, rad), optionally
//! `p_NAME` (ħ/bohr, ħ; missing ones are 0), optionally the Euler angles `euler_phi,
//! euler_theta, euler_psi` (or `phi, theta, psi`; rad, z-x-z; default `0, π/2, 0`) and their
//! momenta `pe_phi, pe_theta, pe_psi` (or `p_phi, p_theta, p_psi`) or the body-frame `Jx, Jy,
//! Jz` (ħ; default 0), or both (as `trajectory.csv` has them): then J is the state, and the
//! Euler momenta must agree with it (at θ = 0 or π they determine only two components of J). The prefixed names are the ones `trajectory.csv` uses (they cannot
//! collide with a coordinate's name) and win when both are present. Other columns (`t`, `H`,
//! the unwrapped angles) are ignored, so a `trajectory.csv` written by `rovib run` is a valid
//! states file. Errors name the CSV file, line and column.

use std::ops::Range;
use std::path::Path;

use crate::runtime::Molecule;
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::hamiltonian::PhaseState;
use crate::runtime::hamiltonian::euler::euler_momenta_from_angular_momentum;
use crate::runtime::hamiltonian::fast::{BodyState, quaternion_of_euler};
use crate::runtime::nalgebra::{SVector, Vector3};
use crate::scene::Scene;

/// The largest states file read: 1 GiB (a million water states in extended XYZ are about
/// 0.3 GB), so that `/dev/zero` or a wrong path is an error rather than memory without bound.
pub const MAX_STATES_FILE_BYTES: u64 = 1 << 30;

/// Reads the states in `path`. `Err(Ok(e))` is an error located in the file, `Err(Err(m))` a
/// file that cannot be read at all.
pub fn read_states<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    path: &Path,
    _scene: &Scene,
) -> Result<Vec<BodyState<N>>, Result<FileError, String>> {
    let text = crate::runtime::diagnostic::read_text_capped(path, MAX_STATES_FILE_BYTES)
        .map_err(|e| Err(e.to_string().replacen("cannot read ", "cannot read the states file ", 1)))?;
    // A UTF-8 byte-order mark is read as three spaces: the same bytes, so every error keeps
    // its line and column.
    let text = match text.strip_prefix('\u{feff}') {
        Some(rest) => format!("   {rest}"),
        None => text,
    };
    let name = path.display().to_string();
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("xyz") || e.eq_ignore_ascii_case("extxyz")) {
        return super::states_xyz::read_xyz(m, &name, &text).map_err(Ok);
    }
    read_csv(m, &Source { path: &name, text: &text }).map_err(Ok)
}

/// The states of a CSV states file.
fn read_csv<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    src: &Source<'_>,
) -> Result<Vec<BodyState<N>>, FileError> {
    // Lines with their byte offsets, ending in LF or CRLF (the terminator is not part of a line).
    let mut lines = src.text.split_inclusive('\n').scan(0usize, |offset, line| {
        let start = *offset;
        *offset += line.len();
        Some((start, line.trim_end_matches(['\n', '\r'])))
    });
    let Some((_, header)) = lines.next() else {
        return Err(
            src.whole_file("the states file is empty", "write a header line of column names, then one state per line")
        );
    };
    let columns = Columns::of(m, src, header)?;
    let mut states = Vec::new();
    let mut row = Row { values: Vec::with_capacity(columns.count), spans: Vec::with_capacity(columns.count) };
    for (start, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        row.read(src, start, line, columns.count)?;
        states.push(columns.state(m, src, &row, start..start + line.len())?);
    }
    if states.is_empty() {
        return Err(src.whole_file("the states file has a header but no states", "add one line per initial state"));
    }
    Ok(states)
}

/// Where the header puts each part of a state.
struct Columns<const N: usize> {
    /// Columns in the header.
    count: usize,
    /// Each coordinate's.
    q: [usize; N],
    /// Each momentum's, if given.
    p: [Option<usize>; N],
    /// The Euler angles', if given.
    euler: Option<[usize; 3]>,
    /// The Euler momenta's, if given.
    pe: Option<[usize; 3]>,
    /// The body-frame J's, if given.
    j: Option<[usize; 3]>,
}

impl<const N: usize> Columns<N> {
    /// The columns named by `header`, which must name every coordinate.
    fn of<M: Molecule<N, NA>, const NA: usize>(m: &M, src: &Source<'_>, header: &str) -> Result<Self, FileError> {
        let columns: Vec<&str> = header.split(',').map(str::trim).collect();
        let find = |name: &str| columns.iter().position(|c| *c == name);
        let coords = m.coordinates();
        let mut q = [0usize; N];
        for k in 0..N {
            q[k] = find(&format!("q_{}", coords[k].name)).or_else(|| find(coords[k].name)).ok_or_else(|| {
                src.error(
                    0..header.len(),
                    format!("the states file has no column `q_{}` (or `{}`)", coords[k].name, coords[k].name),
                    format!(
                        "the header must name every coordinate of {} as q_NAME: {}",
                        m.name(),
                        coords.iter().map(|c| format!("q_{}", c.name)).collect::<Vec<_>>().join(", ")
                    ),
                )
            })?;
        }
        let p = std::array::from_fn(|k| find(&format!("p_{}", coords[k].name)));
        // All three columns of a vector or none.
        let triple = |names: [&str; 3]| -> Result<Option<[usize; 3]>, FileError> {
            match names.map(find) {
                [Some(a), Some(b), Some(c)] => Ok(Some([a, b, c])),
                [None, None, None] => Ok(None),
                _ => Err(src.error(
                    0..header.len(),
                    format!("the states file has only some of the columns {}", names.join(", ")),
                    format!("give all of {} or none", names.join(", ")),
                )),
            }
        };
        let euler = triple(["euler_phi", "euler_theta", "euler_psi"])?
            .map_or_else(|| triple(["phi", "theta", "psi"]), |c| Ok(Some(c)))?;
        let pe = triple(["pe_phi", "pe_theta", "pe_psi"])?
            .map_or_else(|| triple(["p_phi", "p_theta", "p_psi"]), |c| Ok(Some(c)))?;
        let j = triple(["Jx", "Jy", "Jz"])?;
        Ok(Columns { count: columns.len(), q, p, euler, pe, j })
    }

    /// The state of `row` (written at `line` in the file), whose coordinates must be in range.
    fn state<M: Molecule<N, NA>, const NA: usize>(
        &self,
        m: &M,
        src: &Source<'_>,
        row: &Row,
        line: Range<usize>,
    ) -> Result<BodyState<N>, FileError> {
        let values = &row.values;
        let coords = m.coordinates();
        let mut q = SVector::<f64, N>::zeros();
        let mut p = SVector::<f64, N>::zeros();
        for k in 0..N {
            q[k] = values[self.q[k]];
            let c = &coords[k];
            if !c.contains(q[k]) {
                return Err(src.error(
                    row.spans[self.q[k]].clone(),
                    format!(
                        "{} = {} is outside its valid range [{}, {}] (bohr or rad): no geometry of {} has it",
                        c.name,
                        q[k],
                        c.range.0,
                        c.range.1,
                        m.name()
                    ),
                    "give a value within the coordinate's range (a bond angle in [0, π], a length above 0)",
                ));
            }
            if let Some(c) = self.p[k] {
                p[k] = values[c];
            }
        }
        let pick = |c: [usize; 3]| Vector3::new(values[c[0]], values[c[1]], values[c[2]]);
        let euler = self.euler.map_or(Vector3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0), pick);
        match (self.pe, self.j) {
            // Both (a `trajectory.csv` of `rovib run`): J is the state (the Euler momenta do not
            // determine it at θ = 0 or π); the Euler momenta must be those of that J.
            (Some(c), Some(jc)) => {
                let (pe, j) = (pick(c), pick(jc));
                let expected = euler_momenta_from_angular_momentum(&euler, &j);
                let tolerance = 1e-9 * (1.0 + j.norm() + pe.norm());
                if (pe - expected).amax() > tolerance {
                    return Err(src.error(
                        line,
                        format!(
                            "the Euler momenta ({}, {}, {}) are not those of Jx, Jy, Jz at these Euler angles \
                             (which give ({}, {}, {})): the row contradicts itself",
                            pe[0], pe[1], pe[2], expected[0], expected[1], expected[2]
                        ),
                        "correct the row, or give only one of the two (Jx, Jy, Jz or pe_phi, pe_theta, pe_psi)",
                    ));
                }
                Ok(BodyState { q, p, orientation: quaternion_of_euler(&euler), j })
            }
            (Some(c), None) => BodyState::from_phase(&PhaseState { q, p, euler, pe: pick(c) }).map_err(|e| {
                src.error(
                    line,
                    format!(
                        "this state: {e}; at θ = 0 or π the Euler momenta determine only two of the three \
                         components of J, so the state is not known"
                    ),
                    "give Jx, Jy, Jz instead of the Euler momenta at gimbal lock (or start from the run's lab.xyz, \
                     whose velocities determine the state)",
                )
            }),
            (None, j) => {
                Ok(BodyState { q, p, orientation: quaternion_of_euler(&euler), j: j.map_or(Vector3::zeros(), pick) })
            }
        }
    }
}

/// One row's values and where each is written, reused from row to row.
struct Row {
    values: Vec<f64>,
    spans: Vec<Range<usize>>,
}

impl Row {
    /// Reads `line` (at byte `start` of the file): finite numbers, one per column of the header.
    fn read(&mut self, src: &Source<'_>, start: usize, line: &str, columns: usize) -> Result<(), FileError> {
        self.values.clear();
        self.spans.clear();
        let mut offset = start;
        for field in line.split(',') {
            self.spans.push(offset..offset + field.len());
            let v: f64 = field.trim().parse().ok().filter(|v: &f64| v.is_finite()).ok_or_else(|| {
                src.error(
                    offset..offset + field.len(),
                    format!("`{}` is not a finite number", field.trim()),
                    "write a number in atomic units",
                )
            })?;
            self.values.push(v);
            offset += field.len() + 1;
        }
        if self.values.len() != columns {
            return Err(src.error(
                start..start + line.len(),
                format!("this row has {} values but the header names {} columns", self.values.len(), columns),
                "write one value per column",
            ));
        }
        Ok(())
    }
}
