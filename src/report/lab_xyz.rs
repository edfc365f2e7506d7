//! `lab.xyz`: the lab-frame atoms at each output time, as extended XYZ.

use std::path::Path;

use super::{Frame, Needs, Open, Output, Reporter};
use crate::error::Error;
use crate::output_file::OutputFile;
use crate::runtime::units::{AU_TIME_IN_FS, BOHR_IN_ANGSTROM, HARTREE_IN_EV};

/// One ASE time unit in femtoseconds, the unit of the `momenta` column ASE reads: `1e15 / (1e10 ·
/// √(e/u))` with ASE's default (CODATA 2014) elementary charge and atomic mass unit.
pub const ASE_TIME_IN_FS: f64 = 10.180_505_671_156_348;

/// The `Properties=` value of every `lab.xyz` frame: per atom the element, the position (Å), the
/// mass (u), the momentum in ASE's units (u·Å per ASE time unit, so that ASE's `Atoms` get the
/// masses and velocities) and the velocity in Å/fs.
pub const LAB_XYZ_PROPERTIES: &str = "species:S:1:pos:R:3:masses:R:1:momenta:R:3:vel:R:3";

/// `lab.xyz`: extended XYZ, one frame per output time, readable by ASE (`ase.io.read(path,
/// index=":")` gives `Atoms` with positions, masses, velocities and the potential energy), VMD
/// and OVITO. Per atom: element, position (Å), mass (u), momentum (ASE units) and velocity
/// (Å/fs), all with full round-trip precision. The comment line carries `Time` and
/// `time_unit`, `energy` (the potential energy U in eV, the key ASE reads as
/// `get_potential_energy()`), `H_hartree`, `U_hartree` and `H_eV` (eV = 27.211386245988 per
/// hartree, CODATA 2018) and `pbc="F F F"`.
pub struct LabXyz {
    file: OutputFile,
    elements: Vec<&'static str>,
    /// Atom masses, u (Da).
    masses: Vec<f64>,
    time_unit: &'static str,
    line: String,
}

impl LabXyz {
    /// Creates the file for atoms of the given elements and masses (Da).
    pub fn create(
        dir: &Path,
        elements: Vec<&'static str>,
        masses: Vec<f64>,
        time_unit: &'static str,
    ) -> Result<Self, Error> {
        Ok(LabXyz { file: OutputFile::create(dir, "lab.xyz")?, elements, masses, time_unit, line: String::new() })
    }

    /// Opens an existing `lab.xyz` of `frames` frames to append frames (a resumed run).
    pub fn append(
        dir: &Path,
        elements: Vec<&'static str>,
        masses: Vec<f64>,
        time_unit: &'static str,
        frames: usize,
    ) -> Result<Self, Error> {
        let file = OutputFile::append(dir, "lab.xyz", &elements.len().to_string(), frames * (elements.len() + 2))?;
        Ok(LabXyz { file, elements, masses, time_unit, line: String::new() })
    }

    /// Writes one frame: `energy` = H and `potential` = U (hartree), `atoms` = per atom the
    /// lab-frame position (bohr) and velocity (bohr per ħ/E_h).
    pub fn frame(
        &mut self,
        t: f64,
        energy: f64,
        potential: f64,
        atoms: impl IntoIterator<Item = ([f64; 3], [f64; 3])>,
    ) -> Result<(), Error> {
        use std::fmt::Write as _;
        self.file.line(&self.elements.len().to_string())?;
        self.file.line(&format!(
            "Properties={LAB_XYZ_PROPERTIES} Time={t:?} time_unit={} energy={:?} H_hartree={energy:?} \
             U_hartree={potential:?} H_eV={:?} pbc=\"F F F\"",
            self.time_unit,
            potential * HARTREE_IN_EV,
            energy * HARTREE_IN_EV,
        ))?;
        // Å/fs per bohr/(ħ/E_h).
        let velocity_scale = BOHR_IN_ANGSTROM / AU_TIME_IN_FS;
        for ((element, mass), (x, v)) in self.elements.iter().zip(&self.masses).zip(atoms) {
            let x = x.map(|c| c * BOHR_IN_ANGSTROM);
            let v = v.map(|c| c * velocity_scale);
            let momentum = v.map(|c| mass * c * ASE_TIME_IN_FS);
            self.line.clear();
            let _ = write!(self.line, "{element}");
            for c in x.iter().chain([mass]).chain(&momentum).chain(&v) {
                let _ = write!(self.line, " {c:?}");
            }
            let line = std::mem::take(&mut self.line);
            let result = self.file.line(&line);
            self.line = line;
            result?;
        }
        Ok(())
    }

    /// Flushes to disk.
    pub fn flush(&mut self) -> Result<(), Error> {
        self.file.flush()
    }
}

const NEEDS: Needs = Needs { lab: true, dipole: false, orientation: true };

/// `"lab"` in `run.outputs`.
pub(super) const OUTPUT: Output = Output { name: "lab", files: &["lab.xyz"], by_default: true, needs: NEEDS, open };

fn open(o: &Open<'_>) -> Result<Box<dyn Reporter>, Error> {
    let elements: Vec<&'static str> = o.atoms.iter().map(|a| a.element).collect();
    let masses: Vec<f64> = o.atoms.iter().map(|a| a.mass_da).collect();
    Ok(Box::new(match o.records() {
        None => LabXyz::create(o.dir, elements, masses, o.time_unit)?,
        Some(frames) => LabXyz::append(o.dir, elements, masses, o.time_unit, frames)?,
    }))
}

impl Reporter for LabXyz {
    fn needs(&self) -> Needs {
        NEEDS
    }

    fn report(&mut self, f: &Frame<'_>) -> Result<(), Error> {
        let lab = f.lab.ok_or("lab.xyz was given an output time without the lab frame")?;
        let atoms = lab.positions.chunks_exact(3).zip(lab.velocities.chunks_exact(3));
        let atoms = atoms.map(|(x, v)| ([x[0], x[1], x[2]], [v[0], v[1], v[2]]));
        self.frame(f.t, f.energy, lab.potential, atoms)
    }

    fn flush(&mut self) -> Result<(), Error> {
        LabXyz::flush(self)
    }
}
