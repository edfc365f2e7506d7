//! Pair states (bound, metastable, free), restricted sampling and the dimer constant against
//! independent quadratures of the classical Boltzmann distribution of the model atom–atom pair
//! `molecules/n2ar_pair.toml` (Lennard-Jones U(d) between N2 and Ar, N2 bonded to a spectator
//! N1 that Ar does not feel; the pair's monomers are the atoms N2 and Ar).
//!
//! With V(d) = U_LJ(d) − U_LJ(far), far = 20 bohr (the region's upper limit), the reduced mass
//! m of N2 and Ar and w(d) = d² e^(−U_LJ(d)/kT) on [5.5, 20] bohr, the relative velocity is
//! Maxwellian at kT/m whatever N1 does, so with K = ½ m v² (a Γ(3/2, kT) variable):
//!
//! - bound: f_b = ∫ w P(K < −V(d)) dd / ∫ w dd, P(K < E) = (4/√π) ∫_0^√(E/kT) y² e^(−y²) dy;
//! - ⟨H_rel⟩ of the bound states: ∫ w (4/√π) ∫ y² e^(−y²) (kT y² + V) dy dd / ∫ w P dd;
//! - metastable: the transverse speed s (density (m/kT) s e^(−m s²/2kT)) gives L = m d s and the
//!   barrier B = max over r in [d, far] of V(r) + L²/(2 m r²); with E_t = ½ m s² + V(d) the state
//!   is metastable when ½ m v_r² lies in [max(0, −E_t), B − E_t), a Gaussian probability in v_r;
//! - K_c = 4π ∫ d² e^(−U_LJ/kT) P(K < −V(d)) dd, Z_A Z_B = 4π ∫ r² e^(−U_bond/kT) dr (N1–N2).
//!
//! Every integral is composite Simpson written here; the barrier is a dense scan refined by a
//! golden-section search. Statistical checks use fixed seeds and 4 standard errors.

use crate::common;
use common::ensemble::{column, csv};
use std::f64::consts::PI;
use std::path::PathBuf;

use rovib::ensemble::pair_states::{PairStates, census};
use rovib::ensemble::run_ensemble;
use rovib::molecules::N2arPair;
use rovib::runtime::sample::{BOLTZMANN, Region, Thermal};
use rovib::scene::parse_scene;

const T: f64 = 250.0;
const EPS: f64 = 4.556335e-4;
const SIGMA: f64 = 6.4;
const KB: f64 = 0.066;
const R0: f64 = 2.07;
const D: [f64; 2] = [5.5, 20.0];
const R: [f64; 2] = [1.47, 2.67];
const ELECTRON_MASSES_PER_DALTON: f64 = 1_822.888_486_209;

fn lj(d: f64) -> f64 {
    4.0 * EPS * ((SIGMA / d).powi(12) - (SIGMA / d).powi(6))
}

fn v(d: f64) -> f64 {
    lj(d) - lj(D[1])
}

fn reduced_mass() -> f64 {
    let (m_n, m_ar) = (14.003_074_004_43 * ELECTRON_MASSES_PER_DALTON, 39.962_383_123_7 * ELECTRON_MASSES_PER_DALTON);
    m_n * m_ar / (m_n + m_ar)
}

/// The standard normal probability of [a, b].
fn normal(a: f64, b: f64) -> f64 {
    if b <= a {
        return 0.0;
    }
    common::simpson(|x| (-0.5 * x * x).exp() / (2.0 * PI).sqrt(), a, b, 200)
}

struct Quadrature {
    bound: f64,
    metastable: f64,
    bound_energy: f64,
    dimer: f64,
    monomer: f64,
}

fn quadrature() -> Quadrature {
    let kt = BOLTZMANN * T;
    let m = reduced_mass();
    let w = |d: f64| d * d * (-lj(d) / kt).exp();
    let norm = common::simpson(w, D[0], D[1], 4000);
    let c = 4.0 / PI.sqrt();
    let p_bound = |d: f64| {
        let e = -v(d);
        if e <= 0.0 { 0.0 } else { c * common::simpson(|y| y * y * (-y * y).exp(), 0.0, (e / kt).sqrt(), 400) }
    };
    let h_bound = |d: f64| {
        let e = -v(d);
        if e <= 0.0 {
            0.0
        } else {
            c * common::simpson(|y| y * y * (-y * y).exp() * (kt * y * y + v(d)), 0.0, (e / kt).sqrt(), 400)
        }
    };
    let bound_weight = common::simpson(|d| w(d) * p_bound(d), D[0], D[1], 2000);
    let bound_energy = common::simpson(|d| w(d) * h_bound(d), D[0], D[1], 2000) / bound_weight;
    // The centrifugal barrier outside d for angular momentum l.
    let barrier = |d: f64, l: f64| {
        let ueff = |r: f64| v(r) + l * l / (2.0 * m * r * r);
        let n = 400;
        let h = (D[1] - d) / n as f64;
        let best = (0..=n).max_by(|&a, &b| ueff(d + a as f64 * h).total_cmp(&ueff(d + b as f64 * h))).unwrap();
        let (mut a, mut b) = ((d + (best as f64 - 1.0) * h).max(d), (d + (best as f64 + 1.0) * h).min(D[1]));
        let g = (5f64.sqrt() - 1.0) / 2.0;
        for _ in 0..40 {
            let (x1, x2) = (b - g * (b - a), a + g * (b - a));
            if ueff(x1) < ueff(x2) { a = x1 } else { b = x2 }
        }
        ueff(0.5 * (a + b))
    };
    let sd = (kt / m).sqrt();
    let p_meta = |d: f64| {
        common::simpson(
            |s| {
                let density = s / (sd * sd) * (-0.5 * s * s / (sd * sd)).exp();
                let e_t = 0.5 * m * s * s + v(d);
                let b = barrier(d, m * d * s);
                let (lo, hi) = ((-e_t).max(0.0), b - e_t);
                if hi <= lo {
                    return 0.0;
                }
                // 1/2 m v_r^2 in [lo, hi): |v_r|/sd in [sqrt(2 lo / kT), sqrt(2 hi / kT)).
                density * 2.0 * normal((2.0 * lo / kt).sqrt(), (2.0 * hi / kt).sqrt())
            },
            0.0,
            8.0 * sd,
            200,
        )
    };
    let metastable = common::simpson(|d| w(d) * p_meta(d), D[0], D[1], 200) / norm;
    let monomer = 4.0 * PI * common::simpson(|r| r * r * (-0.5 * KB * (r - R0).powi(2) / kt).exp(), R[0], R[1], 2000);
    Quadrature { bound: bound_weight / norm, metastable, bound_energy, dimer: 4.0 * PI * bound_weight, monomer }
}

fn pairs() -> PairStates {
    PairStates {
        monomers: [vec![0], vec![2]],
        distance: 1,
        far: D[1],
        max_energy: None,
        monomer_integral: None,
        temperature: Some(T),
    }
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 6 s unoptimised on a loaded 2-core machine"]
fn the_quadratures_are_self_consistent() {
    // The metastable quadrature's Gaussian in v_r: with no barrier test (hi = infinity) the
    // probability of H_rel >= 0 is 1 - f_b.
    assert!((normal(0.0, 12.0) - 0.5).abs() < 1e-10);
    let q = quadrature();
    assert!(q.bound > 0.01 && q.bound < 0.2, "bound fraction {}", q.bound);
    assert!(q.metastable > 0.001 && q.metastable < q.bound, "metastable fraction {}", q.metastable);
    assert!(q.bound_energy < 0.0 && q.bound_energy > -EPS);
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 56 s unoptimised on a loaded 2-core machine"]
fn sampled_fractions_and_bound_energy_match_the_quadratures() {
    let q = quadrature();
    let region = Region { energy_cap: None, limits: [Some((R[0], R[1])), Some((D[0], D[1])), Some((0.0, PI))] };
    let sampler = Thermal::new(&N2arPair, T, &region, 17).unwrap();
    let c = census(&N2arPair, &pairs(), &sampler, None, 20_000);
    assert_eq!(c.left_out, 0);
    assert_eq!(c.total(), 20_000);
    let (fb, sb) = c.fraction(0);
    let (fm, sm) = c.fraction(1);
    assert!((fb - q.bound).abs() <= 4.0 * sb, "bound {fb} ± {sb}, quadrature {}", q.bound);
    assert!((fm - q.metastable).abs() <= 4.0 * sm, "metastable {fm} ± {sm}, quadrature {}", q.metastable);
    let (h, sh) = (c.energy[0].mean(), c.energy[0].standard_error());
    assert!((h - q.bound_energy).abs() <= 4.0 * sh, "<H_rel>_bound {h:e} ± {sh:e}, quadrature {:e}", q.bound_energy);
    // Precise enough to mean something.
    assert!(sb < 0.1 * q.bound && sm < 0.2 * q.metastable, "± {sb}, ± {sm}");
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rovib-pairstates-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn scene_text(n: u64, pairs: &str) -> String {
    format!(
        "molecule = \"n2ar_pair\"\n[units]\nlength = \"bohr\"\n[ensemble]\ntrajectories = {n}\nseed = 2811\n\
         method = \"thermal\"\ntemperature = {T}\nregion = {{ limits = {{ r = [{}, {}], d = [{}, {}], alpha = [0.0, \
         3.141592653589793] }} }}\n[statistics]\nmeans = [\"d\"]\ncorrelations = [\"mu_x\", \"mu_y\", \"mu_z\"]\n\
         [spectrum]\nestimator = \"pair\"\nmax_wavenumber = 1500.0\n[pairs]\n{pairs}\n[integrator]\n\
         method = \"dop853\"\nrtol = 1e-9\natol = 1e-10\n[run]\nend = 400.0\noutput_interval = 20.0\n",
        R[0], R[1], D[0], D[1]
    )
}

fn run(name: &str, text: &str) -> (PathBuf, serde_json::Value) {
    let scene = parse_scene("pairs.toml", text).unwrap();
    let dir = out_dir(name);
    run_ensemble(&scene, &common::ensemble::options(dir.clone(), 2)).unwrap();
    let summary = common::ensemble::summary(&dir);
    (dir, summary)
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 22 s unoptimised on a loaded 2-core machine"]
fn per_class_correlations_add_up_and_start_at_each_class_m0() {
    let q = quadrature();
    let (dir, s) = run(
        "classes",
        &scene_text(
            512,
            &format!("monomers = [[\"N2\"], [\"Ar\"]]\ndistance = \"d\"\nmonomer_integral = {}", q.monomer),
        ),
    );
    let p = &s["pair_states"];
    assert_eq!(p["states"].as_u64(), Some(512));
    let (h, rows) = csv(&dir.join("correlations_by_state.csv"));
    let (th, total) = csv(&dir.join("correlations.csv"));
    let zero = rows.iter().position(|r| r[0] == 0.0).unwrap();
    for (row, t) in rows.iter().zip(&total) {
        let sum: f64 =
            ["bound", "metastable", "free"].iter().map(|c| row[column(&h, &format!("C_{c}_(e*bohr)^2"))]).sum();
        let all: f64 = ["mu_x", "mu_y", "mu_z"].iter().map(|a| t[column(&th, &format!("{a}_C_(e*bohr)^2"))]).sum();
        assert!((sum - all).abs() <= 1e-12 * all.abs().max(1e-20), "tau {}: {sum:e} against {all:e}", row[0]);
    }
    // C_class(0) = fraction × <|mu|^2>_class over the same states.
    for c in ["bound", "metastable", "free"] {
        let c0 = rows[zero][column(&h, &format!("C_{c}_(e*bohr)^2"))];
        let class = &p["classes"][c];
        let expect = class["fraction"].as_f64().unwrap() * class["M0_phase_space"].as_f64().unwrap_or(0.0);
        assert!((c0 - expect).abs() <= 1e-9 * expect.abs().max(1e-30), "{c}: C(0) = {c0:e}, f M0 = {expect:e}");
    }
    // The dimer constant from the bound fraction and the configurational integral.
    let k = &p["dimer_constant"];
    let (kc, se) = (k["K_c_bohr3"].as_f64().unwrap(), k["K_c_stderr_bohr3"].as_f64().unwrap());
    assert!((kc - q.dimer).abs() <= 4.0 * se, "K_c = {kc:e} ± {se:e} bohr^3, quadrature {:e}", q.dimer);
    let cm3 = k["K_c_cm3_per_molecule"].as_f64().unwrap();
    assert!((cm3 / kc - 5.291_772_109_03e-9f64.powi(3)).abs() < 1e-30);
    let kp = k["K_p_atm-1"].as_f64().unwrap();
    assert!((kp - cm3 / (1.380649e-23 * T / 101325.0 * 1e6)).abs() <= 1e-12 * kp);
    assert!(dir.join("spectrum_by_state.csv").exists() && dir.join("pair_states.csv").exists());
}

#[test]
#[ignore = "heavy tier (CI: `cargo test --profile heavy -- --ignored`): 85 s unoptimised on a loaded 2-core machine"]
fn sampling_restricted_to_bound_pairs_matches_the_quadratures() {
    let q = quadrature();
    let text = scene_text(
        256,
        &format!(
            "monomers = [[\"N2\"], [\"Ar\"]]\ndistance = \"d\"\nmax_energy = 0.0\nmonomer_integral = {}",
            q.monomer
        ),
    );
    let (_, s) = run("restricted", &text);
    let p = &s["pair_states"];
    assert_eq!(p["classes"]["bound"]["count"].as_u64(), Some(256), "{p}");
    let (h, sh) = (p["H_rel_mean_hartree"].as_f64().unwrap(), p["H_rel_stderr_hartree"].as_f64().unwrap());
    assert!((h - q.bound_energy).abs() <= 4.0 * sh, "<H_rel> {h:e} ± {sh:e}, quadrature {:e}", q.bound_energy);
    let r = &p["restriction"];
    let (a, sa) = (r["acceptance"].as_f64().unwrap(), r["acceptance_stderr"].as_f64().unwrap());
    assert!((a - q.bound).abs() <= 4.0 * sa, "acceptance {a} ± {sa}, bound fraction {}", q.bound);
    let k = &p["dimer_constant"];
    let (kc, se) = (k["K_c_bohr3"].as_f64().unwrap(), k["K_c_stderr_bohr3"].as_f64().unwrap());
    assert!((kc - q.dimer).abs() <= 4.0 * se, "K_c = {kc:e} ± {se:e}, quadrature {:e}", q.dimer);
}

#[test]
fn pairs_keys_are_checked_at_their_place() {
    let base = scene_text(64, "monomers = [[\"N2\"], [\"Ar\"]]\ndistance = \"d\"");
    let line_of = |text: &str, needle: &str| text.lines().position(|l| l.contains(needle)).unwrap() + 1;
    let expect = |text: String, needle: &str, says: &str| {
        let e = match parse_scene("pairs.toml", &text) {
            Ok(scene) => run_ensemble(&scene, &common::ensemble::options(out_dir("bad"), 1)).unwrap_err().to_string(),
            Err(e) => e.to_string(),
        };
        let at = format!("pairs.toml:{}:", line_of(&text, needle));
        assert!(e.contains(&at) && e.contains(says), "expected {at} and {says:?} in\n{e}");
    };
    expect(base.replace("[\"Ar\"]]", "[\"Kr\"]]"), "monomers", "no atom `Kr`");
    expect(base.replace("[\"Ar\"]]", "[\"N2\"]]"), "monomers", "named twice");
    expect(base.replace("distance = \"d\"", "distance = \"R\""), "distance", "no coordinate `R`");
    expect(base.replace("distance = \"d\"", "distance = \"d\"\nfar = -1.0"), "far", "positive");
    expect(base.replace("distance = \"d\"", "distance = \"d\"\nmonomer = 1.0"), "monomer =", "unknown field");
    expect(base.replace("[[\"N2\"], [\"Ar\"]]", "[[\"N2\"]]"), "monomers", "two non-empty lists");
    let single = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/h2o.toml")).unwrap()
        + "\n[pairs]\ndistance = \"r1\"\n";
    let e = parse_scene("single.toml", &single).unwrap_err().to_string();
    assert!(e.contains("[pairs] table without an [ensemble]"), "{e}");
}
