//! Extended XYZ initial states: states → lab frame → XYZ text (Å, Å/fs, and ASE momenta) →
//! read back through the fit → the same q, p and J; and located errors for bad files.

use rovib::ensemble::states_xyz::{ASE_TIME_IN_FS, read_xyz};
use rovib::molecules::H2o;
use rovib::runtime::Kinematics;
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

/// A frame at the Euler chart's gimbal lock (θ = 0: positions in the body frame's own
/// orientation, as `lab.xyz` of a run started at θ = 0 holds) is read as the same state: the
/// orientation is fitted as a quaternion, J from the velocities.
#[test]
fn a_frame_at_gimbal_lock_is_read() {
    let mut s = states()[1];
    s.orientation = quaternion_of_euler(&Vector3::new(0.4, 0.0, 0.3));
    let read = read_xyz(&H2o, "lab.xyz", &xyz(&[s], false)).unwrap();
    assert_same(&s, &read[0]);
}

/// States files (CSV): a coordinate outside its valid range is refused at its own field; CRLF
/// line ends keep the line numbers; a UTF-8 byte-order mark is accepted.
#[test]
fn states_csv_ranges_line_ends_and_bom() {
    use rovib::ensemble::states_file::read_states;
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-states-csv");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let scene = rovib::scene::parse_scene(
        "t.toml",
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = 1\nmethod = \"file\"\nfile = \"s.csv\"\n[run]\nend = 1\noutput_interval = 1\n",
    )
    .unwrap();
    let read = |name: &str, text: &str| {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        read_states(&H2o, &path, &scene)
    };
    for (text, line, column, what) in [
        ("q_r1,q_r2,q_alpha\n1.8,1.8,1.82\n-1.81,1.8,1.82\n", 3, 1, "r1 = -1.81"),
        ("q_r1,q_r2,q_alpha\n1.8,1.8,1.82\n1.8,1.8,4.0\n", 3, 9, "alpha = 4"),
        ("q_r1,q_r2,q_alpha\r\n1.8,1.8,1.82\r\n1.8,1.8,1.82\r\n1.8,x,1.82\r\n", 4, 5, "not a finite number"),
    ] {
        let e = read("s.csv", text).unwrap_err().unwrap();
        assert_eq!((e.line, e.column), (line, column), "{e}");
        assert!(e.to_string().contains(what), "expected {what:?} in {e}");
    }
    let states = read("bom.csv", "\u{feff}q_r1,q_r2,q_alpha\r\n1.8,1.7,1.82\r\n").unwrap();
    assert_eq!(states.len(), 1);
    assert_eq!(states[0].q, SVector::<f64, 3>::new(1.8, 1.7, 1.82));
}

/// `rovib run`'s own `trajectory.csv` from a start at gimbal lock (θ = 0) is a states file:
/// its `Jx, Jy, Jz` columns give the state, which the Euler momenta alone cannot there
/// (J = (3, 8, 2) has p_e = (2, 3, 2): Jy is lost). A row whose Euler momenta contradict its J
/// is refused at its line.
#[test]
fn a_trajectory_csv_from_gimbal_lock_is_a_states_file() {
    use rovib::ensemble::states_file::read_states;
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-states-gimbal");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let run = dir.join("run.toml");
    std::fs::write(
        &run,
        "molecule = \"h2o\"\n[units]\nlength = \"bohr\"\nangle = \"rad\"\ntime = \"au\"\n[initial]\nq = { r1 = 1.8, r2 = 1.75, alpha = 1.82 }\neuler = [0.4, 0.0, 0.3]\n\
         j = [3.0, 8.0, 2.0]\n[integrator]\nmethod = \"dop853\"\n[run]\nend = 2.0\noutput_interval = 1.0\n\
         outputs = [\"trajectory\"]\n",
    )
    .unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rovib"))
        .args(["run", run.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let csv = dir.join("out/trajectory.csv");
    let scene = rovib::scene::parse_scene(
        "t.toml",
        "molecule = \"h2o\"\n[ensemble]\ntrajectories = 1\nmethod = \"file\"\nfile = \"s.csv\"\n[run]\nend = 1\noutput_interval = 1\n",
    )
    .unwrap();
    let states = read_states(&H2o, &csv, &scene).unwrap();
    assert_eq!(states.len(), 3);
    assert!((states[0].j - Vector3::new(3.0, 8.0, 2.0)).amax() < 1e-12, "J = {}", states[0].j);
    assert!((states[0].q - SVector::<f64, 3>::new(1.8, 1.75, 1.82)).amax() < 1e-15);
    // pe_theta of the first data row changed: the row contradicts itself.
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_owned).collect();
    let pe_theta = lines[0].split(',').position(|c| c == "pe_theta").unwrap();
    let mut fields: Vec<String> = lines[1].split(',').map(str::to_owned).collect();
    fields[pe_theta] = "7.5".to_owned();
    lines[1] = fields.join(",");
    let edited = dir.join("edited.csv");
    std::fs::write(&edited, lines.join("\n")).unwrap();
    let e = read_states(&H2o, &edited, &scene).unwrap_err().unwrap();
    assert_eq!(e.line, 2, "{e}");
    assert!(e.to_string().contains("contradicts itself"), "{e}");
}
