//! Physical constants and unit conversions (CODATA 2018), shared by the generator and the runtime.
//!
//! rovib computes in atomic units throughout: lengths in bohr, masses in electron masses,
//! energies in hartree, time in ħ/E_h, angles in radians. Definitions and scenes may state
//! other units; they are converted once, at the boundary, with the factors below.
//!
//! It lives in `rovib-base`, which both the generator and the runtime depend on.

/// One bohr in ångström (CODATA 2018: a₀ = 0.529 177 210 903 Å).
pub const BOHR_IN_ANGSTROM: f64 = 0.529_177_210_903;

/// One dalton (unified atomic mass unit) in electron masses (CODATA 2018: m_u/m_e = 1822.888 486 209).
pub const DALTON_IN_ELECTRON_MASSES: f64 = 1_822.888_486_209;

/// One hartree in wavenumbers, cm⁻¹ (CODATA 2018: E_h/hc = 219 474.631 363 20 cm⁻¹).
pub const HARTREE_IN_WAVENUMBERS: f64 = 219_474.631_363_20;

/// One hartree in electronvolts (CODATA 2018: E_h = 27.211 386 245 988 eV).
pub const HARTREE_IN_EV: f64 = 27.211_386_245_988;

/// One hartree in kcal/mol (thermochemical calorie; E_h N_A = 627.509 474 kcal/mol).
pub const HARTREE_IN_KCAL_PER_MOL: f64 = 627.509_474_277_2;

/// One atomic unit of time (ħ/E_h) in femtoseconds (CODATA 2018: 2.418 884 326 5857 × 10⁻² fs).
pub const AU_TIME_IN_FS: f64 = 2.418_884_326_585_7e-2;

/// A unit of length accepted in definitions and scenes.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum LengthUnit {
    /// Atomic unit of length.
    Bohr,
    /// 10⁻¹⁰ m.
    Angstrom,
}

impl LengthUnit {
    /// Spellings accepted in files, in the order they are suggested in error messages.
    pub const SPELLINGS: &'static [(&'static str, LengthUnit)] = &[
        ("bohr", LengthUnit::Bohr),
        ("angstrom", LengthUnit::Angstrom),
        ("Å", LengthUnit::Angstrom),
        ("A", LengthUnit::Angstrom),
    ];

    /// Parses a unit as written in a file (see [`LengthUnit::SPELLINGS`]).
    pub fn parse(s: &str) -> Option<Self> {
        Self::SPELLINGS.iter().find(|(name, _)| *name == s).map(|&(_, u)| u)
    }

    /// How many bohr one of this unit is.
    pub fn in_bohr(self) -> f64 {
        match self {
            LengthUnit::Bohr => 1.0,
            LengthUnit::Angstrom => 1.0 / BOHR_IN_ANGSTROM,
        }
    }

    /// The canonical spelling.
    pub fn name(self) -> &'static str {
        match self {
            LengthUnit::Bohr => "bohr",
            LengthUnit::Angstrom => "angstrom",
        }
    }
}

/// A unit of angle accepted in definitions and scenes.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum AngleUnit {
    /// Radians (the unit of every trigonometric function).
    Rad,
    /// Degrees.
    Deg,
}

impl AngleUnit {
    /// Spellings accepted in files.
    pub const SPELLINGS: &'static [(&'static str, AngleUnit)] =
        &[("rad", AngleUnit::Rad), ("deg", AngleUnit::Deg), ("degree", AngleUnit::Deg)];

    /// Parses a unit as written in a file.
    pub fn parse(s: &str) -> Option<Self> {
        Self::SPELLINGS.iter().find(|(name, _)| *name == s).map(|&(_, u)| u)
    }

    /// How many radians one of this unit is.
    pub fn in_rad(self) -> f64 {
        match self {
            AngleUnit::Rad => 1.0,
            AngleUnit::Deg => core::f64::consts::PI / 180.0,
        }
    }

    /// The canonical spelling.
    pub fn name(self) -> &'static str {
        match self {
            AngleUnit::Rad => "rad",
            AngleUnit::Deg => "deg",
        }
    }
}

/// A unit of energy accepted in definitions and scenes.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum EnergyUnit {
    /// Atomic unit of energy, E_h.
    Hartree,
    /// Wavenumbers, hc × 1 cm⁻¹.
    Wavenumber,
    /// Electronvolts.
    ElectronVolt,
    /// Kilocalories per mole.
    KcalPerMol,
}

impl EnergyUnit {
    /// Spellings accepted in files.
    pub const SPELLINGS: &'static [(&'static str, EnergyUnit)] = &[
        ("hartree", EnergyUnit::Hartree),
        ("cm-1", EnergyUnit::Wavenumber),
        ("eV", EnergyUnit::ElectronVolt),
        ("kcal/mol", EnergyUnit::KcalPerMol),
    ];

    /// Parses a unit as written in a file.
    pub fn parse(s: &str) -> Option<Self> {
        Self::SPELLINGS.iter().find(|(name, _)| *name == s).map(|&(_, u)| u)
    }

    /// How many hartree one of this unit is.
    pub fn in_hartree(self) -> f64 {
        match self {
            EnergyUnit::Hartree => 1.0,
            EnergyUnit::Wavenumber => 1.0 / HARTREE_IN_WAVENUMBERS,
            EnergyUnit::ElectronVolt => 1.0 / HARTREE_IN_EV,
            EnergyUnit::KcalPerMol => 1.0 / HARTREE_IN_KCAL_PER_MOL,
        }
    }

    /// The canonical spelling.
    pub fn name(self) -> &'static str {
        match self {
            EnergyUnit::Hartree => "hartree",
            EnergyUnit::Wavenumber => "cm-1",
            EnergyUnit::ElectronVolt => "eV",
            EnergyUnit::KcalPerMol => "kcal/mol",
        }
    }
}

/// The unit of an internal coordinate: a length or an angle.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum CoordinateUnit {
    /// A bond length or other distance.
    Length(LengthUnit),
    /// A bond angle, torsion or other angle.
    Angle(AngleUnit),
}

impl CoordinateUnit {
    /// Parses any length or angle unit.
    pub fn parse(s: &str) -> Option<Self> {
        LengthUnit::parse(s).map(CoordinateUnit::Length).or_else(|| AngleUnit::parse(s).map(CoordinateUnit::Angle))
    }

    /// How many atomic units (bohr or rad) one of this unit is.
    pub fn in_atomic_units(self) -> f64 {
        match self {
            CoordinateUnit::Length(u) => u.in_bohr(),
            CoordinateUnit::Angle(u) => u.in_rad(),
        }
    }

    /// The canonical spelling.
    pub fn name(self) -> &'static str {
        match self {
            CoordinateUnit::Length(u) => u.name(),
            CoordinateUnit::Angle(u) => u.name(),
        }
    }

    /// The atomic unit of the same kind: bohr for lengths, rad for angles.
    pub fn atomic(self) -> Self {
        match self {
            CoordinateUnit::Length(_) => CoordinateUnit::Length(LengthUnit::Bohr),
            CoordinateUnit::Angle(_) => CoordinateUnit::Angle(AngleUnit::Rad),
        }
    }
}

/// One debye in atomic units of dipole moment, e·bohr (1 D = 10⁻²¹/c C·m; e a₀ from CODATA 2018).
pub const DEBYE_IN_E_BOHR: f64 = 0.393_430_269_519_899_5;

/// A unit of electric dipole moment accepted in a definition's `[dipole]` table.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum DipoleUnit {
    /// Debye, 10⁻²¹/c C·m.
    Debye,
    /// The atomic unit, e·bohr.
    EBohr,
    /// e·Å.
    EAngstrom,
}

impl DipoleUnit {
    /// Spellings accepted in files.
    pub const SPELLINGS: &'static [(&'static str, DipoleUnit)] =
        &[("debye", DipoleUnit::Debye), ("e*bohr", DipoleUnit::EBohr), ("e*angstrom", DipoleUnit::EAngstrom)];

    /// Parses a unit as written in a file.
    pub fn parse(s: &str) -> Option<Self> {
        Self::SPELLINGS.iter().find(|(name, _)| *name == s).map(|&(_, u)| u)
    }

    /// How many e·bohr one of this unit is.
    pub fn in_e_bohr(self) -> f64 {
        match self {
            DipoleUnit::Debye => DEBYE_IN_E_BOHR,
            DipoleUnit::EBohr => 1.0,
            DipoleUnit::EAngstrom => 1.0 / BOHR_IN_ANGSTROM,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_are_reciprocal_and_match_codata() {
        // 1 Å = 1.889 726 124 6 bohr (CODATA 2018).
        assert!((LengthUnit::Angstrom.in_bohr() - 1.889_726_124_6).abs() < 1e-9);
        // 1 cm⁻¹ = 4.556 335 252 912 × 10⁻⁶ E_h (CODATA 2018).
        assert!((EnergyUnit::Wavenumber.in_hartree() / 4.556_335_252_912e-6 - 1.0).abs() < 1e-11);
        assert!((AngleUnit::Deg.in_rad() * 180.0 - core::f64::consts::PI).abs() < 1e-15);
        for &(name, unit) in EnergyUnit::SPELLINGS {
            assert_eq!(EnergyUnit::parse(name), Some(unit));
        }
        assert_eq!(CoordinateUnit::parse("deg"), Some(CoordinateUnit::Angle(AngleUnit::Deg)));
        assert_eq!(CoordinateUnit::parse("parsec"), None);
        // 1 D = 3.335 640 95e-30 C m and e a0 = 8.478 353 6255e-30 C m: 0.393 430 e a0.
        assert!((DipoleUnit::Debye.in_e_bohr() - 3.335_640_952e-30 / 8.478_353_625_5e-30).abs() < 1e-9);
        assert_eq!(DipoleUnit::parse("e*angstrom"), Some(DipoleUnit::EAngstrom));
    }
}
