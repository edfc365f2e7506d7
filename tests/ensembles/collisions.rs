//! Collision ensembles (`method = "collision"`) against independent results:
//!
//! - the sampler's impact parameter, relative energy and rotational energy against their
//!   analytic distributions (Kolmogorov–Smirnov with fixed seeds, `√n·D < 1.63`, the 1 % point;
//!   means within 4 standard errors): `P(b) ∝ b` on `[0, b_max]` (`⟨b²⟩ = b_max²/2`), the
//!   flux-weighted Maxwell–Boltzmann `P(E) = E e^(−E/kT)/(kT)²` (`⟨E⟩ = 2kT`), the thermal
//!   rigid linear rotor `P(E_rot) = e^(−E_rot/kT)/kT` (`⟨E_rot⟩ = kT`), and `|L| = √(J(J+1))`;
//! - with the interaction switched off (`eps = 0`) every final state equals the initial one;
//! - on the isotropic model `molecules/n2ar_iso.toml` with the diatomic not rotating, the
//!   deflection angle equals the classical deflection function of U(R),
//!   `χ = π − 2b ∫_{r_t}^∞ dr / (r² √(1 − b²/r² − U/E))`, by a 1-D quadrature written here;
//! - energy and angular momentum are conserved from start to end;
//! - scene errors are located.

use std::path::PathBuf;

use rovib::ensemble::collision_output::run_collisions;
use rovib::molecules::Arn2;
use rovib::runtime::sample::BOLTZMANN;
use rovib::runtime::sample::collision::{
    Collision, CollisionSpec, FragmentRotation, FragmentVibration, RelativeEnergy, Stratum, fragment,
};
use rovib::scene::parse_scene;

use crate::common;

const EPS: f64 = 4.556335e-4;
const SIGMA: f64 = 6.4;

fn dir(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-collisions-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The Kolmogorov–Smirnov statistic `√n · sup |F_n − F|` of `xs` against the CDF `cdf`.
fn ks(mut xs: Vec<f64>, cdf: impl Fn(f64) -> f64) -> f64 {
    xs.sort_by(f64::total_cmp);
    let n = xs.len() as f64;
    let mut d: f64 = 0.0;
    for (i, &x) in xs.iter().enumerate() {
        let f = cdf(x);
        d = d.max((f - i as f64 / n).abs()).max(((i + 1) as f64 / n - f).abs());
    }
    d * n.sqrt()
}

fn mean_and_error(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let m = xs.iter().sum::<f64>() / n;
    let v = xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (v / n).sqrt())
}

fn spec(strata: Vec<Stratum>, energy: RelativeEnergy, rotation: FragmentRotation, n: u64) -> CollisionSpec {
    CollisionSpec {
        fragments: [vec![0, 1], vec![2]],
        strata,
        energy,
        rotation: [rotation, FragmentRotation::None],
        vibration: [FragmentVibration::None, FragmentVibration::None],
        r0: 30.0,
        trajectories: n,
    }
}

/// KS limit at the 1 % level.
const KS_LIMIT: f64 = 1.63;

#[test]
fn sampled_b_energy_and_rotation_follow_their_distributions() {
    let (t, b_max, n) = (300.0, 12.0, 4000u64);
    let kt = BOLTZMANN * t;
    let one = vec![Stratum { low: 0.0, high: b_max, weight: 1.0 }];
    let s = Collision::new(&Arn2, spec(one, RelativeEnergy::Thermal(t), FragmentRotation::Thermal(t), n), 11).unwrap();
    let masses = *s.masses();
    let (mut b, mut e, mut rot) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..n {
        let (lab, drawn) = s.draw_lab(i);
        b.push(drawn.b);
        e.push(drawn.energy);
        rot.push(fragment::internal(&lab, &masses, &[0, 1]).e_rot);
        // The drawn relative energy is the lab state's.
        let (a, c) = (fragment::internal(&lab, &masses, &[0, 1]), fragment::internal(&lab, &masses, &[2]));
        let mu = a.mass * c.mass / (a.mass + c.mass);
        let et = 0.5 * mu * (c.velocity - a.velocity).norm_squared();
        assert!((et - drawn.energy).abs() <= 1e-12 * drawn.energy, "E_trans {et} vs drawn {}", drawn.energy);
        assert!(((c.position - a.position).norm() - 30.0).abs() < 1e-9);
    }
    let kb = ks(b.clone(), |x| (x / b_max).powi(2));
    let ke = ks(e.clone(), |x| 1.0 - (1.0 + x / kt) * (-x / kt).exp());
    let kr = ks(rot.clone(), |x| 1.0 - (-x / kt).exp());
    assert!(kb < KS_LIMIT, "b: sqrt(n) D = {kb}");
    assert!(ke < KS_LIMIT, "E: sqrt(n) D = {ke}");
    assert!(kr < KS_LIMIT, "E_rot: sqrt(n) D = {kr}");
    // The same statistics fail against the wrong forms (the test can fail): b uniform instead
    // of b² uniform, the plain Maxwell–Boltzmann Γ(3/2, kT) energy instead of the flux-weighted
    // Γ(2, kT), a nonlinear rotor's Γ(3/2, kT) instead of the linear rotor's Γ(1, kT).
    assert!(ks(b.clone(), |x| x / b_max) > 3.0 * KS_LIMIT);
    let gamma32 = |x: f64| {
        let y = x / kt;
        rovib::runtime::special::erf(y.sqrt()) - 2.0 * (y / std::f64::consts::PI).sqrt() * (-y).exp()
    };
    assert!(ks(e.clone(), gamma32) > 3.0 * KS_LIMIT);
    assert!(ks(rot.clone(), gamma32) > 3.0 * KS_LIMIT);
    let b2: Vec<f64> = b.iter().map(|x| x * x).collect();
    for (name, xs, expected) in [("b²", &b2, b_max * b_max / 2.0), ("E", &e, 2.0 * kt), ("E_rot", &rot, kt)] {
        let (m, se) = mean_and_error(xs);
        assert!((m - expected).abs() < 4.0 * se, "<{name}> = {m} ± {se}, expected {expected}");
    }
}

#[test]
fn quantised_rotation_and_strata() {
    let strata = vec![Stratum { low: 0.0, high: 4.0, weight: 1.0 }, Stratum { low: 4.0, high: 10.0, weight: 3.0 }];
    let n = 400;
    let s =
        Collision::new(&Arn2, spec(strata, RelativeEnergy::Fixed(1e-3), FragmentRotation::Quantum(7), n), 5).unwrap();
    assert_eq!(s.stratum_counts(), vec![100, 300]);
    let masses = *s.masses();
    for i in 0..n {
        let (lab, drawn) = s.draw_lab(i);
        let (lo, hi) = if i < 100 { (0.0, 4.0) } else { (4.0, 10.0) };
        assert!(drawn.b >= lo && drawn.b <= hi, "trajectory {i}: b = {} outside [{lo}, {hi}]", drawn.b);
        let f = fragment::internal(&lab, &masses, &[0, 1]);
        assert!((f.l.norm() - 56f64.sqrt()).abs() < 1e-10, "|L| = {}", f.l.norm());
        assert!(f.t_vib.abs() < 1e-15, "a rigid rotor has no vibration: {}", f.t_vib);
    }
}

/// Writes a collision scene for n2ar_iso.
fn iso_scene(dir: &std::path::Path, extra: &str, collision: &str, run: &str) -> rovib::scene::Scene {
    let text = format!(
        "molecule = \"n2ar_iso\"\n{extra}\n[ensemble]\ntrajectories = 12\nseed = 3\nmethod = \"collision\"\n\
         [collision]\n{collision}\n[[collision.fragment]]\natoms = [\"N1\", \"N2\"]\n\
         [[collision.fragment]]\natoms = [\"Ar\"]\n[integrator]\nmethod = \"dop853\"\nrtol = 1e-11\natol = 1e-11\n\
         [run]\n{run}\n"
    );
    let path = dir.join("scene.toml");
    std::fs::write(&path, &text).unwrap();
    parse_scene(&path.display().to_string(), &text).unwrap()
}

#[test]
fn without_interaction_the_final_state_is_the_initial_one() {
    let d = dir("free");
    let scene = iso_scene(
        &d,
        "[potential.parameters]\neps = 0.0",
        "b_max = 8.0\nenergy = 1e-3\nr0 = 30.0\nr_stop = 31.0",
        "end = 400000.0\noutput_interval = 2000.0",
    );
    let (report, collisions) = run_collisions(&scene, &common::ensemble::options(d.join("out"), 2)).unwrap();
    assert_eq!(report.outcome.completed, 12, "{:?}", collisions.failures);
    for r in &collisions.records {
        assert!(r.delta_e().abs() < 1e-9 * 1e-3, "trajectory {}: dE = {}", r.index, r.delta_e());
        assert!(r.deflection < 1e-6, "trajectory {}: deflection {}", r.index, r.deflection);
        assert_eq!(r.outcome.name(), "inelastic");
    }
}

/// `U(R)` of n2ar_iso.
fn lj(r: f64) -> f64 {
    4.0 * EPS * ((SIGMA / r).powi(12) - (SIGMA / r).powi(6))
}

/// The classical deflection function χ(b, E) of U(R): the turning point r_t (largest root of
/// `1 − b²/r² − U/E`) by bisection, then with `u = r_t/r = 1 − s²` the integrand is finite at
/// the turning point, `χ = π − (2b/r_t) ∫₀¹ 2s ds / √g(1 − s²)`, by composite Simpson.
fn deflection_function(b: f64, e: f64) -> f64 {
    let g = |r: f64| 1.0 - b * b / (r * r) - lj(r) / e;
    // Scan inwards from far away to the first sign change.
    let mut hi = 1e3;
    let mut lo = hi;
    while g(lo) > 0.0 {
        hi = lo;
        lo *= 0.999;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if g(mid) > 0.0 { hi = mid } else { lo = mid }
    }
    let rt = hi;
    let f = |s: f64| {
        if s == 0.0 {
            // The limit 2 / √(−dg/du) at u = 1, by a small finite difference.
            let h = 1e-7;
            let gu = |u: f64| g(rt / u);
            return 2.0 / ((gu(1.0 - h) - gu(1.0)) / h).sqrt();
        }
        let u = 1.0 - s * s;
        2.0 * s / g(rt / u).sqrt()
    };
    let n = 20_000;
    let h = 1.0 / n as f64;
    let mut sum = f(0.0) + f(1.0);
    for k in 1..n {
        sum += f(k as f64 * h) * if k % 2 == 1 { 4.0 } else { 2.0 };
    }
    std::f64::consts::PI - 2.0 * b / rt * sum * h / 3.0
}

#[test]
fn elastic_deflection_equals_the_classical_deflection_function() {
    let d = dir("deflection");
    let e = 3.0 * EPS;
    let scene = iso_scene(
        &d,
        "",
        &format!("b_max = 10.0\nenergy = {e}\nr0 = 200.0\nr_stop = 200.0"),
        "end = 3000000.0\noutput_interval = 2000.0",
    );
    let (_, collisions) = run_collisions(&scene, &common::ensemble::options(d.join("out"), 2)).unwrap();
    assert!(collisions.records.len() >= 8, "too few completed: {:?}", collisions.failures);
    let mut resolved = 0;
    for r in &collisions.records {
        let chi = deflection_function(r.b, e);
        let expected = chi.cos().clamp(-1.0, 1.0).acos();
        // The check resolves a 1 % change of the energy (it can fail).
        let off = deflection_function(r.b, 1.01 * e).cos().clamp(-1.0, 1.0).acos();
        if (off - expected).abs() > 1e-4 {
            resolved += 1;
        }
        assert!(
            (r.deflection - expected).abs() < 1e-5,
            "trajectory {} (b = {}): deflection {} rad, χ(b, E) = {chi} (|χ| folded: {expected})",
            r.index,
            r.b,
            r.deflection
        );
        // Elastic: the relative energy and the diatomic's (zero) rotation are unchanged.
        assert!(r.delta_e().abs() < 1e-8 * e, "trajectory {}: dE = {}", r.index, r.delta_e());
        assert!(r.last.fragments[0].e_rot < 1e-12);
        // Conservation from start to end.
        assert!(r.energy_change.abs() < 1e-9 * e, "trajectory {}: dH = {}", r.index, r.energy_change);
        assert!(
            r.angular_momentum_change < 1e-7 * r.angular_momentum.max(1.0),
            "trajectory {}: |dL| = {}",
            r.index,
            r.angular_momentum_change
        );
    }
    assert!(2 * resolved >= collisions.records.len(), "the tolerance does not resolve a 1 % change of E");
}

#[test]
fn collision_scene_errors_are_located() {
    let d = dir("errors");
    let cases = [
        ("b_max = 40.0\nenergy = 1e-3\nr0 = 30.0\nr_stop = 31.0", "r0 must be above"),
        ("b_max = 4.0\nenergy = 1e-3\ntemperature = 300.0\nr0 = 30.0\nr_stop = 31.0", "both collision.energy"),
        ("b_max = 4.0\nr0 = 30.0\nr_stop = 31.0", "needs energy or temperature"),
        ("b_max = 4.0\nenergy = 1e-3\nr0 = 30.0\nr_stop = 31.0\nimpact = 3", "unknown field `impact`"),
        ("strata = [{ b = [1, 4], weight = 1 }]\nenergy = 1e-3\nr0 = 30.0\nr_stop = 31.0", "starting where"),
    ];
    for (collision, expected) in cases {
        let scene = iso_scene(&d, "", collision, "end = 1000.0\noutput_interval = 10.0");
        let e = run_collisions(&scene, &common::ensemble::options(d.join("out"), 1)).unwrap_err();
        let text = e.to_string();
        assert!(text.contains(expected), "{collision}: {text}");
        assert!(text.contains("scene.toml:"), "not located: {text}");
    }
    // An unknown atom label, a vibration on a rigid bond, [statistics], at their places.
    let text = "molecule = \"n2ar_iso\"\n[ensemble]\ntrajectories = 2\nmethod = \"collision\"\n[collision]\n\
                b_max = 4.0\nenergy = 1e-3\nr0 = 30.0\nr_stop = 31.0\n[[collision.fragment]]\natoms = [\"N1\", \"X\"]\n\
                [[collision.fragment]]\natoms = [\"Ar\"]\n[run]\nend = 10.0\n";
    let scene = parse_scene("s.toml", text).unwrap();
    let e = run_collisions(&scene, &common::ensemble::options(d.join("out"), 1)).unwrap_err().to_string();
    assert!(e.contains("no atom `X`") && e.contains("s.toml:11"), "{e}");
    let text = text.replace("\"N1\", \"X\"", "\"N1\", \"N2\"").replace("atoms = [\"Ar\"]", "atoms = [\"Ar\"]\nv = 0");
    let scene = parse_scene("s.toml", &text).unwrap();
    let e = run_collisions(&scene, &common::ensemble::options(d.join("out"), 1)).unwrap_err().to_string();
    assert!(e.contains("diatomic fragments only"), "{e}");
    let text = format!("{text}[statistics]\nmeans = [\"R\"]\n");
    let scene = parse_scene("s.toml", &text).unwrap();
    let e = run_collisions(&scene, &common::ensemble::options(d.join("out"), 1)).unwrap_err().to_string();
    assert!(e.contains("does not use [statistics]"), "{e}");
    // [pairs] classifies thermal pairs; a collision ensemble refuses it rather than ignore it.
    let text = format!("{text}[pairs]\nmonomers = [[\"N1\", \"N2\"], [\"Ar\"]]\ndistance = \"R\"\n")
        .replace("[statistics]\nmeans = [\"R\"]\n", "");
    let scene = parse_scene("s.toml", &text).unwrap();
    let e = run_collisions(&scene, &common::ensemble::options(d.join("out"), 1)).unwrap_err().to_string();
    assert!(e.contains("does not classify pair states") && e.contains("s.toml:"), "{e}");
}
