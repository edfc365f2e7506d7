//! The two ways the generator builds `∂T/∂q` (`GradientMethod::Direct`, from explicit second
//! derivatives, and `GradientMethod::Reverse`, a directional derivative along q̇ and one
//! reverse sweep) against each other and against central finite differences of `T` itself, on
//! the graph (no compilation), for water, methane and the ethane and propane fixtures, at
//! states away from the reference geometry with every velocity non-zero.

use rovib_codegen::expr::ExprId;
use rovib_codegen::kinetic::{self, GradientMethod, Options};
use rovib_codegen::parse_definition;

/// `(T, ∂T/∂q)` of `path` by `method`, evaluated at `vars` (q, ω, q̇).
fn evaluate(path: &str, method: GradientMethod, vars: &dyn Fn(usize) -> Vec<f64>) -> (usize, Vec<f64>, Vec<f64>) {
    let text = std::fs::read_to_string(path).expect("fixture");
    let mut def = parse_definition(path, &text).expect("valid definition");
    let e = kinetic::build(&mut def, &Options { kinetic_gradient: method, ..Options::default() });
    assert_eq!(e.gradient_method, method);
    let n = e.n;
    let x = vars(n);
    let mut roots: Vec<ExprId> = vec![e.kinetic_energy];
    roots.extend(&e.kinetic_gradient);
    let values = def.graph.eval(&roots, &x);
    // T at q ± h e_k, for finite differences.
    let fd = (0..n)
        .map(|k| {
            let h = 1e-5 * x[k].abs().max(1.0);
            let mut plus = x.clone();
            plus[k] += h;
            let mut minus = x.clone();
            minus[k] -= h;
            let tp = def.graph.eval(&[e.kinetic_energy], &plus)[0];
            let tm = def.graph.eval(&[e.kinetic_energy], &minus)[0];
            (tp - tm) / (2.0 * h)
        })
        .collect();
    (n, values, fd)
}

/// q: the reference geometry moved by a few per cent; ω and q̇ of order one.
fn state(path: &str) -> impl Fn(usize) -> Vec<f64> {
    let text = std::fs::read_to_string(path).expect("fixture");
    let def = parse_definition(path, &text).expect("valid definition");
    let reference: Vec<f64> =
        def.coordinates.iter().map(|c| c.reference.unwrap_or(1.0) * c.unit.in_atomic_units()).collect();
    move |n| {
        let mut x: Vec<f64> =
            reference.iter().enumerate().map(|(k, r)| r * (1.0 + 0.03 * ((k % 5) as f64 - 2.0))).collect();
        x.extend([0.7, -0.4, 0.3]);
        x.extend((0..n).map(|k| 0.5 - 0.13 * (k % 9) as f64 + 0.01));
        x
    }
}

fn check(path: &str) {
    let vars = state(path);
    let (n, direct, fd) = evaluate(path, GradientMethod::Direct, &vars);
    let (_, reverse, _) = evaluate(path, GradientMethod::Reverse, &vars);
    let scale = direct[1..].iter().fold(direct[0].abs(), |m, v| m.max(v.abs()));
    assert!((reverse[0] - direct[0]).abs() <= 1e-13 * scale, "{path}: T {} vs {}", reverse[0], direct[0]);
    for k in 0..n {
        let (d, r, f) = (direct[1 + k], reverse[1 + k], fd[k]);
        assert!((d - r).abs() <= 1e-11 * scale, "{path}: dT/dq_{k}: direct {d}, reverse {r}");
        assert!((r - f).abs() <= 1e-6 * scale, "{path}: dT/dq_{k}: reverse {r}, finite differences {f}");
    }
}

#[test]
fn water_gradients_agree() {
    check("../molecules/h2o.toml");
}

#[test]
fn methane_gradients_agree() {
    check("../molecules/ch4.toml");
}

#[test]
fn ethane_gradients_agree() {
    check("tests/fixtures/alkanes/ethane.toml");
}

#[test]
fn propane_gradients_agree() {
    check("tests/fixtures/alkanes/propane.toml");
}

/// Large molecules get the reverse method by default, small ones keep the direct one.
#[test]
fn the_default_picks_by_size() {
    for (path, expected) in [
        ("../molecules/h2o.toml", GradientMethod::Direct),
        ("tests/fixtures/alkanes/propane.toml", GradientMethod::Reverse),
    ] {
        let text = std::fs::read_to_string(path).expect("fixture");
        let mut def = parse_definition(path, &text).expect("valid definition");
        assert_eq!(kinetic::build(&mut def, &Options::default()).gradient_method, expected, "{path}");
    }
}
