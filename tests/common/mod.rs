//! Helpers shared by the workspace's integration tests: random states near a molecule's
//! reference geometry, finite differences, and matrix comparisons.
#![allow(dead_code)]

pub mod cli;
pub mod ensemble;

use rovib::runtime::nalgebra::{SMatrix, SVector};
use rovib::runtime::units::CoordinateUnit;
use rovib::runtime::{Kinematics, Molecule, MoleculeVisitor};

/// The stack of the thread [`for_each_molecule`] runs each check on. The test harness's
/// threads have 2 MiB, which a molecule of 54 coordinates (hexane, added through
/// `ROVIB_MOLECULES_DIR`) overflows: the G-matrix path's `Workspace` holds `N + 1` kinetic
/// matrices, 1.4 MB for `N = 54`, and the test profile keeps temporary copies of such values
/// on the stack. The memory is reserved, not touched, unless a check needs it.
pub const CHECK_STACK_BYTES: usize = 256 << 20;

/// Runs `check` on every molecule of the build (there must be at least one), each on its own
/// thread with a [`CHECK_STACK_BYTES`] stack and to its end even if an earlier one fails, and
/// fails naming every molecule that failed with its message: a bare `unwrap` inside a check
/// still reports which molecule it was.
pub fn for_each_molecule(check: impl MoleculeVisitor<Output = ()> + Copy + Send) {
    assert!(!rovib::molecules::NAMES.is_empty());
    let mut failures = Vec::new();
    for name in rovib::molecules::NAMES {
        let outcome = std::thread::scope(|scope| {
            std::thread::Builder::new()
                .name(format!("check of {name}"))
                .stack_size(CHECK_STACK_BYTES)
                .spawn_scoped(scope, move || rovib::molecules::visit(name, check))
                .expect("a thread for the check")
                .join()
        });
        match outcome {
            Ok(Some(())) => {}
            Ok(None) => failures.push(format!("{name}: listed in molecules::NAMES but cannot be visited")),
            Err(payload) => failures.push(format!("{name}: {}", panic_message(payload.as_ref()))),
        }
    }
    assert!(
        failures.is_empty(),
        "failed for {} of {} molecules:\n{}",
        failures.len(),
        rovib::molecules::NAMES.len(),
        failures.join("\n")
    );
}

/// ∫ₐᵇ f by the composite Simpson rule on `n` (even) intervals.
pub fn simpson(f: impl Fn(f64) -> f64, a: f64, b: f64, n: usize) -> f64 {
    let h = (b - a) / n as f64;
    let mut s = f(a) + f(b);
    for i in 1..n {
        s += f(a + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    s * h / 3.0
}

/// The molecules whose kinetic metric is too ill-conditioned for the checks that compare two
/// paths to a fixed 1e-12: `hclar` (a MODEL HCl-like rotor + Ar, whose light rotor makes
/// M·M⁻¹ − 1 about 5e-12 in round-off alone). Its paths are checked instead against an
/// independent lab-frame propagation (tests/numerics/rigid_collinear.rs).
pub const ILL_CONDITIONED: [&str; 1] = ["hclar"];

/// [`for_each_molecule`] without the [`ILL_CONDITIONED`] ones, for checks whose tolerance is a
/// fixed multiple of the round-off of a well-conditioned metric.
pub fn for_each_well_conditioned_molecule(check: impl MoleculeVisitor<Output = ()> + Copy + Send) {
    #[derive(Copy, Clone)]
    struct Skip<C>(C);
    impl<C: MoleculeVisitor<Output = ()>> MoleculeVisitor for Skip<C> {
        type Output = ();
        fn visit<M, const N: usize, const NA: usize>(self, m: M)
        where
            M: Molecule<N, NA> + Copy + Send + Sync + 'static,
        {
            if !ILL_CONDITIONED.contains(&Kinematics::name(&m)) {
                self.0.visit(m)
            }
        }
    }
    for_each_molecule(Skip(check))
}

/// The definition file of the molecule called `name` as the build names it:
/// `molecules/NAME.toml`, or its path under `ROVIB_MOLECULES_DIR` when that is set.
pub fn source_of(name: &str) -> &'static str {
    #[derive(Copy, Clone)]
    struct Source;
    impl MoleculeVisitor for Source {
        type Output = &'static str;
        fn visit<M: Molecule<N, NA>, const N: usize, const NA: usize>(self, m: M) -> &'static str {
            m.source()
        }
    }
    rovib::molecules::visit(name, Source).unwrap_or_else(|| panic!("{name} is not a molecule of this build"))
}

/// The text of a panic's payload (a `&str` or `String` message; anything else is named so).
pub fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_owned()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "a panic without a message".to_owned()
    }
}

/// How far (rad) [`chart_centre`] moves a bond angle in from the end of its range when the
/// reference geometry is singular for the chart of internal coordinates and Euler angles (a
/// linear reference, α = π): 50°, so the random geometries of [`random_q`] (±0.15 rad) stay at
/// least 41° from linear, where the central differences of G (step 1e-3 α, truncation error
/// relative to |G11| about 24 h⁴/(π − α)⁵) stay below 4e-9 (near linear G11 grows like
/// 1/(π − α)²; at 20° from linear the shared 1e-8 tolerances fail from truncation alone).
pub const BEND_AWAY_FROM_LINEAR: f64 = 50.0 * std::f64::consts::PI / 180.0;

/// Whether the chart of internal coordinates and Euler angles is regular at `q`: every relative
/// pivot of the kinetic metric above `charts::RETURN_PIVOT` (where `rovib run` would use it).
pub fn euler_chart_regular<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, q: &SVector<f64, N>) -> bool {
    let mut k = rovib::runtime::KineticMatrices::<N>::default();
    m.kinetic(q, &mut k);
    rovib::runtime::hamiltonian::MetricFactor::is_regular(&k, rovib::runtime::charts::RETURN_PIVOT)
}

/// The geometry the generic tests draw their random geometries around: the reference geometry
/// where the Euler chart is regular there; at a singular reference (a linear molecule at its
/// linear equilibrium, where the chart is singular whatever the body frame) the reference with
/// every angle within [`BEND_AWAY_FROM_LINEAR`] of an end of its range moved to that distance
/// from the end (HCN and CO2: α = 130°). The generic tests check the chart's quantities, which
/// exist only where it is regular; the linear geometry itself is covered by the Cartesian chart
/// (tests/linear_charts.rs, tests/cartesian_potential.rs, `rovib freq`).
pub fn chart_centre<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M) -> SVector<f64, N> {
    let reference = m.reference_geometry().unwrap_or_else(|| panic!("{} has no reference geometry", m.name()));
    if euler_chart_regular(m, &reference) {
        return reference;
    }
    let coords = m.coordinates();
    let bent = SVector::from_fn(|k, _| match coords[k].unit {
        CoordinateUnit::Angle(_) => {
            let (low, high) = coords[k].range;
            let (low, high) = (low + BEND_AWAY_FROM_LINEAR, high - BEND_AWAY_FROM_LINEAR);
            if low <= high { reference[k].clamp(low, high) } else { reference[k] }
        }
        CoordinateUnit::Length(_) => reference[k],
    });
    assert!(
        euler_chart_regular(m, &bent),
        "{}: the Euler chart is singular at the reference geometry {:?} and still at {:?} (every bounded angle \
         moved {BEND_AWAY_FROM_LINEAR} rad in from the ends of its range): the generic tests need a regular geometry \
         near the reference (tests/common/mod.rs, chart_centre)",
        m.name(),
        reference.as_slice(),
        bent.as_slice()
    );
    bent
}
#[allow(unused_imports)]
pub use rovib_testkit::Rng;

/// A random geometry near the reference ([`chart_centre`]: the reference, or for a linear
/// reference the same geometry bent by 50°): lengths within ±8 %, angles within ±0.15 rad,
/// reflected back into the coordinate's range at its ends.
pub fn random_q<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, rng: &mut Rng) -> SVector<f64, N> {
    let reference = chart_centre(m);
    let coords = m.coordinates();
    SVector::from_fn(|k, _| match coords[k].unit {
        CoordinateUnit::Length(_) => reference[k] * rng.uniform(0.92, 1.08),
        CoordinateUnit::Angle(_) => {
            let (low, high) = coords[k].range;
            let x = reference[k] + rng.uniform(-0.15, 0.15);
            if x > high {
                2.0 * high - x
            } else if x < low {
                2.0 * low - x
            } else {
                x
            }
        }
    })
}

/// The step for central differences along coordinate k.
pub fn fd_step<const N: usize>(q: &SVector<f64, N>, k: usize) -> f64 {
    1e-3 * q[k].abs().max(1.0)
}

/// Fourth-order central difference of a vector-valued function along q_k.
pub fn central_difference<const N: usize, const R: usize, const C: usize>(
    q: &SVector<f64, N>,
    k: usize,
    mut f: impl FnMut(&SVector<f64, N>) -> SMatrix<f64, R, C>,
) -> SMatrix<f64, R, C> {
    let h = fd_step(q, k);
    let at = |t: f64, f: &mut dyn FnMut(&SVector<f64, N>) -> SMatrix<f64, R, C>| {
        let mut x = *q;
        x[k] += t;
        f(&x)
    };
    let (m2, m1, p1, p2) = (at(-2.0 * h, &mut f), at(-h, &mut f), at(h, &mut f), at(2.0 * h, &mut f));
    (m2 - 8.0 * m1 + 8.0 * p1 - p2) / (12.0 * h)
}

/// max |a − b| / max(max |b|, floor): a norm-wise relative difference.
pub fn rel_diff<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>, floor: f64) -> f64 {
    if R * C == 0 {
        return 0.0;
    }
    (a - b).amax() / b.amax().max(floor)
}

use rovib::runtime::hamiltonian::PhaseState;
use rovib::runtime::nalgebra::Vector3;

/// A random phase-space state near the reference geometry: momenta of a few ħ/bohr or ħ (a
/// kinetic energy of order 0.01 hartree for water), Euler angles away from gimbal lock.
pub fn random_state<M: Molecule<N, NA>, const N: usize, const NA: usize>(m: &M, rng: &mut Rng) -> PhaseState<N> {
    PhaseState {
        q: random_q(m, rng),
        p: SVector::from_fn(|_, _| rng.uniform(-5.0, 5.0)),
        euler: Vector3::new(rng.uniform(-3.0, 3.0), rng.uniform(0.3, 2.8), rng.uniform(-3.0, 3.0)),
        pe: Vector3::from_fn(|_, _| rng.uniform(-10.0, 10.0)),
    }
}

/// `∂f/∂y_i` at `y` by a 5-point central difference with one Richardson extrapolation
/// (error O(h⁶)), for a scalar function of a flat state.
pub fn richardson_derivative(y: &[f64], i: usize, h: f64, f: &mut dyn FnMut(&[f64]) -> f64) -> f64 {
    let mut d = |h: f64| {
        let mut x = y.to_vec();
        let mut at = |t: f64, x: &mut Vec<f64>| {
            x[i] = y[i] + t;
            f(x)
        };
        let (m2, m1, p1, p2) = (at(-2.0 * h, &mut x), at(-h, &mut x), at(h, &mut x), at(2.0 * h, &mut x));
        (m2 - 8.0 * m1 + 8.0 * p1 - p2) / (12.0 * h)
    };
    let (d1, d2) = (d(h), d(h / 2.0));
    d2 + (d2 - d1) / 15.0
}
pub mod cartesian;
pub mod internal_coordinates;
pub mod rigid_rotor;
