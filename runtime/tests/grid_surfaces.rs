//! Tabulated surfaces (`rovib_runtime::grid`), checked against independent numbers: polynomials
//! the spline must reproduce exactly, the h⁴ / h³ convergence on smooth functions, central
//! differences of the spline itself, and located errors for every malformed grid file.

use nalgebra::SVector;
use rovib_runtime::diagnostic::Source;
use rovib_runtime::grid::{GridPotential, MAX_AXES, Outside, TensorSpline, parse};
use rovib_runtime::molecule::Coordinate;
use rovib_runtime::surface::Potential;
use rovib_runtime::units::{AngleUnit, CoordinateUnit, LengthUnit};

/// A fixed sequence of uniform numbers in [0, 1) (splitmix64).
struct Uniform(u64);
impl Uniform {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Non-uniform knots on [a, b]: n points, jittered by up to 30 % of the step.
fn knots(a: f64, b: f64, n: usize, rng: &mut Uniform) -> Vec<f64> {
    let h = (b - a) / (n - 1) as f64;
    (0..n).map(|i| a + h * i as f64 + if i == 0 || i == n - 1 { 0.0 } else { 0.3 * h * (rng.next() - 0.5) }).collect()
}

/// Samples `f` (value only) at every node, row-major.
fn sample(knots: &[Vec<f64>], f: &dyn Fn(&[f64; 3]) -> f64) -> Vec<f64> {
    let d = knots.len();
    let total: usize = knots.iter().map(Vec::len).product();
    (0..total)
        .map(|mut node| {
            let mut x = [0.0; 3];
            for a in (0..d).rev() {
                x[a] = knots[a][node % knots[a].len()];
                node /= knots[a].len();
            }
            f(&x)
        })
        .collect()
}

/// A polynomial of degree 3 in each variable (with mixed terms) and its gradient.
fn cubic(x: &[f64; 3]) -> (f64, [f64; 3]) {
    let p = |t: f64| 0.3 - 1.2 * t + 0.7 * t * t - 0.4 * t * t * t;
    let dp = |t: f64| -1.2 + 1.4 * t - 1.2 * t * t;
    let q = |t: f64| 1.0 + 0.5 * t * t * t;
    let dq = |t: f64| 1.5 * t * t;
    let [u, v, w] = *x;
    let value = p(u) * q(v) + u * u * v * w * w * w - 2.0 * v * v * v * w + q(w);
    let grad = [
        dp(u) * q(v) + 2.0 * u * v * w * w * w,
        p(u) * dq(v) + u * u * w * w * w - 6.0 * v * v * w,
        3.0 * u * u * v * w * w - 2.0 * v * v * v + dq(w),
    ];
    (value, grad)
}

#[test]
fn cubic_polynomials_are_reproduced_exactly_in_one_two_and_three_dimensions() {
    let mut rng = Uniform(7);
    for d in 1..=3 {
        let k: Vec<Vec<f64>> = (0..d).map(|a| knots(-1.0 + 0.2 * a as f64, 1.5, 5 + a, &mut rng)).collect();
        // Coordinates past the axis count are 0 in the evaluation, so the sampled function is too.
        let s = TensorSpline::new(k.clone(), 1, &sample(&k, &|x| cubic(x).0)).unwrap();
        for _ in 0..200 {
            let mut x = [0.0; MAX_AXES];
            for a in 0..d {
                x[a] = k[a][0] + (k[a][k[a].len() - 1] - k[a][0]) * rng.next();
            }
            let mut g = [0.0; MAX_AXES];
            let v = s.evaluate(0, &x, Outside::Error, &mut g);
            let (want, want_g) = cubic(&x);
            assert!((v - want).abs() < 1e-12 * (1.0 + want.abs()), "{d}D at {x:?}: {v} vs {want}");
            for a in 0..d {
                assert!(
                    (g[a] - want_g[a]).abs() < 1e-11 * (1.0 + want_g[a].abs()),
                    "{d}D ∂{a} at {x:?}: {} vs {}",
                    g[a],
                    want_g[a]
                );
            }
        }
    }
}

/// A smooth model surface: Morse(R) × (1 + 0.3 P2(cos θ)) + a harmonic third coordinate.
fn smooth(x: &[f64; 3]) -> (f64, [f64; 3]) {
    let [r, t, s] = *x;
    let e = (-1.1 * (r - 2.0)).exp();
    let morse = 0.1 * (1.0 - e) * (1.0 - e);
    let dmorse = 0.1 * 2.0 * (1.0 - e) * 1.1 * e;
    let c = t.cos();
    let p2 = 0.5 * (3.0 * c * c - 1.0);
    let dp2 = -3.0 * c * t.sin();
    let a = 1.0 + 0.3 * p2;
    let sr = (0.8 * s).sin();
    (
        morse * a * (1.0 + 0.2 * sr),
        [dmorse * a * (1.0 + 0.2 * sr), morse * 0.3 * dp2 * (1.0 + 0.2 * sr), morse * a * 0.16 * (0.8 * s).cos()],
    )
}

/// The largest errors of value and gradient (over all components) at fixed random points, for a
/// uniform grid with `n` points per axis over the first `d` axes.
fn errors(d: usize, n: usize) -> (f64, f64) {
    let boxes = [(1.2, 4.0), (0.0, std::f64::consts::PI), (-1.0, 1.5)];
    let k: Vec<Vec<f64>> = (0..d)
        .map(|a| (0..n).map(|i| boxes[a].0 + (boxes[a].1 - boxes[a].0) * i as f64 / (n - 1) as f64).collect())
        .collect();
    let s = TensorSpline::new(
        k,
        1,
        &sample(
            &(0..d)
                .map(|a| (0..n).map(|i| boxes[a].0 + (boxes[a].1 - boxes[a].0) * i as f64 / (n - 1) as f64).collect())
                .collect::<Vec<_>>(),
            &|x| smooth(x).0,
        ),
    )
    .unwrap();
    let mut rng = Uniform(11);
    let (mut ev, mut eg) = (0.0f64, 0.0f64);
    for _ in 0..400 {
        let mut x = [0.0; MAX_AXES];
        for a in 0..d {
            x[a] = boxes[a].0 + (boxes[a].1 - boxes[a].0) * rng.next();
        }
        let mut g = [0.0; MAX_AXES];
        let v = s.evaluate(0, &x, Outside::Error, &mut g);
        let (want, want_g) = smooth(&x);
        ev = ev.max((v - want).abs());
        for a in 0..d {
            eg = eg.max((g[a] - want_g[a]).abs());
        }
    }
    (ev, eg)
}

#[test]
fn interpolation_error_falls_as_h4_for_values_and_h3_for_gradients() {
    for (d, n) in [(1, 16), (2, 12), (3, 10)] {
        let (ev1, eg1) = errors(d, n);
        let (ev2, eg2) = errors(d, 2 * n - 1);
        let (ev3, eg3) = errors(d, 4 * n - 3);
        let order = |a: f64, b: f64| (a / b).log2();
        println!(
            "{d}D: n = {n}, {}, {}: value errors {ev1:.2e} {ev2:.2e} {ev3:.2e} (orders {:.2}, {:.2}); gradient errors \
             {eg1:.2e} {eg2:.2e} {eg3:.2e} (orders {:.2}, {:.2})",
            2 * n - 1,
            4 * n - 3,
            order(ev1, ev2),
            order(ev2, ev3),
            order(eg1, eg2),
            order(eg2, eg3)
        );
        assert!(order(ev2, ev3) > 3.6 && order(ev2, ev3) < 4.6, "{d}D value order {}", order(ev2, ev3));
        assert!(order(eg2, eg3) > 2.6 && order(eg2, eg3) < 3.6, "{d}D gradient order {}", order(eg2, eg3));
    }
}

fn coordinates() -> [Coordinate; 3] {
    let c = |name, unit| Coordinate { name, unit, reference: None, range: (f64::NEG_INFINITY, f64::INFINITY) };
    [
        c("R", CoordinateUnit::Length(LengthUnit::Bohr)),
        c("theta", CoordinateUnit::Angle(AngleUnit::Rad)),
        c("s", CoordinateUnit::Length(LengthUnit::Bohr)),
    ]
}

/// A grid file of `smooth` with axes in the order theta, s, R (not the coordinates' order),
/// angles in degrees and energies in cm-1.
fn smooth_file(n: usize) -> String {
    let mut text = String::from("# a test grid\ntheta[deg], s[bohr] R[bohr] energy[cm-1]\n");
    let cm = rovib_runtime::units::HARTREE_IN_WAVENUMBERS;
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let t = 180.0 * i as f64 / (n - 1) as f64;
                let s = -1.0 + 2.5 * j as f64 / (n - 1) as f64;
                let r = 1.2 + 2.8 * k as f64 / (n - 1) as f64;
                text.push_str(&format!("{t}, {s} {r}  {:e}\n", smooth(&[r, t.to_radians(), s]).0 * cm));
            }
        }
    }
    text
}

#[test]
fn the_gradient_is_the_derivative_of_the_interpolant() {
    let text = smooth_file(12);
    let grid = parse(&Source { path: "pes.csv", text: &text }).unwrap();
    let p = GridPotential::<3>::new(&grid, &coordinates(), Outside::Error).unwrap();
    let mut rng = Uniform(3);
    for _ in 0..100 {
        let q = SVector::from([1.25 + 2.7 * rng.next(), 0.05 + 3.0 * rng.next(), -0.95 + 2.4 * rng.next()]);
        let mut g = SVector::zeros();
        let u = p.energy_gradient(&q, &mut g);
        assert_eq!(u, p.energy(&q));
        for k in 0..3 {
            let h = 1e-5;
            let (mut a, mut b) = (q, q);
            a[k] += h;
            b[k] -= h;
            let numeric = (p.energy(&a) - p.energy(&b)) / (2.0 * h);
            assert!((g[k] - numeric).abs() < 1e-8 * (1.0 + g[k].abs()), "∂{k} at {q:?}: {} vs {numeric}", g[k]);
        }
        // Units: the file's cm-1 and degrees became hartree and radians.
        let (want, _) = smooth(&[q[0], q[1], q[2]]);
        assert!((u - want).abs() < 3e-3, "{u} vs {want}");
    }
}

#[test]
fn outside_the_box_error_gives_nan_and_extrapolate_continues_the_edge_cubic() {
    let text = "x[bohr] energy[hartree]\n0 0\n1 1\n2 8\n3 27\n";
    let grid = parse(&Source { path: "g.csv", text }).unwrap();
    let one = [coordinates()[0]];
    let mut renamed = one;
    renamed[0].name = "x";
    let stop = GridPotential::<1>::new(&grid, &renamed, Outside::Error).unwrap();
    let go = GridPotential::<1>::new(&grid, &renamed, Outside::Extrapolate).unwrap();
    let mut g = SVector::zeros();
    assert!(stop.energy_gradient(&SVector::from([3.0 + 1e-9]), &mut g).is_nan() && g[0].is_nan());
    assert!(stop.energy_gradient(&SVector::from([f64::NAN]), &mut g).is_nan());
    assert_eq!(stop.energy_gradient(&SVector::from([3.0]), &mut g), 27.0);
    // x³ through 4 points is x³ itself, continued on both sides.
    for x in [-0.5, 3.5, 5.0] {
        let u = go.energy_gradient(&SVector::from([x]), &mut g);
        assert!(
            (u - x * x * x).abs() < 1e-12 * (1.0 + u.abs()) && (g[0] - 3.0 * x * x).abs() < 1e-11 * (1.0 + g[0].abs())
        );
    }
    assert!(GridPotential::<1>::new(&grid, &one, Outside::Error).is_err());
}

#[test]
fn evaluation_allocates_nothing() {
    let text = smooth_file(5);
    let grid = parse(&Source { path: "pes.csv", text: &text }).unwrap();
    let p = GridPotential::<3>::new(&grid, &coordinates(), Outside::Extrapolate).unwrap();
    let mut g = SVector::zeros();
    let mut sum = 0.0;
    let info = allocation_counter::measure(|| {
        for i in 0..100 {
            sum += p.energy_gradient(&SVector::from([1.3 + 0.02 * i as f64, 1.0, 0.3]), &mut g);
        }
    });
    assert!(sum.is_finite());
    assert_eq!(info.count_total, 0);
}

/// The error for `text` as a grid file: (line, column, message).
fn error(text: &str) -> (usize, usize, String) {
    let e = parse(&Source { path: "pes.csv", text }).unwrap_err();
    assert_eq!(e.path, "pes.csv");
    (e.line, e.column, e.message)
}

#[test]
fn malformed_files_are_located_errors() {
    let ok = "a[bohr] b[rad] energy[hartree]\n";
    let block = |a: f64, bs: &[f64]| bs.iter().map(|b| format!("{a} {b} 0\n")).collect::<String>();
    let four = [0.0, 1.0, 2.0, 3.0];
    let good: String = ok.to_owned() + &[0.0, 1.0, 2.0, 3.0].iter().map(|&a| block(a, &four)).collect::<String>();
    assert!(parse(&Source { path: "p", text: &good }).is_ok());
    // A missing point inside: the next point is where the missing one should be.
    let missing = good.replacen("1 2 0\n", "", 1);
    let (line, column, m) = error(&missing);
    assert_eq!((line, column), (8, 3), "{m}");
    assert!(m.contains("expected a = 1, b = 2"), "{m}");
    // The last point missing.
    let (line, _, m) = error(good.trim_end().rsplit_once('\n').unwrap().0);
    assert_eq!(line, 16, "{m}");
    assert!(m.contains("ends after 15 points") && m.contains("has 16"), "{m}");
    // Non-rectangular: the second block has another b.
    let (line, column, m) = error(&good.replacen("1 2 0\n", "1 2.5 0\n", 1));
    assert_eq!((line, column), (8, 3), "{m}");
    // Unsorted and repeated axis values.
    let (line, _, m) = error(&(ok.to_owned() + &block(0.0, &[0.0, 2.0, 1.0, 3.0])));
    assert_eq!(line, 4, "{m}");
    assert!(m.contains("not increasing"), "{m}");
    let (_, _, m) = error(&(ok.to_owned() + &block(0.0, &[0.0, 1.0, 1.0, 3.0])));
    assert!(m.contains("repeated"), "{m}");
    // NaN, inf, a word.
    for bad in ["NaN", "inf", "x1"] {
        let (line, column, m) = error(&good.replacen("2 3 0\n", &format!("2 3 {bad}\n"), 1));
        assert_eq!((line, column), (13, 5), "{m}");
        assert!(m.contains("not a finite number") && m.contains("energy"), "{m}");
    }
    // Fewer than 4 values on an axis.
    let three: String =
        ok.to_owned() + &[0.0, 1.0, 2.0, 3.0].iter().map(|&a| block(a, &[0.0, 1.0, 2.0])).collect::<String>();
    let (line, column, m) = error(&three);
    assert_eq!((line, column), (1, 9), "{m}");
    assert!(m.contains("`b` has 3 values"), "{m}");
    // A short line, bad headers and units.
    let (line, _, m) = error(&good.replacen("2 3 0\n", "2 3\n", 1));
    assert_eq!(line, 13, "{m}");
    assert!(m.contains("2 fields"), "{m}");
    assert!(error("a[bohr] energy\n").2.contains("not a column"));
    assert!(error("a[furlong] energy[hartree]\n").2.contains("unknown coordinate unit"));
    assert!(error("a[bohr] energy[kJ]\n").2.contains("unknown energy unit"));
    assert!(error("a[bohr] b[bohr] c[bohr] d[bohr] energy[hartree]\n").2.contains("1 to 3"));
    assert!(error("a[bohr] energy[hartree] mu_x[debye]\n").2.contains("mu_x[unit], mu_y[unit], mu_z[unit]"));
    assert!(error("a[bohr] a[bohr] energy[hartree]\n").2.contains("named twice"));
    assert!(error("# nothing\n\n").2.contains("no header"));
    assert!(error("a[bohr] energy[hartree]\n").2.contains("no points"));
}

#[test]
fn dipole_columns_are_a_dipole_surface() {
    let mut text = String::from("x[angstrom] energy[eV] mu_x[debye] mu_y[debye] mu_z[debye]\n");
    for i in 0..6 {
        let x = 0.5 * i as f64;
        text.push_str(&format!("{x} {} {} 0 {}\n", x * x, x, 2.0 - x * x * x));
    }
    let grid = parse(&Source { path: "d.csv", text: &text }).unwrap();
    let mut c = [coordinates()[0]];
    c[0].name = "x";
    let p = GridPotential::<1>::new(&grid, &c, Outside::Error).unwrap();
    let d = p.dipole_part().expect("a dipole");
    let x = 1.3; // angstrom
    let q = SVector::from([x / rovib_runtime::units::BOHR_IN_ANGSTROM]);
    let mut mu = nalgebra::Vector3::zeros();
    d.moment(&q, &mut mu);
    let debye = rovib_runtime::units::DEBYE_IN_E_BOHR;
    assert!((mu[0] - x * debye).abs() < 1e-12 && mu[1] == 0.0 && (mu[2] - (2.0 - x * x * x) * debye).abs() < 1e-12);
    let mut j = nalgebra::SMatrix::<f64, 3, 1>::zeros();
    d.moment_jacobian(&q, &mut j);
    let a = rovib_runtime::units::BOHR_IN_ANGSTROM; // d/dq = (dx/dq) d/dx, x = q·a
    assert!((j[(2, 0)] - (-3.0 * x * x * debye * a)).abs() < 1e-11, "{j}");
    let u = p.energy(&q) * rovib_runtime::units::HARTREE_IN_EV;
    assert!((u - x * x).abs() < 1e-12, "{u}");
}
