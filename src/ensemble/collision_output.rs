//! The files of a collision ensemble: final_states.csv (one row per completed trajectory, units
//! in the header), collision_histograms.csv (area-weighted distributions of ΔE, the deflection
//! angle, the lifetime and each fragment's final rotational energy) and summary.json (counts,
//! cross sections, energy-transfer moments, conservation, failures); and the entry point that
//! runs the ensemble and writes them.

use std::path::PathBuf;

use serde_json::json;

use super::collision_final::{Estimate, Outcome, Record};
use super::collision_run::{CollisionReport, run};
use super::collision_scene::CollisionScene;
use super::runner::{Accumulators, LISTED_FAILURES};
use super::scene::{EnsembleScene, MethodSpec, parse_ensemble};
use super::{EnsembleOptions, EnsembleReport, Status};
use crate::error::Error;
use crate::molecules;
use crate::output::OutputFile;
use crate::runtime::sample::collision::{FragmentRotation, FragmentVibration, RelativeEnergy};
use crate::runtime::{Molecule, MoleculeVisitor};
use crate::scene::Scene;

/// The columns of final_states.csv.
pub const FINAL_STATES_HEADER: &str = "index,stratum,b_bohr,outcome,e_trans_initial_hartree,e_trans_final_hartree,\
delta_e_hartree,e_rot_a_initial_hartree,e_rot_a_final_hartree,e_vib_a_initial_hartree,e_vib_a_final_hartree,\
l_a_initial_hbar,l_a_final_hbar,e_rot_b_initial_hartree,e_rot_b_final_hartree,e_vib_b_initial_hartree,\
e_vib_b_final_hartree,l_b_initial_hbar,l_b_final_hbar,l_orbital_initial_hbar,l_orbital_final_hbar,deflection_rad,\
lifetime_au,t_end_au,r_min_bohr,r_final_bohr,energy_change_hartree,angular_momentum_change_hbar";

/// Runs the collision ensemble of `scene` (method = "collision") and writes its files.
pub fn run_collisions(scene: &Scene, options: &EnsembleOptions) -> Result<(EnsembleReport, CollisionReport), Error> {
    let ensemble = parse_ensemble(scene)?;
    let name = scene.molecule.get_ref().clone();
    molecules::visit(&name, Visit { scene, ensemble: &ensemble, options }).ok_or_else(|| {
        let e = Error::unknown_molecule(&name);
        Error::File(scene.source().error(scene.molecule.span(), e.to_string(), "use a name from `rovib list`"))
    })?
}

struct Visit<'a> {
    scene: &'a Scene,
    ensemble: &'a EnsembleScene,
    options: &'a EnsembleOptions,
}

impl MoleculeVisitor for Visit<'_> {
    type Output = Result<(EnsembleReport, CollisionReport), Error>;

    fn visit<M, const N: usize, const NA: usize>(self, m: M) -> Self::Output
    where
        M: Molecule<N, NA> + Copy + Send + Sync + 'static,
    {
        let MethodSpec::Collision(super::method::collision::Collision(c)) = &self.ensemble.method else {
            return Err(Error::Message("the scene's ensemble method is not \"collision\"".into()));
        };
        crate::scene_molecule::with_scene_molecule(self.scene, m, Collide { visit: self, collision: c })
    }
}

/// The collisions of a visit, run on the scene's molecule.
struct Collide<'a> {
    visit: Visit<'a>,
    collision: &'a CollisionScene,
}

impl crate::scene_molecule::SceneMoleculeUser for Collide<'_> {
    type Output = (EnsembleReport, CollisionReport);

    fn with_molecule<M, const N: usize, const NA: usize>(self, m: M) -> Result<Self::Output, Error>
    where
        M: Molecule<N, NA> + Sync,
    {
        let Visit { scene, ensemble, options } = self.visit;
        run_and_write(&m, scene, ensemble, self.collision, options)
    }
}

/// Runs the collisions for molecule `m` (the scene's potential already applied) and writes the
/// files into `options.out_dir`.
pub fn run_and_write<M, const N: usize, const NA: usize>(
    m: &M,
    scene: &Scene,
    ensemble: &EnsembleScene,
    c: &CollisionScene,
    options: &EnsembleOptions,
) -> Result<(EnsembleReport, CollisionReport), Error>
where
    M: Molecule<N, NA> + Sync,
{
    if options.resume {
        return Err(scene
            .source()
            .error(
                ensemble.method_span(),
                "a collision ensemble cannot be resumed (`--resume`, `EnsembleOptions::resume`): it keeps no checkpoint",
                "run the scene again without resuming (an interrupted run's final_states.csv keeps the \
                 trajectories it completed; see docs/src/reference/ensemble.md)",
            )
            .into());
    }
    std::fs::create_dir_all(&options.out_dir)
        .map_err(|e| Error::context(format!("cannot create {}", options.out_dir.display()), e))?;
    let _lock = crate::dir_lock::DirLock::acquire(&options.out_dir)?;
    let (report, wall, threads) = run(m, scene, ensemble.trajectories, ensemble.seed, ensemble.threads, c, options)?;
    let dir = &options.out_dir;
    let interrupted = options.stop.load(std::sync::atomic::Ordering::Relaxed);
    let mut files = Vec::new();
    write_final_states(dir, &report.records)?;
    files.push(dir.join("final_states.csv"));
    // The histograms are statistics of the whole ensemble: an interrupted run writes none (and
    // leaves no earlier run's behind).
    let histograms = dir.join("collision_histograms.csv");
    if interrupted {
        match std::fs::remove_file(&histograms) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(Error::context(format!("cannot remove {}", histograms.display()), e));
            }
            _ => {}
        }
    } else {
        write_histograms(dir, &report, c)?;
        files.push(histograms);
    }
    let status = if interrupted {
        Status::Interrupted
    } else if report.records.is_empty() {
        Status::Failed
    } else {
        Status::Completed
    };
    let description = describe(c);
    let mut outcome = super::runner::Outcome::new(Accumulators {
        n_times: 0,
        n_means: 0,
        means: Vec::new(),
        histograms: Vec::new(),
        correlations: Vec::new(),
    });
    outcome.completed = report.records.len() as u64;
    for f in &report.failures {
        *outcome.failed.entry(f.reason.clone()).or_default() += 1;
    }
    outcome.first_failures = report.failures.iter().take(LISTED_FAILURES).cloned().collect();
    // Cut short by the interrupt, or never started.
    outcome.interrupted = ensemble.trajectories.saturating_sub(outcome.completed + report.failures.len() as u64);
    write_summary(dir, scene, ensemble, c, &report, &description, status, wall, threads)?;
    files.push(dir.join("summary.json"));
    let ensemble_report = EnsembleReport {
        status,
        requested: ensemble.trajectories,
        outcome,
        times: Vec::new(),
        quantities: Vec::new(),
        units: Vec::new(),
        wall_time: wall,
        threads,
        threads_note: None,
        lanes_note: None,
        ranks: 1,
        blocks_by_rank: Vec::new(),
        resumed: 0,
        seed: ensemble.seed,
        sampler: description,
        phase_space: None,
        pair_states: None,
        files,
        tables: None,
    };
    Ok((ensemble_report, report))
}

/// One line saying how the collisions were drawn.
fn describe(c: &CollisionScene) -> String {
    let energy = match c.energy {
        RelativeEnergy::Fixed(e) => format!("E = {e} hartree"),
        RelativeEnergy::Thermal(t) => format!("E flux-weighted Maxwell-Boltzmann at {t} K"),
    };
    let b = if c.stratified {
        format!("b² uniform in {} strata up to {} bohr", c.strata.len(), c.strata.last().map_or(0.0, |s| s.high))
    } else {
        format!("b² uniform up to b_max = {} bohr", c.strata[0].high)
    };
    let frag = |k: usize| {
        let rot = match c.rotation[k] {
            FragmentRotation::None => "no rotation".to_owned(),
            FragmentRotation::Thermal(t) => format!("rotation thermal at {t} K"),
            FragmentRotation::Quantum(j) => format!("rotation J = {j}"),
        };
        let vib = match c.vibration[k] {
            FragmentVibration::None => "no vibration".to_owned(),
            FragmentVibration::Thermal(t) => format!("vibration thermal (harmonic) at {t} K"),
            FragmentVibration::Quantum(v) => format!("vibration v = {v} (harmonic)"),
        };
        format!("{rot}, {vib}")
    };
    format!("collisions: {b}, {energy}, r0 = {} bohr, A: {}, B: {}, random orientations", c.r0, frag(0), frag(1))
}

fn write_final_states(dir: &std::path::Path, records: &[Record]) -> Result<(), Error> {
    let mut f = OutputFile::create(dir, "final_states.csv")?;
    f.line(FINAL_STATES_HEADER)?;
    for r in records {
        let (a0, a1, b0, b1) =
            (r.initial.fragments[0], r.last.fragments[0], r.initial.fragments[1], r.last.fragments[1]);
        let numbers = [
            r.b,
            r.initial.e_trans,
            r.last.e_trans,
            r.delta_e(),
            a0.e_rot,
            a1.e_rot,
            a0.e_vib,
            a1.e_vib,
            a0.l,
            a1.l,
            b0.e_rot,
            b1.e_rot,
            b0.e_vib,
            b1.e_vib,
            b0.l,
            b1.l,
            r.initial.l_orbital,
            r.last.l_orbital,
            r.deflection,
            r.lifetime,
            r.t_end,
            r.r_min,
            r.last.r,
            r.energy_change,
            r.angular_momentum_change,
        ];
        let mut line = format!("{},{},{:.12e},{}", r.index, r.stratum, numbers[0], r.outcome.name());
        for x in &numbers[1..] {
            line.push_str(&format!(",{x:.12e}"));
        }
        f.line(&line)?;
    }
    f.flush()
}

/// Area-weighted histogram of `f` over the inelastic records: each record counts
/// `(A_s/A)/n_s` (`n_s` the completed trajectories of its stratum), so the weights sum to the
/// inelastic probability; the density divides by the bin width.
fn histogram(
    report: &CollisionReport,
    strata_areas: &[f64],
    bins: usize,
    f: impl Fn(&Record) -> f64,
) -> Vec<(f64, f64, f64)> {
    let total: f64 = strata_areas.iter().sum();
    let mut per_stratum = vec![0usize; strata_areas.len()];
    for r in &report.records {
        per_stratum[r.stratum] += 1;
    }
    let xs: Vec<(f64, f64)> = report
        .records
        .iter()
        .filter(|r| r.outcome == Outcome::Inelastic && f(r).is_finite())
        .map(|r| (f(r), strata_areas[r.stratum] / total / per_stratum[r.stratum] as f64))
        .collect();
    if xs.is_empty() {
        return Vec::new();
    }
    let lo = xs.iter().map(|x| x.0).fold(f64::INFINITY, f64::min);
    let mut hi = xs.iter().map(|x| x.0).fold(f64::NEG_INFINITY, f64::max);
    if hi <= lo {
        hi = lo + lo.abs().max(1e-300) * 1e-6 + f64::MIN_POSITIVE;
    }
    let width = (hi - lo) / bins as f64;
    let mut w = vec![0.0; bins];
    for (x, weight) in xs {
        let k = (((x - lo) / width) as usize).min(bins - 1);
        w[k] += weight;
    }
    (0..bins).map(|k| (lo + k as f64 * width, lo + (k + 1) as f64 * width, w[k])).collect()
}

fn write_histograms(dir: &std::path::Path, report: &CollisionReport, c: &CollisionScene) -> Result<(), Error> {
    let areas: Vec<f64> = c.strata.iter().map(|s| s.area()).collect();
    let mut f = OutputFile::create(dir, "collision_histograms.csv")?;
    f.line("quantity,unit,low,high,probability,density")?;
    type Series<'a> = (&'a str, &'a str, &'a dyn Fn(&Record) -> f64);
    let series: [Series<'_>; 5] = [
        ("delta_e", "hartree", &|r: &Record| r.delta_e()),
        ("deflection", "rad", &|r: &Record| r.deflection),
        ("lifetime", "au", &|r: &Record| r.lifetime),
        ("e_rot_a_final", "hartree", &|r: &Record| r.last.fragments[0].e_rot),
        ("e_rot_b_final", "hartree", &|r: &Record| r.last.fragments[1].e_rot),
    ];
    for (name, unit, g) in series {
        for (lo, hi, p) in histogram(report, &areas, c.bins, g) {
            f.line(&format!("{name},{unit},{lo:.12e},{hi:.12e},{p:.12e},{:.12e}", p / (hi - lo)))?;
        }
    }
    f.flush()
}

fn estimate(e: &Estimate, unit: &str) -> serde_json::Value {
    let num = |x: f64| if x.is_finite() { json!(x) } else { serde_json::Value::Null };
    json!({ "value": num(e.value), "standard_error": num(e.error), "unit": unit })
}

#[allow(clippy::too_many_arguments)]
fn write_summary(
    dir: &std::path::Path,
    scene: &Scene,
    ensemble: &EnsembleScene,
    c: &CollisionScene,
    report: &CollisionReport,
    description: &str,
    status: Status,
    wall: f64,
    threads: usize,
) -> Result<(), Error> {
    let s = &report.summary;
    let mut failed = serde_json::Map::new();
    for f in &report.failures {
        let n = failed.get(&f.reason).and_then(serde_json::Value::as_u64).unwrap_or(0);
        failed.insert(f.reason.clone(), json!(n + 1));
    }
    let first: Vec<_> = report
        .failures
        .iter()
        .take(LISTED_FAILURES)
        .map(|f| json!({ "index": f.index, "reason": f.reason, "time_au": f.time, "detail": f.detail }))
        .collect();
    let mut outcomes = serde_json::Map::new();
    let mut sigma = serde_json::Map::new();
    for (k, o) in Outcome::ALL.iter().enumerate() {
        outcomes.insert(o.name().into(), json!(s.counts[k]));
        sigma.insert(o.name().into(), estimate(&s.cross_sections[k], "bohr^2"));
    }
    let strata: Vec<_> = c
        .strata
        .iter()
        .zip(&report.stratum_counts)
        .enumerate()
        .map(|(k, (st, n))| {
            let done = report.records.iter().filter(|r| r.stratum == k).count();
            json!({ "b_bohr": [st.low, st.high], "weight": st.weight, "area_bohr2": st.area(), "trajectories": n, "completed": done })
        })
        .collect();
    let statistics = json!({
        "outcomes": outcomes,
        "cross_sections": sigma,
        "energy_transfer": {
            "over": "inelastic trajectories, each stratum weighted by its area; delta_e = E_trans(final) - E_trans(initial)",
            "mean_delta_e": estimate(&s.delta_e, "hartree"),
            "mean_delta_e_squared": estimate(&s.delta_e2, "hartree^2"),
            "mean_delta_e_rot_a": estimate(&s.fragment_changes[0], "hartree"),
            "mean_delta_e_vib_a": estimate(&s.fragment_changes[1], "hartree"),
            "mean_delta_e_rot_b": estimate(&s.fragment_changes[2], "hartree"),
            "mean_delta_e_vib_b": estimate(&s.fragment_changes[3], "hartree"),
        },
    });
    let interrupted = matches!(status, Status::Interrupted);
    let mut summary = json!({
        "status": status.name(),
        "method": "collision",
        "scene": scene.path,
        "molecule": scene.molecule.get_ref(),
        "sampler": description,
        "seed": ensemble.seed,
        "trajectories": ensemble.trajectories,
        "completed": report.records.len(),
        "interrupted_or_not_run": ensemble.trajectories.saturating_sub((report.records.len() + report.failures.len()) as u64),
        "failed": failed,
        "first_failures": first,
        "r0_bohr": c.r0,
        "r_stop_bohr": c.r_stop,
        "lifetime_radius_bohr": c.lifetime_radius,
        "strata": strata,
        "final": !interrupted,
        "conservation": {
            "max_energy_change_hartree": s.max_energy_change,
            "max_angular_momentum_change_hbar": s.max_angular_momentum_change,
        },
        "wall_time_s": wall,
        "threads": threads,
    });
    // An interrupted run's outcomes, cross sections and energy transfer are over the trajectories
    // that happened to complete, not the scene's ensemble: written apart, as partial.
    let (key, statistics) = if interrupted {
        let mut partial = statistics;
        partial["note"] = json!(
            "interrupted: over the completed trajectories only (final_states.csv), not the scene's ensemble; \
             not final statistics"
        );
        ("partial_statistics", partial)
    } else {
        ("statistics", statistics)
    };
    if let (Some(map), serde_json::Value::Object(stats)) = (summary.as_object_mut(), statistics) {
        if key == "statistics" {
            map.extend(stats);
        } else {
            map.insert(key.into(), serde_json::Value::Object(stats));
        }
    }
    let mut f = OutputFile::create(dir, "summary.json")?;
    f.line(&serde_json::to_string_pretty(&summary).map_err(|e| e.to_string())?)?;
    f.flush()
}

/// Where the files of a collision ensemble go, for the docs' tests.
pub fn files(dir: &std::path::Path) -> [PathBuf; 3] {
    [dir.join("final_states.csv"), dir.join("collision_histograms.csv"), dir.join("summary.json")]
}
