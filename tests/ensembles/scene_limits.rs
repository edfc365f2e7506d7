//! Every setting of a scene is validated by the parser, at its
//! place in the file, before any file is touched; numbers in messages are compact; limits on
//! unbounded work carry their numbers and can be raised.

use rovib::molecules::H2o;
use rovib::runtime::diagnostic::FileError;
use rovib::runtime::integrate::{DEFAULT_MAX_STEPS, Dop853Options, GaussLegendreOptions, Method, Rk4Options};
use rovib::scene::parse_scene;
use rovib::start::initial_state;

const BASE: &str = r#"molecule = "h2o"

[units]
length = "angstrom"
angle = "deg"
time = "fs"

[initial]
q = { r1 = 1.0, r2 = 0.95, alpha = 104.0 }

[integrator]
INTEGRATOR

[run]
end = 20.0
output_interval = 1.0
"#;

const INTEGRATOR_LINE: usize = 12;

fn with(integrator: &str) -> String {
    BASE.replace("INTEGRATOR", integrator)
}

fn error(text: &str) -> FileError {
    match parse_scene("scenes/bad.toml", text) {
        Ok(s) => initial_state(&H2o, &s).err().unwrap_or_else(|| panic!("expected an error for\n{text}")),
        Err(e) => e,
    }
}

/// An error at `line` whose message contains every piece of `message` and is short (no number
/// written out in hundreds of digits).
fn check(e: &FileError, line: usize, message: &[&str]) {
    assert_eq!(e.path, "scenes/bad.toml");
    assert_eq!(e.line, line, "{e}");
    for m in message {
        assert!(e.message.contains(m), "`{m}` not in: {}", e.message);
    }
    assert!(e.message.len() < 200, "message too long ({} bytes): {}", e.message.len(), e.message);
    assert!(!e.help.is_empty());
}

#[test]
fn tolerances_outside_what_dop853_can_resolve_are_refused_where_written() {
    // 1e-300 passed the scene check and failed in the solver, printing 300 zeros.
    for rtol in ["1e-300", "1e-16", "0", "-1e-10", "2.0", "nan", "inf"] {
        let e = error(&with(&format!("method = \"dop853\"\nrtol = {rtol}")));
        check(&e, INTEGRATOR_LINE + 1, &["integrator.rtol"]);
    }
    let e = error(&with("method = \"dop853\"\nrtol = 1e-300"));
    check(&e, INTEGRATOR_LINE + 1, &["(2.22e-15, 1]", "got 1e-300"]);
    for atol in ["5e-324", "0", "-1", "inf"] {
        let e = error(&with(&format!("method = \"dop853\"\natol = {atol}")));
        check(&e, INTEGRATOR_LINE + 1, &["integrator.atol"]);
    }
    // The edges that are allowed.
    for ok in ["rtol = 2.3e-15", "rtol = 1.0", "atol = 1e-300", "atol = 1e300"] {
        assert!(parse_scene("ok.toml", &with(&format!("method = \"dop853\"\n{ok}"))).is_ok(), "{ok}");
    }
}

#[test]
fn steps_that_overflow_or_exceed_the_run_are_refused_where_written() {
    // 1e308 fs is infinite in atomic units: refused by the parser, at its place, not left to the
    // solver.
    let e = error(&with("method = \"rk4\"\nstep = 1e308"));
    check(&e, INTEGRATOR_LINE + 1, &["`integrator.step` is inf in atomic units"]);
    let e = error(&with("method = \"gauss-legendre\"\nstep = 0.0"));
    check(&e, INTEGRATOR_LINE + 1, &["integrator.step", "got 0"]);
    let e = error(&with("method = \"dop853\"\nmin_step = 1e308"));
    check(&e, INTEGRATOR_LINE + 1, &["`integrator.min_step` is inf in atomic units"]);
    let e = error(&with("method = \"dop853\"\nmin_step = 30.0"));
    check(&e, INTEGRATOR_LINE + 1, &["integrator.min_step", "not shorter than the run"]);
    for method in ["\"dop853\"", "\"rk4\"\nstep = 0.1", "\"gauss-legendre\"\nstep = 0.1"] {
        let e = error(&with(&format!("method = {method}\nmax_steps = 0")));
        check(&e, e.line, &["`integrator.max_steps` is 0"]);
        assert!(e.help.contains(&DEFAULT_MAX_STEPS.to_string()), "{}", e.help);
    }
    let e = error(
        &BASE.replace("INTEGRATOR", "method = \"dop853\"").replace("output_interval = 1.0", "output_interval = 1e307"),
    );
    check(&e, 16, &["`run.output_interval` is inf"]);
    let e = error(&with("method = \"dop853\"\ncompensated = true"));
    check(&e, INTEGRATOR_LINE + 1, &["`compensated` does not apply"]);
}

#[test]
fn fixed_step_runs_that_need_more_than_max_steps_are_refused_with_the_numbers() {
    // Gauss–Legendre and RK4 defaulted to max_steps = u64::MAX: now the same finite default as
    // DOP853, and the count is known before the run. 20 fs in steps of 1e-6 fs: 2e7 steps fit,
    // 1e-7 fs (2e8 steps) does not.
    for method in ["rk4", "gauss-legendre"] {
        assert!(parse_scene("ok.toml", &with(&format!("method = \"{method}\"\nstep = 1e-6"))).is_ok());
        let e = error(&with(&format!("method = \"{method}\"\nstep = 1e-7")));
        check(&e, INTEGRATOR_LINE + 1, &["needs 200000000 steps", "max_steps = 100000000"]);
        assert!(e.help.contains("raise integrator.max_steps"), "{}", e.help);
        // Raised on purpose, it runs (here: parses); the error then points at max_steps.
        let raised = with(&format!("method = \"{method}\"\nstep = 1e-7\nmax_steps = 200000000"));
        assert!(parse_scene("ok.toml", &raised).is_ok());
        let e = error(&with(&format!("method = \"{method}\"\nstep = 1e-7\nmax_steps = 199999999")));
        check(&e, INTEGRATOR_LINE + 2, &["needs 200000000 steps"]);
    }
}

#[test]
fn the_scene_and_the_runtime_share_one_set_of_integrator_defaults() {
    let s = parse_scene("d.toml", &BASE.replace("[integrator]\nINTEGRATOR\n", "")).unwrap();
    assert_eq!(s.method, Method::Dop853(Dop853Options::default()));
    let s = parse_scene("d.toml", &with("method = \"gauss-legendre\"\nstep = 0.1")).unwrap();
    let Method::GaussLegendre(o) = s.method else { panic!() };
    assert_eq!(o.max_steps, GaussLegendreOptions::default().max_steps);
    let s = parse_scene("d.toml", &with("method = \"rk4\"\nstep = 0.1")).unwrap();
    let Method::Rk4(o) = s.method else { panic!() };
    assert_eq!(o.max_steps, Rk4Options::default().max_steps);
    for max_steps in [Dop853Options::default().max_steps, o.max_steps, GaussLegendreOptions::default().max_steps] {
        assert_eq!(max_steps, DEFAULT_MAX_STEPS);
    }
    const { assert!(DEFAULT_MAX_STEPS < u64::MAX) };
}

#[test]
fn metric_thresholds_outside_what_the_runtime_can_test_are_refused() {
    // Below 1e-12 the runtime raised the threshold silently; at 1 or above every run stops.
    for pivot in ["1e-14", "1.0", "0"] {
        let text = with("method = \"dop853\"").replace("[run]\n", &format!("[run]\nmin_metric_pivot = {pivot}\n"));
        check(&error(&text), 15, &["run.min_metric_pivot"]);
    }
}

#[test]
fn euler_momenta_at_gimbal_lock_are_refused_and_j_there_is_accepted() {
    let text = BASE.replace("INTEGRATOR", "method = \"dop853\"");
    let e = error(&text.replace("[integrator]", "euler = [0, 0, 0]\npe = [1, 2, 3]\n[integrator]"));
    check(&e, 12, &["θ = 0 rad", "pe do not determine the angular momentum"]);
    assert!(e.help.contains("j = [Jx, Jy, Jz]"));
    for ok in ["euler = [0, 0, 0]\nj = [1, 2, 3]", "euler = [0, 180, 0]\npe = [0, 0, 0]"] {
        let s = parse_scene("ok.toml", &text.replace("[integrator]", &format!("{ok}\n[integrator]"))).unwrap();
        let start = initial_state(&H2o, &s).unwrap();
        if ok.contains("j =") {
            assert_eq!(start.body.j.as_slice(), [1.0, 2.0, 3.0]);
        }
    }
}

#[test]
fn lab_velocities_and_positions_that_overflow_are_refused() {
    let lab = |x: &str, v: &str| {
        BASE.replace("INTEGRATOR", "method = \"dop853\"").replace(
            "q = { r1 = 1.0, r2 = 0.95, alpha = 104.0 }",
            &format!(
                "positions = {{ O = [{x}, 0, 0.0], H1 = [0.76, 0.0, 0.59], H2 = [-0.76, 0.0, 0.59] }}\n\
                 velocities = {{ O = [{v}, 0, 0], H1 = [{v}, 0, 0], H2 = [{v}, 0, 0] }}"
            ),
        )
    };
    // 1e308 Å per ħ/E_h is infinite in bohr per ħ/E_h: lab.xyz got `inf`.
    let au = |text: String| text.replace("time = \"fs\"", "time = \"au\"");
    check(&error(&au(lab("0.0", "1e308"))), 10, &["`velocities.", "overflows in atomic units"]);
    check(&error(&lab("1e308", "0")), 9, &["`positions.O` overflows in atomic units"]);
    // Finite but faster than light (3e3 Å/fs > c = 2998 Å/fs) or carried beyond 1e9 bohr.
    check(&error(&lab("0.0", "3000.0")), 9, &["centre of mass moves at", "not slower than light"]);
    check(&error(&lab("1e9", "0")), 9, &["would reach", "more than 1000000000"]);
    check(&error(&lab("0.0", "2e6")), 9, &["not slower than light"]);
    let s = parse_scene("ok.toml", &lab("0.0", "0.01")).unwrap();
    let start = initial_state(&H2o, &s).unwrap();
    assert!((start.com_velocity[0] - 0.01 / 0.529_177_210_903 * 0.024_188_843_265_857).abs() < 1e-15);
}

/// An ensemble scene bound to water: `Ok` or the located error of parsing or binding.
fn bind_ensemble(text: &str) -> Result<(), FileError> {
    use rovib::ensemble::output_times;
    use rovib::ensemble::scene::parse_ensemble;
    let scene = parse_scene("big.toml", text)?;
    let e = parse_ensemble(&scene)?;
    e.bind(&H2o, &scene, &output_times(scene.t_end, scene.output_interval)).map(|_| ())
}

/// Ensembles whose statistics or kept trajectories would exhaust memory or disk are refused
/// before the first trajectory, with the estimate and the key that raises the cap; raising it
/// accepts them. (Before, these ran until killed or aborted on allocation.)
#[test]
fn ensembles_beyond_the_memory_and_disk_caps_are_refused_with_their_figures() {
    let head = "molecule = \"h2o\"\n[ensemble]\ntrajectories = 100000\nthreads = 2\nmethod = \"thermal\"\n\
                temperature = 300\nregion = { energy_cap = 0.1 }\n";
    let times: Vec<String> = (0..100).map(|k| format!("{}", k * 10)).collect();
    let big_histogram = format!(
        "[statistics]\nhistograms = [{{ quantity = \"r1\", bins = 1000000, range = [0, 5], times = [{}] }}]\n",
        times.join(", ")
    );
    let run = "[run]\nend = 1000\noutput_interval = 10\n";
    // 10^6 bins × 100 times: 0.8 GB per set of accumulators, several sets in flight.
    let e = bind_ensemble(&format!("{head}{big_histogram}{run}")).unwrap_err();
    assert_eq!(e.line, 3, "{e}");
    assert!(e.message.contains("would need about") && e.message.contains("GB of memory"), "{e}");
    assert!(e.message.contains("100000000 histogram bins") && e.message.contains("max_memory_gb = 4"), "{e}");
    assert!(e.help.contains("raise ensemble.max_memory_gb"), "{e}");
    // With the memory allowed, the checkpoint (a 0.3 GB line per block) exceeds the disk cap.
    let raised = format!("{head}max_memory_gb = 100\n{big_histogram}{run}");
    let e = bind_ensemble(&raised).unwrap_err();
    assert!(e.message.contains("would write about") && e.message.contains("max_disk_gb = 20"), "{e}");
    assert_eq!(e.line, 3, "{e}");
    bind_ensemble(&raised.replace("max_memory_gb = 100\n", "max_memory_gb = 100\nmax_disk_gb = 1000\n")).unwrap();
    // 300 histograms of 10^6 bins at one time each.
    let many: Vec<String> =
        (0..300).map(|_| "{ quantity = \"r1\", bins = 1000000, range = [0, 5] }".to_owned()).collect();
    let e = bind_ensemble(&format!("{head}[statistics]\nhistograms = [{}]\n{run}", many.join(", "))).unwrap_err();
    assert!(e.message.contains("300000000 histogram bins"), "{e}");
    // Every trajectory kept, 10^5 trajectories × 10^4 output times: hundreds of GB.
    let kept = format!("{head}keep_trajectories = 1\n[run]\nend = 10000\noutput_interval = 1\n");
    let e = bind_ensemble(&kept).unwrap_err();
    assert!(e.message.contains("kept trajectories") && e.message.contains("max_disk_gb"), "{e}");
    assert!(e.help.contains("keep fewer trajectories"), "{e}");
    let kept_raised = kept.replace("keep_trajectories = 1\n", "keep_trajectories = 1\nmax_disk_gb = 1e6\n");
    bind_ensemble(&kept_raised).unwrap();
    // The caps themselves are checked where written.
    let e = bind_ensemble(&format!("{head}max_disk_gb = -1\n{run}")).unwrap_err();
    assert_eq!(e.line, 8, "{e}");
    assert!(e.message.contains("`ensemble.max_disk_gb` must be a positive finite number of GB, got -1"), "{e}");
    // An ordinary ensemble is far below both.
    bind_ensemble(&format!("{head}{run}")).unwrap();
}
