//! Extended XYZ initial states: states → lab frame → XYZ text (Å, Å/fs, and ASE momenta) →
//! read back through the fit → the same q, p and J; and located errors for bad files.

use rovib::ensemble::states_xyz::{ASE_TIME_IN_FS, read_xyz};
use rovib::molecules::H2o;
use rovib::runtime::Molecule;
use rovib::runtime::frames::{CentreOfMass, to_lab_body};
use rovib::runtime::hamiltonian::fast::{BodyState, quaternion_of_euler};
use rovib::runtime::nalgebra::{SVector, Vector3};
use rovib::runtime::units::{AU_TIME_IN_FS, BOHR_IN_ANGSTROM};

fn states() -> Vec<BodyState<3>> {
    let q0 = H2o.reference_geometry().unwrap();
    (0..4)
        .map(|i| {
            let s = i as f64;
            BodyState {
                q: q0 + SVector::<f64, 3>::new(0.05 * s, -0.03 * s, 0.04 * s),
                p: SVector::<f64, 3>::new(0.3 - 0.1 * s, 0.2 * s, -0.15),
                orientation: quaternion_of_euler(&Vector3::new(0.3 + s, 1.1 - 0.2 * s, -0.7 * s)),
                j: Vector3::new(1.5 * s, -2.0, 0.5),
            }
        })
        .collect()
}

/// Writes the states as extended XYZ; `momenta` selects ASE's momenta column instead of `vel`.
fn xyz(states: &[BodyState<3>], momenta: bool) -> String {
    let com = CentreOfMass { position: Vector3::new(1.0, -2.0, 0.5), velocity: Vector3::new(1e-4, 2e-4, -1e-4) };
    let atoms = H2o.atoms();
    let mut text = String::new();
    for s in states {
        let lab = to_lab_body(&H2o, s, &com).unwrap();
        let column = if momenta { "momenta" } else { "vel" };
        text += &format!("3\nProperties=species:S:1:pos:R:3:{column}:R:3 pbc=\"F F F\"\n");
        for i in 0..3 {
            let x = lab.positions.column(i) * BOHR_IN_ANGSTROM;
            let mut v = lab.velocities.column(i) * BOHR_IN_ANGSTROM / AU_TIME_IN_FS; // Å/fs
            if momenta {
                v *= atoms[i].mass_da * ASE_TIME_IN_FS;
            }
            text +=
                &format!("{} {:e} {:e} {:e} {:e} {:e} {:e}\n", atoms[i].element, x[0], x[1], x[2], v[0], v[1], v[2]);
        }
    }
    text
}

fn assert_same(a: &BodyState<3>, b: &BodyState<3>) {
    assert!((a.q - b.q).amax() < 1e-9, "q {:?} vs {:?}", a.q, b.q);
    assert!((a.p - b.p).amax() < 1e-9, "p {:?} vs {:?}", a.p, b.p);
    assert!((a.j - b.j).amax() < 1e-9, "J {:?} vs {:?}", a.j, b.j);
    let r = a.orientation.rotation_to(&b.orientation).angle();
    assert!(r < 1e-9, "orientation differs by {r} rad");
}

#[test]
fn states_round_trip_through_extended_xyz() {
    let given = states();
    for momenta in [false, true] {
        let read = read_xyz(&H2o, "frames.xyz", &xyz(&given, momenta)).unwrap();
        assert_eq!(read.len(), given.len());
        for (a, b) in given.iter().zip(&read) {
            assert_same(a, b);
        }
    }
}

#[test]
fn bad_files_are_located_errors() {
    let good = xyz(&states()[..1], false);
    let cases = [
        (good.replacen('3', "4", 1), "frame 1 has 4 atoms"),
        (good.replacen("\nO ", "\nN ", 1), "species `N`"),
        (good.replacen("pos:R:3", "position:R:3", 1), "no `pos:R:3` column"),
        (good.lines().take(3).collect::<Vec<_>>().join("\n"), "ends after 1 of its 3 atoms"),
        (String::new(), "no frames"),
        (good.replacen("e-", "x-", 1), "not a finite number"),
    ];
    for (text, expected) in cases {
        let e = read_xyz(&H2o, "bad.xyz", &text).unwrap_err();
        let shown = e.to_string();
        assert!(shown.contains(expected), "expected {expected:?} in {shown}");
        assert!(shown.contains("bad.xyz"), "{shown}");
    }
}
