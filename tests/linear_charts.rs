//! The chart switch (`rovib::runtime::charts`) against a plain Cartesian propagation.
//!
//! HCN's equilibrium is linear, so every bend oscillation passes through a linear geometry,
//! twice a period (≈ 1900 ħ/E_h): there the chart of internal coordinates and orientation is
//! singular and the run continues in the Cartesian chart. The switched run, mapped to lab
//! positions at every output time, must agree with an independent Newtonian propagation of the
//! three atoms (tests/common/cartesian.rs: forces from the molecule's U(q) with q(x) and ∂q/∂x
//! by automatic differentiation, nothing of the generated Cartesian potential, the kinetic
//! matrices, the body frame or the switch) started from the same lab state; and H and the
//! lab-frame angular momentum must be conserved across every switch. With J = 0 (planar bend)
//! and with J ≠ 0 (the bend precesses about the lab angular momentum).

mod common;

use common::cartesian::CartesianSystem as Reference;
use common::internal_coordinates;
use rovib::molecules::{H2o, Hcn};
use rovib::runtime::Molecule;
use rovib::runtime::cartesian_system::CartesianSystem;
use rovib::runtime::charts::{self, ChartObserver, ChartStart, ChartState};
use rovib::runtime::frames::{CentreOfMass, LabState, to_lab_body};
use rovib::runtime::hamiltonian::fast::{BodyState, ReducedSystem, Reduction};
use rovib::runtime::integrate::{Dop853, Dop853Options};
use rovib::runtime::nalgebra::{SVector, UnitQuaternion, Vector3};
use std::ops::ControlFlow;

const T_END: f64 = 10000.0;
const INTERVAL: f64 = 5.0;
const RTOL: f64 = 1e-13;
const ATOL: f64 = 1e-14;

/// What the switched run produced at each output time: lab positions about the centre of mass,
/// H, the lab angular momentum and the chart.
struct Outputs<'m, M> {
    system: ReducedSystem<'m, M, 3, 3>,
    cartesian: CartesianSystem<'m, M, 3, 3>,
    rows: Vec<(f64, LabState<3>, f64, Vector3<f64>, bool)>,
}

impl<M: Molecule<3, 3>> ChartObserver for Outputs<'_, M> {
    fn observe(&mut self, t: f64, state: ChartState<'_>) -> ControlFlow<()> {
        let m = self.system.molecule();
        let masses = m.masses();
        let row = match state {
            ChartState::Internal(y) => {
                let (body, h) = self.system.expand_body_and_energy(y).expect("internal output");
                let lab = to_lab_body(m, &body, &CentreOfMass::default()).expect("lab state");
                let l = lab.angular_momentum(&masses);
                (t, lab, h, l, false)
            }
            ChartState::Cartesian(y) => {
                let lab = LabState::<3>::read_from(y);
                let h = self.cartesian.energy(y).expect("Cartesian energy");
                (t, lab, h, lab.angular_momentum(&masses), true)
            }
        };
        self.rows.push(row);
        ControlFlow::Continue(())
    }
}

struct Report {
    max_dx: f64,
    energy_drift: f64,
    l_drift: f64,
    switches: u64,
    cartesian_time: f64,
    cartesian_outputs: usize,
    min_bend_from_linear: f64,
}

/// Runs HCN from a bent start (170°) with bend momentum `p_alpha` and body angular momentum
/// `j`, both ways, and compares.
fn run(p_alpha: f64, j: Vector3<f64>, t_end: f64) -> Report {
    let mut q = Hcn.reference_geometry().unwrap();
    q[2] = 170f64.to_radians();
    run_molecule(Hcn, q, SVector::<f64, 3>::new(0.5, -0.3, p_alpha), j, internal_coordinates::hcn, 1, t_end)
}

/// Runs a triatomic `m` from `(q, p)` with body angular momentum `j` with the chart switch and
/// as a plain Cartesian propagation (`q_of_x` its coordinates), and compares.
fn run_molecule<M: Molecule<3, 3>>(
    m: M,
    q: SVector<f64, 3>,
    p: SVector<f64, 3>,
    j: Vector3<f64>,
    q_of_x: common::cartesian::QOfX,
    centre: usize,
    t_end: f64,
) -> Report {
    let body = BodyState { q, p, orientation: UnitQuaternion::from_euler_angles(0.3, -0.2, 0.7), j };
    let reduction = if j == Vector3::zeros() { Reduction::zero_angular_momentum(true) } else { Reduction::none() };
    let system = ReducedSystem::from_body(&m, reduction, &body);
    let options = Dop853Options { rtol: RTOL, atol: ATOL, ..Dop853Options::default() };
    let mut outputs = Outputs { system, cartesian: CartesianSystem::new(&m).unwrap(), rows: Vec::new() };
    let mut report = charts::ChartReport::default();
    charts::integrate(&system, options, 0.0, ChartStart::Fresh(&body), t_end, INTERVAL, &mut outputs, &mut report)
        .unwrap();

    // The reference: Newton's equations from the same lab state.
    let lab0 = to_lab_body(&m, &body, &CentreOfMass::default()).unwrap();
    let mut reference = Reference::new(&m, m.masses(), q_of_x);
    let mut y0 = vec![0.0; 18];
    lab0.write_to(&mut y0);
    let mut rows = Vec::new();
    Dop853::new(18, options)
        .unwrap()
        .integrate(&mut reference, 0.0, &y0, t_end, INTERVAL, &mut |t: f64, y: &[f64]| {
            rows.push((t, y.to_vec()));
            ControlFlow::Continue(())
        })
        .unwrap();
    assert_eq!(rows.len(), outputs.rows.len(), "the same output times");
    let (h0, l0) = (outputs.rows[0].2, outputs.rows[0].3);
    let mut r = Report {
        max_dx: 0.0,
        energy_drift: 0.0,
        l_drift: 0.0,
        switches: report.switches,
        cartesian_time: report.cartesian_time,
        cartesian_outputs: 0,
        min_bend_from_linear: f64::INFINITY,
    };
    for ((t, y), (t2, lab, h, l, cartesian)) in rows.iter().zip(&outputs.rows) {
        assert_eq!(t, t2);
        let reference = LabState::<3>::read_from(y);
        r.max_dx = r.max_dx.max((reference.positions - lab.positions).amax());
        r.energy_drift = r.energy_drift.max((h - h0).abs());
        r.l_drift = r.l_drift.max((l - l0).amax());
        r.cartesian_outputs += usize::from(*cartesian);
        let q = reference.positions;
        let [a, b] = match centre {
            0 => [1, 2],
            1 => [0, 2],
            _ => [0, 1],
        };
        let (u, v) = (q.column(a) - q.column(centre), q.column(b) - q.column(centre));
        r.min_bend_from_linear = r.min_bend_from_linear.min(std::f64::consts::PI - u.angle(&v));
    }
    eprintln!(
        "{} p = {p:?}, J = {j:?}: {} switches, {:.0} of {t_end} ħ/E_h in the Cartesian chart ({} of {} outputs), \
         closest output to linear {:.1e} rad; max |Δx| = {:.2e} bohr, |ΔH| ≤ {:.1e} Eh, |ΔL| ≤ {:.1e} ħ; {} steps, {} rhs",
        m.name(),
        r.switches,
        r.cartesian_time,
        r.cartesian_outputs,
        rows.len(),
        r.min_bend_from_linear,
        r.max_dx,
        r.energy_drift,
        r.l_drift,
        report.stats.accepted,
        report.stats.rhs_evals,
    );
    r
}

fn check(r: &Report, crossings: u64) {
    assert!(r.switches >= 2 * crossings, "{} switches, expected at least {}", r.switches, 2 * crossings);
    assert!(r.cartesian_time > 0.0 && r.cartesian_outputs > 0);
    assert!(r.max_dx < 1e-9, "the switched run is {:e} bohr from the Cartesian reference", r.max_dx);
    assert!(r.energy_drift < 1e-10, "H drifts by {:e} hartree across the switches", r.energy_drift);
    assert!(r.l_drift < 1e-9, "the lab angular momentum drifts by {:e} ħ", r.l_drift);
}

/// J = 0: the bend through linear in a plane, about ten crossings.
#[test]
fn hcn_bends_through_linear_with_zero_angular_momentum() {
    let r = run(6.0, Vector3::zeros(), T_END);
    check(&r, 8);
}

/// J ≠ 0 (5 ħ, not along the axis): the crossings of a rotating molecule.
#[test]
fn hcn_bends_through_linear_while_rotating() {
    let r = run(6.0, Vector3::new(3.0, 4.0, 0.0), T_END);
    check(&r, 8);
}

/// Water above its barrier to linearity (about 30 500 cm⁻¹ in this model, 0.139 hartree): from
/// 150° with p_alpha = 30 ħ the bend passes through 180° and back, each time through the
/// Cartesian chart. The model's bend potential, harmonic in α ∈ [0, π], has a kink at linear
/// (its force changes sign there), which both integrators resolve by shortening their steps.
#[test]
fn water_above_its_barrier_to_linearity_runs_through() {
    let mut q = H2o.reference_geometry().unwrap();
    q[2] = 150f64.to_radians();
    let r = run_molecule(
        H2o,
        q,
        SVector::<f64, 3>::new(0.0, 0.0, 30.0),
        Vector3::zeros(),
        internal_coordinates::h2o,
        0,
        3000.0,
    );
    assert!(r.switches >= 2, "{} switches", r.switches);
    assert!(r.cartesian_time > 0.0 && r.cartesian_outputs > 0);
    assert!(r.max_dx < 1e-9, "the switched run is {:e} bohr from the Cartesian reference", r.max_dx);
    assert!(r.energy_drift < 1e-9, "H drifts by {:e} hartree", r.energy_drift);
    assert!(r.l_drift < 1e-9, "the lab angular momentum drifts by {:e} ħ", r.l_drift);
}

/// `rovib run scenes/hcn_linear.toml`: an exactly linear start (lab form), bending through
/// linear while rotating; completes with the switches counted in summary.json and H and the
/// lab angular momentum conserved across them (every output, both charts).
#[test]
fn the_linear_hcn_scene_runs_through_its_crossings() {
    let out = std::env::temp_dir().join(format!("rovib-linear-scene-{}", std::process::id()));
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/hcn_linear.toml");
    rovib::cli::run::run(&scene, Some(&out), true).expect("the scene runs");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    eprintln!("hcn_linear.toml: charts {} conservation {}", summary["charts"], summary["conservation"]);
    assert_eq!(summary["status"], "completed");
    let switches = summary["charts"]["switches"].as_u64().unwrap();
    // 500 fs, a bend period of about 47 fs: about 21 passes through linear, two switches each.
    assert!(switches >= 30, "{switches} switches");
    let c = &summary["conservation"];
    assert!(c["max_relative_energy_error"].as_f64().unwrap() < 1e-8, "{c}");
    assert!(c["max_lab_angular_momentum_change_hbar"].as_f64().unwrap() < 1e-8, "{c}");
    std::fs::remove_dir_all(&out).unwrap();
}
