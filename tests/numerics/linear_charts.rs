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

use crate::common;

use common::cartesian::CartesianSystem as Reference;
use common::internal_coordinates;
use rovib::ensemble::run_with_sampler;
use rovib::molecules::{H2o, Hcn};
use rovib::runtime::cartesian_system::CartesianSystem;
use rovib::runtime::charts::{self, ChartObserver, ChartStart, ChartState};
use rovib::runtime::frames::{CentreOfMass, LabState, to_lab_body};
use rovib::runtime::hamiltonian::fast::{BodyState, ReducedSystem, Reduction};
use rovib::runtime::integrate::{Dop853, Dop853Options};
use rovib::runtime::nalgebra::{SVector, UnitQuaternion, Vector3};
use rovib::runtime::sample::{SampleError, Sampler};
use rovib::runtime::{Kinematics, Molecule};
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

/// With `[potential.parameters]` overrides (`WithParameters`: a stiffer bend, a longer CN bond):
/// the Cartesian chart runs with the overridden U(x) (`cartesian_potential_with`), and the run
/// agrees with the reference, whose forces come from the overridden U(q) (`potential_gradient`
/// through `potential_gradient_with`) and q(x) of its own. A chart that kept the compiled
/// values would put the Cartesian stretches on another potential.
#[test]
fn hcn_with_overridden_parameters_bends_through_linear() {
    let values: Vec<f64> = Hcn
        .parameters()
        .iter()
        .map(|(name, v)| match *name {
            "fbend" => 1.5 * v,
            "recn" => 1.2,
            _ => *v,
        })
        .collect();
    let m = rovib::parameters::WithParameters { molecule: Hcn, values };
    let mut q = Hcn.reference_geometry().unwrap();
    q[2] = 170f64.to_radians();
    let r = run_molecule(
        m,
        q,
        SVector::<f64, 3>::new(0.5, -0.3, 6.0),
        Vector3::new(3.0, 4.0, 0.0),
        internal_coordinates::hcn,
        1,
        T_END,
    );
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
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-linear-scene");
    let _ = std::fs::remove_dir_all(&out);
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/hcn_linear.toml");
    rovib::simulation::run(&scene, Some(&out)).expect("the scene runs");
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

/// Ensemble member `i` of [`BendingStates`]: HCN from 170° towards linear with a bend momentum
/// and body angular momentum (zero for even `i`) that vary with `i`.
fn bending_state(i: u64) -> BodyState<3> {
    let mut q = Hcn.reference_geometry().unwrap();
    q[2] = (168.0 + 0.7 * i as f64).to_radians();
    let x = i as f64;
    // No component along the molecular axis (body z): with one the bend could not reach linear.
    let j = if i.is_multiple_of(2) { Vector3::zeros() } else { Vector3::new(3.0 - 0.4 * x, 2.0 + 0.3 * x, 0.0) };
    BodyState {
        q,
        p: SVector::<f64, 3>::new(0.4 - 0.1 * x, -0.2 + 0.05 * x, 5.5 + 0.25 * x),
        orientation: UnitQuaternion::from_euler_angles(0.3 + 0.2 * x, -0.2 + 0.1 * x, 0.7 - 0.3 * x),
        j,
    }
}

/// A sampler of [`bending_state`]s: every member passes through linear several times.
struct BendingStates;

impl Sampler<3> for BendingStates {
    fn draw(&self, index: u64) -> Result<BodyState<3>, SampleError> {
        Ok(bending_state(index))
    }
}

const ENSEMBLE_MEMBERS: u64 = 4;
const ENSEMBLE_END: f64 = 4000.0;

fn ensemble_scene(fallback: bool) -> String {
    format!(
        "molecule = \"hcn\"\n[ensemble]\ntrajectories = {ENSEMBLE_MEMBERS}\nseed = 1\nmethod = \"thermal\"\n\
         temperature = 300.0\nkeep_trajectories = 1\n[statistics]\nmeans = [\"rch\", \"rcn\", \"alpha\", \"H\", \"Lx\", \
         \"Ly\", \"Lz\"]\n[integrator]\nmethod = \"dop853\"\nrtol = {RTOL:e}\natol = {ATOL:e}\n[run]\nend = \
         {ENSEMBLE_END}\noutput_interval = {INTERVAL}\ncartesian_fallback = {fallback}\nchart = \"internal\"\n"
    )
}

/// `q(t)`, H(t) and the lab angular momentum of ensemble member `i` by the plain Newtonian
/// propagation (tests/common/cartesian.rs), at the ensemble's output times.
fn reference_member(i: u64) -> Vec<(SVector<f64, 3>, f64, Vector3<f64>)> {
    let body = bending_state(i);
    let lab0 = to_lab_body(&Hcn, &body, &CentreOfMass::default()).unwrap();
    let mut reference = Reference::new(&Hcn, Hcn.masses(), internal_coordinates::hcn);
    let mut y0 = vec![0.0; 18];
    lab0.write_to(&mut y0);
    let options = Dop853Options { rtol: RTOL, atol: ATOL, ..Dop853Options::default() };
    let mut ys = Vec::new();
    Dop853::new(18, options)
        .unwrap()
        .integrate(&mut reference, 0.0, &y0, ENSEMBLE_END, INTERVAL, &mut |_t: f64, y: &[f64]| {
            ys.push(y.to_vec());
            ControlFlow::Continue(())
        })
        .unwrap();
    ys.iter()
        .map(|y| {
            let lab = LabState::<3>::read_from(y);
            (reference.q(&lab.positions), reference.energy(y), reference.angular_momentum(y))
        })
        .collect()
}

/// An ensemble whose members bend through linear (`rovib::ensemble` with the chart switch):
/// every member completes, switching charts at each crossing (counted per trajectory in
/// summary.json and in each kept trajectory's charts.json), and the kept trajectories' q(t) and
/// the ensemble means of q, H and L_lab agree at every output time with the plain Newtonian
/// propagation of each member from the same lab state. With `run.cartesian_fallback = false`
/// (the previous behaviour) nothing switches and summary.json says so.
#[test]
fn ensemble_members_bend_through_linear_in_agreement_with_the_cartesian_propagation() {
    use common::ensemble::{column, csv, options};
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rovib-linear-ensemble");
    let _ = std::fs::remove_dir_all(&dir);
    let scene = rovib::scene::parse_scene("ensemble.toml", &ensemble_scene(true)).unwrap();
    let report = run_with_sampler(&Hcn, &scene, &BendingStates, "bending states", &options(dir.clone(), 2)).unwrap();
    assert_eq!(report.outcome.completed, ENSEMBLE_MEMBERS, "failures {:?}", report.outcome.first_failures);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    let charts = &summary["charts"];
    eprintln!("ensemble charts: {charts}");
    assert_eq!(charts["switching"], true);
    assert_eq!(charts["trajectories_switched"], ENSEMBLE_MEMBERS);
    let listed = charts["first_switching"].as_array().unwrap();
    assert_eq!(listed.len() as u64, ENSEMBLE_MEMBERS);
    let mut total = 0;
    for (i, member) in listed.iter().enumerate() {
        assert_eq!(member["index"], i as u64);
        let switches = member["switches"].as_u64().unwrap();
        // 4000 ħ/E_h is about two bend periods: at least three crossings, two switches each.
        assert!(switches >= 6, "member {i}: {switches} switches");
        let kept: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(format!("trajectories/{i}/charts.json"))).unwrap())
                .unwrap();
        assert_eq!(kept["switches"], switches, "member {i}: charts.json and summary.json");
        total += switches;
    }
    assert_eq!(charts["switches"], total);

    // Member by member: the kept trajectory's q (atomic units) and H against the reference.
    let references: Vec<_> = (0..ENSEMBLE_MEMBERS).map(reference_member).collect();
    let mut max_dq: f64 = 0.0;
    let mut max_dh: f64 = 0.0;
    for (i, reference) in references.iter().enumerate() {
        let (header, rows) = csv(&dir.join(format!("trajectories/{i}/trajectory.csv")));
        assert_eq!(rows.len(), reference.len(), "member {i}: output times");
        let columns = [column(&header, "q_rch"), column(&header, "q_rcn"), column(&header, "q_alpha")];
        let h = column(&header, "H");
        for (row, (q, energy, _)) in rows.iter().zip(reference) {
            for (k, &c) in columns.iter().enumerate() {
                max_dq = max_dq.max((row[c] - q[k]).abs());
            }
            max_dh = max_dh.max((row[h] - energy).abs());
        }
    }
    // The means (atomic units) against the mean of the references.
    let (header, rows) = csv(&dir.join("ensemble.csv"));
    let n = ENSEMBLE_MEMBERS as f64;
    let mut max_mean: [f64; 3] = [0.0; 3];
    for (t, row) in rows.iter().enumerate() {
        let q: SVector<f64, 3> = references.iter().map(|r| r[t].0).sum::<SVector<f64, 3>>() / n;
        let h: f64 = references.iter().map(|r| r[t].1).sum::<f64>() / n;
        let l: Vector3<f64> = references.iter().map(|r| r[t].2).sum::<Vector3<f64>>() / n;
        for (k, name) in ["rch", "rcn", "alpha"].iter().enumerate() {
            max_mean[0] = max_mean[0].max(
                (row[column(&header, &format!("{name}_mean_{}", if k < 2 { "bohr" } else { "rad" }))] - q[k]).abs(),
            );
        }
        max_mean[1] = max_mean[1].max((row[column(&header, "H_mean_hartree")] - h).abs());
        for (k, name) in ["Lx", "Ly", "Lz"].iter().enumerate() {
            max_mean[2] = max_mean[2].max((row[column(&header, &format!("{name}_mean_hbar"))] - l[k]).abs());
        }
    }
    eprintln!(
        "ensemble of {ENSEMBLE_MEMBERS}: {total} switches; kept q within {max_dq:.2e} and H within {max_dh:.2e} Eh of \
         the references; means of q within {:.2e}, of H within {:.2e} Eh, of L_lab within {:.2e} ħ",
        max_mean[0], max_mean[1], max_mean[2]
    );
    assert!(max_dq < 1e-9, "a kept trajectory is {max_dq:e} (bohr or rad) from its Cartesian reference");
    assert!(max_dh < 1e-10, "a kept trajectory's H is {max_dh:e} Eh from its Cartesian reference");
    assert!(max_mean[0] < 1e-9, "the means of q are {:e} from the references'", max_mean[0]);
    assert!(max_mean[1] < 1e-10, "the mean H is {:e} Eh from the references'", max_mean[1]);
    assert!(max_mean[2] < 1e-9, "the mean L_lab is {:e} ħ from the references'", max_mean[2]);
    std::fs::remove_dir_all(&dir).unwrap();

    // The previous behaviour: no switch (a member passes, or stops at the singular geometry,
    // depending on how close to linear its integrator's stages land).
    let scene = rovib::scene::parse_scene("ensemble.toml", &ensemble_scene(false)).unwrap();
    let report = run_with_sampler(&Hcn, &scene, &BendingStates, "bending states", &options(dir.clone(), 2)).unwrap();
    eprintln!("without the fallback: {} completed, failed {:?}", report.outcome.completed, report.outcome.failed);
    assert_eq!(report.outcome.charts, Default::default());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["charts"]["switching"], false);
    std::fs::remove_dir_all(&dir).unwrap();
}
