//! Isotope masses of the elements that molecule definitions name.
//!
//! Atomic masses in daltons from the AME2020 evaluation as tabulated by NIST ("Atomic Weights
//! and Isotopic Compositions", <https://physics.nist.gov/Comp>). The default isotope of an element
//! is its most abundant one.

/// An element: symbol, and its isotopes as (mass number, mass in Da), most abundant first.
pub struct Element {
    /// The chemical symbol.
    pub symbol: &'static str,
    /// (mass number, atomic mass in Da); the first entry is the default isotope.
    pub isotopes: &'static [(u32, f64)],
}

/// The elements rovib knows by name. Atoms of other elements give their mass explicitly.
pub const ELEMENTS: &[Element] = &[
    Element { symbol: "H", isotopes: &[(1, 1.007_825_032_23), (2, 2.014_101_778_12), (3, 3.016_049_281_3)] },
    Element { symbol: "D", isotopes: &[(2, 2.014_101_778_12)] },
    Element { symbol: "T", isotopes: &[(3, 3.016_049_281_3)] },
    Element { symbol: "He", isotopes: &[(4, 4.002_603_254_13), (3, 3.016_029_320_1)] },
    Element { symbol: "Li", isotopes: &[(7, 7.016_003_436_6), (6, 6.015_122_887_4)] },
    Element { symbol: "Be", isotopes: &[(9, 9.012_183_065)] },
    Element { symbol: "B", isotopes: &[(11, 11.009_305_36), (10, 10.012_936_95)] },
    Element { symbol: "C", isotopes: &[(12, 12.0), (13, 13.003_354_835_07)] },
    Element { symbol: "N", isotopes: &[(14, 14.003_074_004_43), (15, 15.000_108_898_88)] },
    Element { symbol: "O", isotopes: &[(16, 15.994_914_619_57), (17, 16.999_131_756_50), (18, 17.999_159_612_86)] },
    Element { symbol: "F", isotopes: &[(19, 18.998_403_162_73)] },
    Element { symbol: "Ne", isotopes: &[(20, 19.992_440_176_2), (22, 21.991_385_114)] },
    Element { symbol: "Na", isotopes: &[(23, 22.989_769_282_0)] },
    Element { symbol: "Mg", isotopes: &[(24, 23.985_041_697)] },
    Element { symbol: "Al", isotopes: &[(27, 26.981_538_53)] },
    Element { symbol: "Si", isotopes: &[(28, 27.976_926_534_65)] },
    Element { symbol: "P", isotopes: &[(31, 30.973_761_998_42)] },
    Element { symbol: "S", isotopes: &[(32, 31.972_071_174_4), (34, 33.967_867_004)] },
    Element { symbol: "Cl", isotopes: &[(35, 34.968_852_682), (37, 36.965_902_602)] },
    Element { symbol: "Ar", isotopes: &[(40, 39.962_383_123_7), (36, 35.967_545_105)] },
    Element { symbol: "Br", isotopes: &[(79, 78.918_337_6), (81, 80.916_289_7)] },
    Element { symbol: "Kr", isotopes: &[(84, 83.911_497_728_2)] },
    Element { symbol: "I", isotopes: &[(127, 126.904_471_9)] },
    Element { symbol: "Xe", isotopes: &[(132, 131.904_155_085_6)] },
];

/// Looks an element up by its symbol (case-sensitive: `Co` is cobalt, `CO` is not a symbol).
pub fn element(symbol: &str) -> Option<&'static Element> {
    ELEMENTS.iter().find(|e| e.symbol == symbol)
}

/// The element symbol that starts a label such as `H1` or `Ob`: the longest known symbol that is
/// a prefix of the label's leading letters.
pub fn element_of_label(label: &str) -> Option<&'static Element> {
    let letters: String = label.chars().take_while(|c| c.is_ascii_alphabetic()).collect();
    (1..=letters.len().min(2)).rev().find_map(|n| element(&letters[..n]))
}

impl Element {
    /// The mass in Da of isotope `mass_number`, or of the default isotope.
    pub fn mass(&self, mass_number: Option<u32>) -> Option<f64> {
        match mass_number {
            None => Some(self.isotopes[0].1),
            Some(a) => self.isotopes.iter().find(|(n, _)| *n == a).map(|(_, m)| *m),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_name_their_elements() {
        assert_eq!(element_of_label("H1").unwrap().symbol, "H");
        assert_eq!(element_of_label("He").unwrap().symbol, "He");
        assert_eq!(element_of_label("Hb").unwrap().symbol, "H");
        assert_eq!(element_of_label("Cl2").unwrap().symbol, "Cl");
        assert!(element_of_label("x1").is_none());
        // Deuterium is ²H, whichever way it is named.
        assert_eq!(element("D").unwrap().mass(None), element("H").unwrap().mass(Some(2)));
        assert_eq!(element("C").unwrap().mass(None), Some(12.0));
        assert_eq!(element("O").unwrap().mass(Some(19)), None);
    }
}
