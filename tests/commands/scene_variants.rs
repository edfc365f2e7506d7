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
    assert_eq!(e.help, "the gauss-legendre and rk4 methods take `step`: remove it, or choose one of them");

    let e = error("method = \"dop853\"\ncompensated = true");
    assert_eq!(e.message, "`compensated` does not apply to the dop853 method");
    assert_eq!((e.line, e.column), (7, 1));
    assert_eq!(e.help, "only the gauss-legendre method takes `compensated`: remove it, or choose that method");

    // The first such key in the file is the one reported.
    let e = error("method = \"dop853\"\nstages = 3\nstep = 0.1");
    assert_eq!(e.message, "`stages` does not apply to the dop853 method");
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
    // The unknown key comes first, at its place, with the method's keys, a did-you-mean and the
    // scene reference.
    assert_eq!(
        e.message,
        "unknown field `step_`, expected one of `method`, `step`, `stages`, `compensated`, `max_steps`"
    );
    assert_eq!((e.line, e.column), (6, 1));
    assert!(e.help.starts_with("did you mean `step`? "), "{}", e.help);
    assert!(e.help.contains("docs/src/reference/scene.md"), "{}", e.help);

    let e = error("stages = 3\nmethod = \"gauss-legendre\"");
    assert_eq!(e.message, "the gauss-legendre method needs a step");
    assert_eq!((e.line, e.column), (7, 10), "at the method's value");

    let e = error("max_steps = 10\nrtol = 1e-8");
    assert_eq!(e.message, "missing field `method`");
    assert!(e.help.contains("docs/src/reference/scene.md"), "{}", e.help);
}

#[test]
fn an_unknown_key_lists_the_method_s_keys_with_a_did_you_mean() {
    let e = error("method = \"rk4\"\nstep = 0.1\nmax_step = 10");
    assert_eq!(e.message, "unknown field `max_step`, expected one of `method`, `step`, `max_steps`");
    assert_eq!((e.line, e.column), (8, 1), "at the key");
    assert!(e.help.starts_with("did you mean `max_steps`? docs/src/reference/scene.md"), "{}", e.help);

    // Close to no key of the method but to another method's: that one, with its method.
    let e = error("method = \"dop853\"\ncompensate = true");
    assert_eq!(
        e.message,
        "unknown field `compensate`, expected one of `method`, `rtol`, `atol`, `min_step`, `max_steps`"
    );
    assert!(e.help.starts_with("did you mean `compensated` (a key of the gauss-legendre method)? "), "{}", e.help);

    // Close to nothing: the list and the reference only.
    let e = error("method = \"dop853\"\ntolerance_of_everything = 1");
    assert_eq!((e.line, e.column), (7, 1));
    assert!(e.help.starts_with("docs/src/reference/scene.md"), "{}", e.help);
}

#[test]
fn each_method_s_bad_values_are_refused_at_their_places() {
    // dop853: rtol, atol, min_step.
    let e = error("method = \"dop853\"\nrtol = 2");
    assert!(e.message.starts_with("`integrator.rtol` must lie in (10·ε, 1]"), "{}", e.message);
    assert_eq!((e.line, e.column), (7, 8));
    let e = error("method = \"dop853\"\natol = 1e-320");
    assert!(e.message.contains("is subnormal"), "{}", e.message);
    assert_eq!((e.line, e.column), (7, 8));
    let e = error("method = \"dop853\"\nmin_step = 5.0");
    assert!(e.message.starts_with("`integrator.min_step` (5 a.u.) is not shorter than the run"), "{}", e.message);
    assert_eq!((e.line, e.column), (7, 12));
    let e = error("method = \"dop853\"\nmax_steps = 0");
    assert_eq!(e.message, "`integrator.max_steps` is 0");
    assert_eq!((e.line, e.column), (7, 13));

    // gauss-legendre: stages, step, the step count against max_steps (at max_steps).
    let e = error("method = \"gauss-legendre\"\nstep = 0.1\nstages = 4");
    assert_eq!(e.message, "Gauss–Legendre with 4 stages is not available");
    assert_eq!((e.line, e.column), (8, 10));
    let e = error("method = \"gauss-legendre\"\nstep = -0.1");
    assert_eq!(e.message, "`integrator.step` must be a positive finite number, got -0.1");
    assert_eq!((e.line, e.column), (7, 8));
    let e = error("method = \"gauss-legendre\"\nstep = 0.1\nmax_steps = 5");
    assert!(e.message.starts_with("the run needs 100 steps"), "{}", e.message);
    assert_eq!((e.line, e.column), (8, 13));

    // rk4: the step, needed, and its count against the default limit (at the step).
    let e = error("method = \"rk4\"\nmax_steps = 5");
    assert_eq!(e.message, "the rk4 method needs a step");
    assert_eq!((e.line, e.column), (6, 10));
    let e = error("method = \"rk4\"\nstep = 1e-9");
    assert!(e.message.starts_with("the run needs 2000000000 steps"), "{}", e.message);
    assert_eq!((e.line, e.column), (7, 8));
}

#[test]
fn an_unknown_method_gets_a_did_you_mean() {
    let e = error("method = \"rk5\"\nstep = 0.1");
    assert_eq!(e.message, "unknown integrator `rk5`");
    assert_eq!((e.line, e.column), (6, 10));
    assert_eq!(
        e.help,
        "did you mean \"rk4\"? use \"dop853\" (adaptive, tolerances), \"gauss-legendre\" (symplectic, fixed step) \
         or \"rk4\" (fixed step)"
    );

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
