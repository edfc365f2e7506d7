//! Throughput of one ensemble against MPI ranks and threads per rank on this machine: the
//! single process (`rovib ensemble --threads T`) against `mpirun -np K rovib ensemble --threads
//! T`, every configuration once per round, rounds interleaved (the order rotates each round).
//! For each run: the wall time of the command (MPI start-up included), the CPU time of every
//! process it started (user + system of the waited-for children, so every rank and `mpirun`
//! itself; on a shared machine the honest measure of cost), the wall time of the trajectories
//! alone (summary.json), the blocks each rank ran, and a check that the statistics files are
//! byte-identical to the first configuration's.
//!
//! ```sh
//! cargo build --release --features mpi
//! cargo run --release --features mpi,examples --example mpi_scaling        # or: -- TRAJECTORIES ROUNDS
//! ```
//! Runs `scenes/h2o_ensemble_bench.toml` (water, 10⁴ a.u., DOP853 at 1e-8) with the number of
//! trajectories given (default 4000). `mpirun` runs with `--oversubscribe --bind-to none`
//! (ranks × threads may exceed the cores; no binding, so a rank's threads may use every core)
//! and `--allow-run-as-root`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

/// CPU time (user + system) of this process's waited-for children, s (`/proc/self/stat`
/// cutime + cstime, in clock ticks of 1/100 s, Linux's USER_HZ).
fn children_cpu() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").expect("Linux /proc/self/stat");
    let fields: Vec<&str> = stat.rsplit_once(')').expect("pid (comm) ...").1.split_whitespace().collect();
    // After the command: state is field 3, cutime 16, cstime 17 (1-based, man 5 proc).
    (fields[13].parse::<f64>().unwrap() + fields[14].parse::<f64>().unwrap()) / 100.0
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map_or_else(|_| "?".into(), |t| t.split_whitespace().next().unwrap_or("?").to_owned())
}

/// How a configuration is started: MPI ranks (none: no `mpirun`) and threads per process.
#[derive(Clone, Copy)]
struct Config {
    ranks: Option<usize>,
    threads: usize,
}

impl Config {
    fn label(&self) -> String {
        match self.ranks {
            None => format!("single process, {} thread(s)", self.threads),
            Some(k) => format!("mpirun -np {k}, {} thread(s) each", self.threads),
        }
    }
}

struct Sample {
    wall: f64,
    cpu: f64,
    trajectories_wall: f64,
    blocks_by_rank: String,
}

fn run(rovib: &Path, scene: &Path, out: &Path, c: Config, reference: Option<&Path>) -> Sample {
    let _ = std::fs::remove_dir_all(out);
    let mut cmd = match c.ranks {
        None => Command::new(rovib),
        Some(k) => {
            let mut m = Command::new("mpirun");
            m.args(["--oversubscribe", "--bind-to", "none", "--allow-run-as-root", "-np", &k.to_string()]).arg(rovib);
            m
        }
    };
    cmd.arg("ensemble")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .args(["--quiet", "--threads", &c.threads.to_string()])
        .stdin(Stdio::null())
        .stdout(Stdio::null());
    let (cpu0, begin) = (children_cpu(), Instant::now());
    let o = cmd.output().expect("the command runs (mpirun: apt-get install openmpi-bin)");
    let (wall, cpu) = (begin.elapsed().as_secs_f64(), children_cpu() - cpu0);
    assert!(o.status.success(), "{}: {}", c.label(), String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let ranks = summary["ranks"].as_u64().unwrap();
    assert_eq!(ranks, c.ranks.unwrap_or(1) as u64, "{}: built without --features mpi?", c.label());
    if let Some(r) = reference {
        for f in ["ensemble.csv", "histograms.csv", "correlations.csv"] {
            let same = std::fs::read(r.join(f)).ok() == std::fs::read(out.join(f)).ok();
            assert!(same, "{f} of {} differs from the first configuration's", c.label());
        }
    }
    Sample {
        wall,
        cpu,
        trajectories_wall: summary["wall_time_s"].as_f64().unwrap_or(f64::NAN),
        blocks_by_rank: summary["blocks_by_rank"].to_string(),
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let n: u64 = args.next().map_or(4000, |a| a.parse().expect("TRAJECTORIES: a number"));
    let rounds: usize = args.next().map_or(3, |a| a.parse().expect("ROUNDS: a number"));
    let exe = std::env::current_exe().unwrap();
    // target/release/examples/mpi_scaling → target/release/rovib
    let rovib = exe.parent().and_then(Path::parent).unwrap().join("rovib");
    assert!(rovib.exists(), "build it first: cargo build --release --features mpi");
    let dir: PathBuf = std::env::temp_dir().join(format!("rovib-mpi-scaling-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string("scenes/h2o_ensemble_bench.toml").expect("run from the repository's root");
    let text: String = text
        .lines()
        .map(|l| if l.trim_start().starts_with("trajectories") { format!("trajectories = {n}") } else { l.into() })
        .collect::<Vec<_>>()
        .join("\n");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, text).unwrap();

    let configs = [
        Config { ranks: None, threads: 1 },
        Config { ranks: None, threads: 2 },
        Config { ranks: Some(1), threads: 1 },
        Config { ranks: Some(1), threads: 2 },
        Config { ranks: Some(2), threads: 1 },
        Config { ranks: Some(2), threads: 2 },
        Config { ranks: Some(4), threads: 1 },
    ];
    let mut samples: Vec<Vec<Sample>> = configs.iter().map(|_| Vec::new()).collect();
    let reference = dir.join("reference");
    println!(
        "{n} trajectories, {rounds} rounds; {} cores",
        std::thread::available_parallelism().map_or(0, |c| c.get())
    );
    for round in 0..rounds {
        let before = load();
        for i in 0..configs.len() {
            let k = (i + round) % configs.len();
            let out = dir.join(format!("c{k}"));
            let first = round == 0 && i == 0;
            let s = run(&rovib, &scene, &out, configs[k], (!first).then_some(reference.as_path()));
            if first {
                let _ = std::fs::remove_dir_all(&reference);
                std::fs::rename(&out, &reference).unwrap();
            }
            samples[k].push(s);
        }
        println!("round {round}: load average (1 min) before {before}, after {}", load());
    }
    println!();
    println!(
        "| configuration | wall time (s), each round | CPU time (s), each round | CPU per trajectory (ms), best | \
         trajectories/s (best wall) | trajectories/CPU-s (best) | CPU relative to 1 process × 1 thread | blocks by rank (last round) |"
    );
    println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |");
    let best_cpu = |s: &[Sample]| s.iter().map(|x| x.cpu).fold(f64::INFINITY, f64::min);
    let base = best_cpu(&samples[0]);
    for (c, s) in configs.iter().zip(&samples) {
        let walls: Vec<String> = s.iter().map(|x| format!("{:.2}", x.wall)).collect();
        let cpus: Vec<String> = s.iter().map(|x| format!("{:.2}", x.cpu)).collect();
        let best_wall = s.iter().map(|x| x.wall).fold(f64::INFINITY, f64::min);
        let cpu = best_cpu(s);
        println!(
            "| {} | {} | {} | {:.3} | {:.0} | {:.0} | {:.3} | {} |",
            c.label(),
            walls.join(" / "),
            cpus.join(" / "),
            cpu / n as f64 * 1e3,
            n as f64 / best_wall,
            n as f64 / cpu,
            cpu / base,
            s.last().map_or(String::new(), |x| x.blocks_by_rank.clone()),
        );
    }
    println!();
    println!("wall time of the trajectories alone (summary.json), s, each round:");
    for (c, s) in configs.iter().zip(&samples) {
        let t: Vec<String> = s.iter().map(|x| format!("{:.2}", x.trajectories_wall)).collect();
        println!("  {}: {}", c.label(), t.join(" / "));
    }
    let _ = std::fs::remove_dir_all(&dir);
}
