//! The Cartesian chart on SIMD lanes (`runtime::cartesian_lanes`) against the one-trajectory
//! Cartesian code (`runtime::cartesian_system`):
//!
//! * the generated lane form of `∂U/∂x` at 2, 4 and 8 lanes equals itself across widths bit for
//!   bit and the generated `f64` gradient to round-off, for every shipped molecule declared by
//!   kind (the lanes' `exp`, `sin_cos`, `acos`… are vector polynomials within 2 ulp of libm's);
//!   molecules with lane forms and U(x) have it, the others do not;
//! * the lane right-hand side at an exactly linear CO₂ (where the generated gradient is not
//!   finite) takes the one-trajectory code's symmetric average in that lane only;
//! * `Dop853Lanes` on the lane system against the scalar DOP853 on `CartesianSystem`, trajectory
//!   by trajectory, to round-off.

use crate::common;

use std::ops::ControlFlow;

use common::{Rng, for_each_molecule, random_q};
use rovib::molecules::{Co2, H2o};
use rovib::runtime::cartesian_lanes::{self, CartesianLanes};
use rovib::runtime::cartesian_system::CartesianSystem;
use rovib::runtime::frames::{CentreOfMass, to_lab_body};
use rovib::runtime::hamiltonian::BodyState;
use rovib::runtime::integrate::{
    Dop853, Dop853Lanes, Dop853Options, LaneFailure, LaneFeeder, LaneSystem, OdeSystem, Stats,
};
use rovib::runtime::lanes::{F64x2, F64x4, F64x8, Real};
use rovib::runtime::nalgebra::{Rotation3, SMatrix, SVector, UnitQuaternion, Vector3};
use rovib::runtime::{Molecule, MoleculeVisitor};

/// Lab positions of a random geometry near the reference, randomly rotated and shifted.
fn random_positions<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, rng: &mut Rng) -> SMatrix<f64, 3, NA> {
    let mut r = SMatrix::<f64, 3, NA>::zeros();
    m.positions(&random_q(m, rng), &mut r);
    let axis = Vector3::new(rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0));
    let s = Rotation3::new(axis.normalize() * rng.uniform(0.0, 3.1)).into_inner();
    let shift = Vector3::new(rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0), rng.uniform(-2.0, 2.0));
    let mut x = s * r;
    for i in 0..NA {
        x.set_column(i, &(x.column(i) + shift));
    }
    x
}

/// The lane gradient of `sets` (one per lane of `T`): per lane, U then ∂U/∂x atom by atom.
fn lane_gradient<M, T, const N: usize, const NA: usize>(m: &M, sets: &[SMatrix<f64, 3, NA>]) -> Vec<Vec<f64>>
where
    M: Molecule<N, NA>,
    T: Real,
{
    let mut x = [[T::splat(0.0); 3]; NA];
    for (lane, s) in sets.iter().enumerate() {
        for (i, row) in x.iter_mut().enumerate() {
            for (a, v) in row.iter_mut().enumerate() {
                v.set_lane(lane, s[(a, i)]);
            }
        }
    }
    let mut g = [[T::splat(0.0); 3]; NA];
    let u = m.cartesian_potential_gradient_lanes(&x, &mut g).expect("a lane form");
    (0..T::LANES)
        .map(|lane| std::iter::once(u.lane(lane)).chain(g.iter().flatten().map(|v| v.lane(lane))).collect())
        .collect()
}

#[derive(Copy, Clone)]
struct GradientLanes;
impl MoleculeVisitor for GradientLanes {
    type Output = ();
    fn visit<M, const N: usize, const NA: usize>(self, m: M)
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let has_u = m.cartesian_potential(&SMatrix::zeros()).is_some();
        let available = cartesian_lanes::available(&m);
        assert_eq!(
            available,
            has_u && m.has_lane_forms(),
            "{}: a lane form exactly with U(x) and lane forms",
            m.name()
        );
        assert_eq!(CartesianLanes::new(&m).is_ok(), available, "{}", m.name());
        if !available {
            eprintln!("{}: no lane form of ∂U/∂x (U(x) {has_u}, lane forms {})", m.name(), m.has_lane_forms());
            return;
        }
        let mut rng = Rng::new(11);
        let sets: Vec<SMatrix<f64, 3, NA>> = (0..8).map(|_| random_positions(&m, &mut rng)).collect();
        let x8 = lane_gradient::<M, F64x8, N, NA>(&m, &sets);
        let x4: Vec<Vec<f64>> = sets.chunks(4).flat_map(|c| lane_gradient::<M, F64x4, N, NA>(&m, c)).collect();
        let x2: Vec<Vec<f64>> = sets.chunks(2).flat_map(|c| lane_gradient::<M, F64x2, N, NA>(&m, c)).collect();
        let mut worst: f64 = 0.0;
        for (k, x) in sets.iter().enumerate() {
            for (i, v) in x8[k].iter().enumerate() {
                assert_eq!(v.to_bits(), x4[k][i].to_bits(), "{} set {k} entry {i}: 8 against 4 lanes", m.name());
                assert_eq!(v.to_bits(), x2[k][i].to_bits(), "{} set {k} entry {i}: 8 against 2 lanes", m.name());
            }
            let mut g = SMatrix::<f64, 3, NA>::zeros();
            let u = m.cartesian_potential_gradient(x, &mut g).expect("U(x)");
            let scalar: Vec<f64> = std::iter::once(u).chain(g.iter().copied()).collect();
            let scale = scalar.iter().fold(1f64, |s, v| s.max(v.abs()));
            for (i, (a, b)) in x8[k].iter().zip(&scalar).enumerate() {
                let d = (a - b).abs() / scale;
                assert!(d <= 1e-13, "{} set {k} entry {i}: lanes {a} against f64 {b}", m.name());
                worst = worst.max(d);
            }
        }
        eprintln!("{}: lane ∂U/∂x against f64, largest relative difference {worst:.1e}", m.name());
    }
}

/// The generated lane form of `∂U/∂x` equals the `f64` gradient to round-off (10⁻¹³ of the
/// largest |U|, |∂U/∂x| or 1) and itself bit for bit at 2, 4 and 8 lanes, for every shipped
/// molecule with U(x) and lane forms; the others have none.
#[test]
fn cartesian_gradient_lanes_equal_the_f64_gradient() {
    for_each_molecule(GradientLanes);
}

/// At an exactly linear CO₂ the generated gradient is not finite (acos at π); the lane
/// right-hand side replaces it in that lane by `CartesianSystem`'s symmetric average (the same
/// numbers bit for bit), while the other lane keeps its lane-form numbers.
#[test]
fn linear_lane_takes_the_symmetric_average() {
    let m = Co2;
    let mut rng = Rng::new(3);
    let linear = [-2.2, 0.0, 2.2];
    let mut y_linear = vec![0.0; 18];
    for (i, z) in linear.iter().enumerate() {
        y_linear[3 * i + 2] = *z;
        y_linear[9 + 3 * i] = 0.01 * (i as f64 - 1.0);
    }
    let bent = random_positions(&m, &mut rng);
    let mut y_bent = vec![0.0; 18];
    y_bent[..9].copy_from_slice(bent.as_slice());
    let y: Vec<F64x2> = (0..18).map(|k| F64x2::from_array([y_linear[k], y_bent[k]])).collect();
    let mut d = vec![F64x2::splat(0.0); 18];
    let mut lanes = CartesianLanes::new(&m).unwrap();
    assert_eq!(LaneSystem::<F64x2>::rhs(&mut lanes, F64x2::splat(0.0), &y, &mut d), 0b11);
    let mut scalar = CartesianSystem::new(&m).unwrap();
    for (lane, ys) in [y_linear, y_bent].iter().enumerate() {
        let mut ds = vec![0.0; 18];
        scalar.rhs(0.0, ys, &mut ds).unwrap();
        let scale = ds.iter().fold(1e-300f64, |s, v| s.max(v.abs()));
        for k in 0..18 {
            let a = d[k].lane(lane);
            assert!(a.is_finite(), "lane {lane} component {k}: {a}");
            if lane == 0 {
                assert_eq!(a.to_bits(), ds[k].to_bits(), "linear lane, component {k}: {a} against {}", ds[k]);
            } else {
                assert!((a - ds[k]).abs() <= 1e-13 * scale, "bent lane, component {k}: {a} against {}", ds[k]);
            }
        }
    }
}

/// Feeds the states in order and records each trajectory's outputs.
struct Feeder {
    states: Vec<Vec<f64>>,
    next: usize,
    lane_job: [usize; 8],
    outputs: Vec<Vec<(f64, Vec<f64>)>>,
    ends: Vec<Option<Result<Stats, LaneFailure>>>,
}

impl LaneFeeder for Feeder {
    fn next(&mut self, lane: usize, y0: &mut [f64]) -> bool {
        let Some(s) = self.states.get(self.next) else { return false };
        y0.copy_from_slice(s);
        self.lane_job[lane] = self.next;
        self.next += 1;
        true
    }
    fn observe(&mut self, lane: usize, t: f64, y: &[f64]) -> ControlFlow<()> {
        self.outputs[self.lane_job[lane]].push((t, y.to_vec()));
        ControlFlow::Continue(())
    }
    fn finish(&mut self, lane: usize, result: Result<Stats, LaneFailure>) {
        self.ends[self.lane_job[lane]] = Some(result);
    }
}

/// Seven water trajectories (random geometries, momenta and orientations, in the lab frame) on
/// four Cartesian lanes against the scalar DOP853 on `CartesianSystem` (libm), one at a time:
/// the same output times, the states to round-off (10⁻¹¹ of the largest |y| over 2000 a.u.).
#[test]
fn cartesian_lanes_equal_one_at_a_time() {
    let m = H2o;
    let mut rng = Rng::new(7);
    let states: Vec<Vec<f64>> = (0..7)
        .map(|_| {
            let axis = Vector3::from_fn(|_, _| rng.uniform(-1.0, 1.0));
            let body = BodyState {
                q: random_q(&m, &mut rng),
                p: SVector::from_fn(|_, _| rng.uniform(-5.0, 5.0)),
                orientation: UnitQuaternion::from_scaled_axis(axis * 3.0),
                j: Vector3::from_fn(|_, _| rng.uniform(-10.0, 10.0)),
            };
            let lab = to_lab_body(&m, &body, &CentreOfMass::default()).unwrap();
            let mut y = vec![0.0; 18];
            CartesianSystem::<H2o, 3, 3>::flat(&lab, &mut y);
            y
        })
        .collect();
    let options = Dop853Options { rtol: 1e-9, atol: 1e-9, ..Default::default() };
    let (t_end, interval) = (2000.0, 150.0);
    let mut feeder = Feeder {
        states: states.clone(),
        next: 0,
        lane_job: [0; 8],
        outputs: vec![Vec::new(); states.len()],
        ends: vec![None; states.len()],
    };
    let mut lanes = Dop853Lanes::<F64x4>::new(18, options).unwrap();
    lanes.integrate(&mut CartesianLanes::new(&m).unwrap(), 0.0, t_end, interval, &mut feeder).unwrap();
    let mut worst: f64 = 0.0;
    let mut system = CartesianSystem::new(&m).unwrap();
    for (j, y0) in states.iter().enumerate() {
        let mut outputs = Vec::new();
        let mut observer = |t: f64, y: &[f64]| {
            outputs.push((t, y.to_vec()));
            ControlFlow::Continue(())
        };
        Dop853::new(18, options).unwrap().integrate(&mut system, 0.0, y0, t_end, interval, &mut observer).unwrap();
        assert!(matches!(feeder.ends[j], Some(Ok(_))), "trajectory {j}: {:?}", feeder.ends[j]);
        assert_eq!(feeder.outputs[j].len(), outputs.len(), "trajectory {j}");
        let scale = outputs.iter().flat_map(|(_, y)| y).fold(0f64, |s, v| s.max(v.abs()));
        for ((tl, yl), (ts, ys)) in feeder.outputs[j].iter().zip(&outputs) {
            assert_eq!(tl, ts, "trajectory {j}");
            for (a, b) in yl.iter().zip(ys) {
                let d = (a - b).abs() / scale;
                assert!(d <= 1e-11, "trajectory {j} at t = {ts}: lanes {a} against one at a time {b}");
                worst = worst.max(d);
            }
        }
    }
    eprintln!("Cartesian lanes against one at a time: largest relative difference {worst:.1e}");
}
