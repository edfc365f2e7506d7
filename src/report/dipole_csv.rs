//! `dipole.csv`: the lab-frame dipole moment at each output time.

use std::path::Path;

use super::{Frame, Needs, Open, Output, Reporter};
use crate::error::Error;
use crate::output_file::OutputFile;
use crate::runtime::nalgebra::Vector3;

/// `dipole.csv`: the lab-frame dipole moment μ_lab = S μ(q), one row per output time.
///
/// Columns: `t` (in the scene's time unit), `mu_x`, `mu_y`, `mu_z` (e·bohr, in the lab frame
/// of `lab.xyz`; the centre of mass's motion does not change it for a neutral molecule).
pub struct DipoleCsv {
    file: OutputFile,
    row: String,
}

/// The header of `dipole.csv`.
const DIPOLE_HEADER: &str = "t,mu_x,mu_y,mu_z";

impl DipoleCsv {
    /// Creates the file and writes the header.
    pub fn create(dir: &Path) -> Result<Self, Error> {
        let mut file = OutputFile::create(dir, "dipole.csv")?;
        file.line(DIPOLE_HEADER)?;
        Ok(DipoleCsv { file, row: String::new() })
    }

    /// Opens an existing `dipole.csv` holding `rows` rows to append to it (a resumed run).
    pub fn append(dir: &Path, rows: usize) -> Result<Self, Error> {
        let file = OutputFile::append(dir, "dipole.csv", DIPOLE_HEADER, rows + 1)?;
        Ok(DipoleCsv { file, row: String::new() })
    }

    /// Writes one row: time and μ_lab in e·bohr, with full round-trip precision.
    pub fn row(&mut self, t: f64, mu: &Vector3<f64>) -> Result<(), Error> {
        use std::fmt::Write as _;
        self.row.clear();
        let _ = write!(self.row, "{t:?},{:?},{:?},{:?}", mu[0], mu[1], mu[2]);
        let row = std::mem::take(&mut self.row);
        let result = self.file.line(&row);
        self.row = row;
        result
    }

    /// Flushes to disk.
    pub fn flush(&mut self) -> Result<(), Error> {
        self.file.flush()
    }
}

const NEEDS: Needs = Needs { lab: false, dipole: true, orientation: true };

/// `"dipole"` in `run.outputs`.
pub(super) const OUTPUT: Output =
    Output { name: "dipole", files: &["dipole.csv"], by_default: false, needs: NEEDS, open };

fn open(o: &Open<'_>) -> Result<Box<dyn Reporter>, Error> {
    Ok(Box::new(match o.records() {
        None => DipoleCsv::create(o.dir)?,
        Some(rows) => DipoleCsv::append(o.dir, rows)?,
    }))
}

impl Reporter for DipoleCsv {
    fn needs(&self) -> Needs {
        NEEDS
    }

    fn report(&mut self, f: &Frame<'_>) -> Result<(), Error> {
        let mu = f.dipole.ok_or("dipole.csv was given an output time without the dipole")?;
        self.row(f.t, &Vector3::from(mu))
    }

    fn flush(&mut self) -> Result<(), Error> {
        DipoleCsv::flush(self)
    }
}
