//! `rovib list`: the compiled-in molecules, their atoms and coordinates.

use std::fmt::Write as _;

use rovib::molecules;
use rovib::runtime::{Molecule, MoleculeVisitor};

struct Describe;

impl MoleculeVisitor for Describe {
    type Output = String;

    fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "{} ({}): {NA} atoms, {N} internal coordinates", m.name(), m.source());
        let atoms: Vec<String> =
            m.atoms().iter().map(|a| format!("{} ({}, {} Da)", a.label, a.element, a.mass_da)).collect();
        let _ = writeln!(s, "  atoms:       {}", atoms.join(", "));
        if N == 0 {
            let _ = writeln!(s, "  coordinates: none (rigid)");
        } else {
            let coords: Vec<String> =
                m.coordinates().iter().map(|c| format!("{} [{}]", c.name, c.unit.name())).collect();
            let _ = writeln!(s, "  coordinates: {}", coords.join(", "));
        }
        for note in molecules::notes(m.name()) {
            let _ = writeln!(s, "  note:        {}", note.strip_prefix("note: ").unwrap_or(note));
        }
        s
    }
}

/// The note on units `rovib list` prints once, after the molecules.
pub const UNIT_NOTE: &str = "Coordinates are listed in the unit their definition declares, which is also the unit of q \
                             values in a scene without [units]; at run time and in trajectory.csv they are in bohr or rad.";

/// The text `rovib list` prints.
pub fn list() -> String {
    let molecules: Vec<String> = molecules::NAMES.iter().filter_map(|name| molecules::visit(name, Describe)).collect();
    format!("{}\n{UNIT_NOTE}\n", molecules.join("\n"))
}
