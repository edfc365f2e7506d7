//! Initial states from an extended XYZ file (`method = "file"` with a `.xyz` or `.extxyz` path):
//! one state per frame, lab-frame positions and velocities fitted to rovib's state.
//!
//! Each frame is the atom count, a comment line whose `Properties=` key names the columns (as
//! ASE, OVITO and rovib's own `lab.xyz` write it, e.g.
//! `Properties=species:S:1:pos:R:3:vel:R:3`), and one line per atom. Atoms are matched to the
//! molecule's atoms **by order**, and each line's species must be the element of that atom.
//! Positions (`pos`) are in Å. Velocities are optional (missing: at rest): a `vel`, `velo` or
//! `velocities` column in Å/fs, or a `momenta` column in ASE's units (u·Å per ASE time unit,
//! 1 ASE time unit = 10.180 5 fs, with the masses of the molecule's atoms). A frame without a
//! `Properties=` key is read as plain XYZ (species and positions). Every frame is fitted with
//! [`crate::runtime::frames::from_lab`] (internal coordinates, orientation, momenta and J; the
//! centre-of-mass motion is removed). Errors name the file, the line and the frame.

use std::ops::Range;

use crate::runtime::Molecule;
use crate::runtime::diagnostic::{FileError, Source};
use crate::runtime::frames::{FitOptions, LabState, from_lab_body};
use crate::runtime::hamiltonian::fast::BodyState;
use crate::runtime::nalgebra::SMatrix;
use crate::runtime::units::{AU_TIME_IN_FS, BOHR_IN_ANGSTROM};

pub use crate::output::ASE_TIME_IN_FS;

/// Where the columns of one atom line are.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Layout {
    species: usize,
    pos: usize,
    /// Column of the first velocity component and the factor from its unit to Å/fs; `true` if
    /// the column holds momenta (to be divided by the atom's mass in u).
    velocity: Option<(usize, f64, bool)>,
    width: usize,
}

/// Parses an extxyz `Properties=name:type:count:...` value.
fn layout(properties: Option<&str>) -> Result<Layout, String> {
    let Some(p) = properties else {
        return Ok(Layout { species: 0, pos: 1, velocity: None, width: 4 });
    };
    let fields: Vec<&str> = p.split(':').collect();
    if !fields.len().is_multiple_of(3) {
        return Err(format!("`Properties={p}` is not a list of name:type:count triples"));
    }
    let (mut species, mut pos, mut velocity, mut column) = (None, None, None, 0usize);
    for t in fields.chunks(3) {
        let count: usize = t[2].parse().map_err(|_| format!("`{}` in `Properties=` is not a column count", t[2]))?;
        match (t[0], count) {
            ("species", 1) => species = Some(column),
            ("pos", 3) => pos = Some(column),
            ("vel" | "velo" | "velocities", 3) => velocity = Some((column, 1.0, false)),
            ("momenta", 3) => velocity = Some((column, 1.0 / ASE_TIME_IN_FS, true)),
            _ => {}
        }
        column += count;
    }
    Ok(Layout {
        species: species.ok_or("`Properties=` has no `species:S:1` column")?,
        pos: pos.ok_or("`Properties=` has no `pos:R:3` column")?,
        velocity,
        width: column,
    })
}

/// The value of `key=` in an extxyz comment line (quotes removed).
fn comment_value<'a>(comment: &'a str, key: &str) -> Option<&'a str> {
    let start = comment.find(&format!("{key}="))? + key.len() + 1;
    let rest = &comment[start..];
    match rest.strip_prefix('"') {
        Some(quoted) => quoted.split('"').next(),
        None => rest.split_whitespace().next(),
    }
}

/// Reads every frame of the extended XYZ text `text` (named `path` in errors).
pub fn read_xyz<M: Molecule<N, NA>, const N: usize, const NA: usize>(
    m: &M,
    path: &str,
    text: &str,
) -> Result<Vec<BodyState<N>>, FileError> {
    let src = Source { path, text };
    let mut lines = text
        .split_inclusive('\n')
        .scan(0usize, |offset, line| {
            let start = *offset;
            *offset += line.len();
            Some((start..start + line.trim_end().len(), line.trim_end()))
        })
        .peekable();
    let atoms = m.atoms();
    let masses_u: Vec<f64> = atoms.iter().map(|a| a.mass_da).collect();
    let mut states = Vec::new();
    let mut frame = 0usize;
    while let Some((span, line)) = lines.next() {
        if line.trim().is_empty() {
            continue;
        }
        frame += 1;
        let count: usize = line.trim().parse().map_err(|_| {
            src.error(
                span.clone(),
                format!("frame {frame}: `{}` is not an atom count", line.trim()),
                "start every frame with its number of atoms",
            )
        })?;
        if count != NA {
            return Err(src.error(
                span,
                format!("frame {frame} has {count} atoms, {} has {NA}", m.name()),
                format!("give the {NA} atoms of {} in the order of its definition", m.name()),
            ));
        }
        let (cspan, comment) = lines.next().ok_or_else(|| {
            src.error(span.clone(), format!("frame {frame} ends before its comment line"), "complete the frame")
        })?;
        let layout = layout(comment_value(comment, "Properties")).map_err(|e| {
            src.error(
                cspan.clone(),
                format!("frame {frame}: {e}"),
                "write the columns as ASE does, e.g. Properties=species:S:1:pos:R:3:vel:R:3",
            )
        })?;
        let mut lab = LabState::<NA> { positions: SMatrix::zeros(), velocities: SMatrix::zeros() };
        let mut last: Range<usize> = cspan;
        for (i, atom) in atoms.iter().enumerate() {
            let (aspan, aline) = lines.next().ok_or_else(|| {
                src.error(
                    last.clone(),
                    format!("frame {frame} ends after {i} of its {NA} atoms"),
                    "give one line per atom",
                )
            })?;
            last = aspan.clone();
            let fields: Vec<&str> = aline.split_whitespace().collect();
            if fields.len() < layout.width {
                return Err(src.error(
                    aspan,
                    format!(
                        "frame {frame}, atom {}: {} columns, `Properties=` names {}",
                        i + 1,
                        fields.len(),
                        layout.width
                    ),
                    "write every column the comment line declares",
                ));
            }
            if !fields[layout.species].eq_ignore_ascii_case(atom.element) {
                return Err(src.error(
                    aspan,
                    format!(
                        "frame {frame}, atom {}: species `{}` where {} has {} ({})",
                        i + 1,
                        fields[layout.species],
                        m.name(),
                        atom.element,
                        atom.label
                    ),
                    format!("list the atoms in the order of {}", m.source()),
                ));
            }
            let number = |c: usize| -> Result<f64, FileError> {
                fields[c].parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                    src.error(
                        aspan.clone(),
                        format!("frame {frame}, atom {}: `{}` is not a finite number", i + 1, fields[c]),
                        "write numbers",
                    )
                })
            };
            for d in 0..3 {
                lab.positions[(d, i)] = number(layout.pos + d)? / BOHR_IN_ANGSTROM;
                if let Some((c, factor, momenta)) = layout.velocity {
                    let mut v = number(c + d)? * factor; // Å/fs (or u·Å/fs for momenta)
                    if momenta {
                        v /= masses_u[i];
                    }
                    lab.velocities[(d, i)] = v / BOHR_IN_ANGSTROM * AU_TIME_IN_FS;
                }
            }
        }
        // The orientation as a quaternion: defined at every orientation, also where the Euler
        // angles are at gimbal lock (θ = 0, a frame in the molecule's own body frame).
        let (body, _, _) = from_lab_body(m, &lab, &FitOptions::default()).map_err(|e| {
            src.error(
                last.clone(),
                format!("frame {frame} cannot start a trajectory of {}: {e}", m.name()),
                "check the positions (Å), their order and units",
            )
        })?;
        if let Some((c, x)) = m.coordinates().iter().zip(body.q.iter()).find(|(c, x)| !c.contains(**x)) {
            return Err(src.error(
                last.clone(),
                format!(
                    "frame {frame}: the fitted {} = {x} is outside its valid range [{}, {}] (bohr or rad)",
                    c.name, c.range.0, c.range.1
                ),
                "check the positions (Å), their order and units",
            ));
        }
        if !body.j.iter().chain(body.p.iter()).all(|x| x.is_finite()) {
            return Err(src.error(
                last,
                format!("frame {frame}: the velocities give non-finite momenta"),
                "check the velocities",
            ));
        }
        states.push(body);
    }
    if states.is_empty() {
        return Err(src.whole_file("the XYZ file has no frames", "write at least one frame"));
    }
    Ok(states)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn properties_are_parsed_in_column_order() {
        let l = layout(Some("species:S:1:pos:R:3:masses:R:1:vel:R:3")).unwrap();
        assert_eq!(l, Layout { species: 0, pos: 1, velocity: Some((5, 1.0, false)), width: 8 });
        let l = layout(Some("species:S:1:pos:R:3:momenta:R:3")).unwrap();
        assert_eq!(l.velocity.map(|v| (v.0, v.2)), Some((4, true)));
        assert!(layout(Some("pos:R:3")).is_err());
        assert!(layout(Some("species:S")).is_err());
        assert_eq!(layout(None).unwrap().width, 4);
    }

    #[test]
    fn comment_values_with_and_without_quotes() {
        let c = "Properties=species:S:1:pos:R:3 Time=1.0 pbc=\"F F F\"";
        assert_eq!(comment_value(c, "Properties"), Some("species:S:1:pos:R:3"));
        assert_eq!(comment_value(c, "pbc"), Some("F F F"));
        assert_eq!(comment_value(c, "energy"), None);
    }

    #[test]
    fn ase_time_unit_follows_from_codata_2014() {
        // ASE: fs = 1e-15 s, s = 1e10 √(e/u); e and u of CODATA 2014.
        let second = 1e10 * (1.602_176_620_8e-19_f64 / 1.660_539_040e-27).sqrt();
        assert!((1.0 / (1e-15 * second) - ASE_TIME_IN_FS).abs() < 1e-9);
    }
}
