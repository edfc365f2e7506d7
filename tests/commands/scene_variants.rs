//! Variant tables (`[integrator]`): each method takes only its own keys, a key of another method
//! is refused at the key, a missing required key at the method, an unknown method with a
//! did-you-mean; values keep their places; summary.json names the method as the scene does.

use rovib::runtime::diagnostic::FileError;
use rovib::runtime::integrate::{Dop853Options, GaussLegendreOptions, Method, Rk4Options};
use rovib::scene::parse_scene;

/// A scene whose `[integrator]` table is `table` (starting on line 6).
fn scene(table: &str) -> String {
    format!("molecule = \"h2o\"\n[initial]\nq = {{ r1 = 1.0 }}\n\n[integrator]\n{table}\n[run]\nend = 2.0\n")
}

fn error(table: &str) -> FileError {
    parse_scene("scenes/bad.toml", &scene(table)).expect_err("an error")
}

fn method(table: &str) -> Method {
    match parse_scene("s.toml", &scene(table)) {
        Ok(s) => s.method,
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn a_key_of_another_method_is_refused_at_the_key() {
    let e = error("method = \"dop853\"\nrtol = 1e-9\n  step = 0.1");
    assert_eq!(e.message, "`step` does not apply to the adaptive dop853 method");
    assert_eq!((e.line, e.column), (8, 3), "at the key");
    assert_eq!(e.help, "remove it, or choose a method it applies to");

    let e = error("method = \"dop853\"\ncompensated = true");
    assert_eq!(e.message, "`compensated` does not apply to the dop853 method");
    assert_eq!((e.line, e.column), (7, 1));

    let e = error("method = \"gauss-legendre\"\nstep = 0.1\nmin_step = 1e-3");
    assert_eq!(e.message, "`min_step` does not apply to the fixed-step gauss-legendre method");
    assert_eq!((e.line, e.column), (8, 1));

    let e = error("method = \"rk4\"\nstep = 0.1\nstages = 3");
    assert_eq!(e.message, "`stages` does not apply to the rk4 method");
    assert_eq!((e.line, e.column), (8, 1));

    let e = error("method = \"rk4\"\nstep = 0.1\natol = 1e-9");
    assert_eq!(e.message, "`atol` does not apply to the fixed-step rk4 method");
}

#[test]
fn a_missing_required_key_is_reported_at_the_method() {
    let e = error("step_ = 0.1\nmethod = \"gauss-legendre\"");
    // The unknown key comes first, at its place, with the scene reference.
    assert!(e.message.starts_with("unknown field `step_`, expected one of `method`, `rtol`"), "{}", e.message);
    assert_eq!((e.line, e.column), (6, 1));
    assert!(e.help.contains("docs/src/reference/scene.md"), "{}", e.help);

    let e = error("stages = 3\nmethod = \"gauss-legendre\"");
    assert_eq!(e.message, "the gauss-legendre method needs a step");
    assert_eq!((e.line, e.column), (7, 10), "at the method's value");

    let e = error("max_steps = 10\nrtol = 1e-8");
    assert_eq!(e.message, "missing field `method`");
    assert!(e.help.contains("docs/src/reference/scene.md"), "{}", e.help);
}

#[test]
fn an_unknown_method_gets_a_did_you_mean() {
    let e = error("method = \"rk5\"\nstep = 0.1");
    assert_eq!(e.message, "unknown integrator `rk5`");
    assert_eq!((e.line, e.column), (6, 10));
    assert!(e.help.starts_with("did you mean \"rk4\"? use \"dop853\""), "{}", e.help);

    let e = error("method = \"gauss\"\nstep = 0.1");
    assert!(!e.help.starts_with("did you mean"), "nothing close: {}", e.help);
    assert!(e.help.contains("gauss-legendre"), "{}", e.help);
}

#[test]
fn values_are_read_into_their_types_at_their_places() {
    let e = error("method = \"dop853\"\nrtol = \"tight\"");
    assert_eq!(e.message, "invalid type: string \"tight\", expected f64");
    assert_eq!((e.line, e.column), (7, 8));

    let e = error("method = \"gauss-legendre\"\nstep = 0.1\nstages = -2");
    assert!(e.message.starts_with("invalid value: integer `-2`"), "{}", e.message);
    assert_eq!((e.line, e.column), (8, 10));

    let e = error("method = 3");
    assert_eq!(e.message, "invalid type: integer `3`, expected a string");
    assert_eq!((e.line, e.column), (6, 10));

    let e = error("method = \"rk4\"\nstep = 0.1\nmax_steps = 0");
    assert_eq!(e.message, "`integrator.max_steps` is 0");
    assert_eq!((e.line, e.column), (8, 13));

    // Every variant's values reach its options (integers are accepted for numbers).
    assert_eq!(
        method("method = \"dop853\"\nrtol = 1e-9\natol = 1e-12\nmax_steps = 7"),
        Method::Dop853(Dop853Options { rtol: 1e-9, atol: 1e-12, max_steps: 7, ..Default::default() })
    );
    assert_eq!(
        method("method = \"gauss-legendre\"\nstep = 1\nstages = 3\ncompensated = false"),
        Method::GaussLegendre(GaussLegendreOptions { step: 1.0, stages: 3, compensated: false, ..Default::default() })
    );
    assert_eq!(
        method("method = \"rk4\"\nstep = 0.5\nmax_steps = 100"),
        Method::Rk4(Rk4Options { step: 0.5, max_steps: 100 })
    );
}

#[test]
fn summary_json_names_the_method_as_the_scene_does() {
    let json = |m: Method| serde_json::to_value(m).unwrap();
    assert_eq!(
        json(Method::Dop853(Dop853Options { rtol: 1e-9, atol: 1e-12, ..Default::default() })),
        serde_json::json!({"name": "dop853", "rtol": 1e-9, "atol": 1e-12})
    );
    assert_eq!(
        json(Method::GaussLegendre(GaussLegendreOptions {
            step: 2.0,
            stages: 3,
            compensated: true,
            ..Default::default()
        })),
        serde_json::json!({"name": "gauss-legendre", "stages": 3, "step_au": 2.0, "compensated": true})
    );
    assert_eq!(
        json(Method::Rk4(Rk4Options { step: 0.5, ..Default::default() })),
        serde_json::json!({"name": "rk4", "step_au": 0.5})
    );
}
