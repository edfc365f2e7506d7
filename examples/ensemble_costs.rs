//! What an ensemble costs besides its trajectories, per block of 64: the message a rank sends to
//! rank 0 (bytes, and the CPU time to write and read it), the merge of a block into the running
//! total, the checkpoint line (bytes, CPU and wall time of the write and `fsync`) and a
//! compaction of the checkpoint. Everything rank 0 does per block alone, while the other ranks
//! compute: the serial part of an MPI run (docs/src/history/benchmarks.md, "Ensembles over MPI").
//!
//! Each scene is run once for 64 trajectories on one thread (the block whose outcome is then
//! shipped, merged and recorded; its process CPU time is the compute cost of a block), then the
//! operations run in interleaved rounds, timed with this thread's CPU time (the machine is
//! shared; each operation repeated for 0.1 s of CPU, since the accounting advances in
//! scheduler ticks) and, for the checkpoint's writes, wall time (the `fsync` waits for the disk). The checkpoint goes into `DIR`
//! (default: the system's temporary folder).
//!
//! ```sh
//! cargo run --release --features mpi,examples --example ensemble_costs            # or: -- ROUNDS DIR
//! ```
//! Without `--features mpi` the message is the same JSON without its 30-byte envelope.

mod common;
use common::thread_cpu;

use std::collections::BTreeMap;
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

use rovib::ensemble::checkpoint::{Checkpoint, Header};
use rovib::ensemble::runner::{BLOCK, Outcome};
use rovib::ensemble::schedule::BlockResult;
use rovib::ensemble::{EnsembleOptions, run_ensemble};
use rovib::scene::parse_scene;

/// CPU time of this process, all threads, s (`/proc/self/stat` utime + stime, in clock ticks of
/// 1/100 s, Linux's USER_HZ).
fn process_cpu() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").expect("Linux /proc/self/stat");
    let fields: Vec<&str> = stat.rsplit_once(')').expect("pid (comm) ...").1.split_whitespace().collect();
    // After the command: state is field 3, utime 14, stime 15 (1-based, man 5 proc).
    (fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap()) / 100.0
}

/// The message a rank sends to rank 0 with `results` (exactly what src/ensemble/mpi.rs sends).
#[cfg(feature = "mpi")]
fn message(results: Vec<(u64, BlockResult)>) -> Vec<u8> {
    use rovib::ensemble::checkpoint::{Identity, Layout};
    let statistics = &results[0].1.as_ref().expect("a block's outcome").statistics;
    let identity = Identity { header: Header::new(b"costs", 1, 1 << 20, BLOCK), layout: Layout::of(statistics) };
    serde_json::to_vec(&rovib::ensemble::mpi::ToRoot::Ready { identity, want: 2, results }).unwrap()
}

#[cfg(feature = "mpi")]
fn read_message(bytes: &[u8]) -> usize {
    match serde_json::from_slice::<rovib::ensemble::mpi::ToRoot>(bytes).unwrap() {
        rovib::ensemble::mpi::ToRoot::Ready { results, .. } => results.len(),
        rovib::ensemble::mpi::ToRoot::Failed(_) => 0,
    }
}

#[cfg(not(feature = "mpi"))]
fn message(results: Vec<(u64, BlockResult)>) -> Vec<u8> {
    serde_json::to_vec(&results).unwrap()
}

#[cfg(not(feature = "mpi"))]
fn read_message(bytes: &[u8]) -> usize {
    serde_json::from_slice::<Vec<(u64, BlockResult)>>(bytes).unwrap().len()
}

/// The scene at `path` with 64 trajectories: one block.
fn one_block(path: &str, out: &Path) -> (Outcome, f64) {
    let text = std::fs::read_to_string(path).unwrap();
    let text: String = text
        .lines()
        .map(|l| if l.trim_start().starts_with("trajectories") { format!("trajectories = {BLOCK}") } else { l.into() })
        .collect::<Vec<_>>()
        .join("\n");
    let scene = parse_scene(path, &text).unwrap();
    let mut options = EnsembleOptions::new(out);
    options.threads = Some(1);
    options.checkpoint = false;
    let begin = process_cpu();
    let report = run_ensemble(&scene, &options).unwrap();
    let cpu = process_cpu() - begin;
    assert_eq!(report.outcome.completed + report.outcome.failed_count(), BLOCK);
    (report.outcome, cpu)
}

/// CPU time of one call of `op`, s: calls repeated until this thread has spent 0.1 s (the
/// scheduler's CPU accounting advances in ticks of a few milliseconds).
fn per_op(mut op: impl FnMut()) -> f64 {
    let begin = thread_cpu();
    let mut calls = 0_u64;
    loop {
        op();
        calls += 1;
        let spent = thread_cpu() - begin;
        if spent >= 0.1 {
            return spent / calls as f64;
        }
    }
}

/// Best and median of a list of per-operation times.
fn best_median(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    (v[0], v[v.len() / 2])
}

fn us(x: f64) -> String {
    format!("{:.1}", x * 1e6)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let rounds: usize = args.next().map_or(5, |a| a.parse().expect("ROUNDS: a number"));
    let dir: PathBuf = args.next().map_or_else(std::env::temp_dir, PathBuf::from).join("rovib-ensemble-costs");
    std::fs::create_dir_all(&dir).unwrap();
    println!("rounds {rounds}, checkpoint in {}, load average {}", dir.display(), load());
    println!(
        "| scene | block compute CPU (ms) | message to rank 0 (bytes) | serialise CPU (µs) | parse CPU (µs) | \
         merge CPU (µs) | checkpoint line (bytes) | line serialise CPU (µs) | append wall, write + fsync (ms) | compaction wall (ms), 0 / 8 \
         blocks pending |"
    );
    println!("| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |");
    for scene in ["scenes/h2o_thermal.toml", "scenes/h2o_ensemble_bench.toml"] {
        let (block, compute) = one_block(scene, &dir.join("run"));
        let bytes = message(vec![(0, Ok(block.clone()))]);
        assert_eq!(read_message(&bytes), 1);
        let header = Header::new(b"costs", 1, 1 << 20, BLOCK);
        let path = dir.join("checkpoint.jsonl");
        let mut checkpoint = Checkpoint::create(&path, &header).unwrap();
        let before = std::fs::metadata(&path).unwrap().len();
        checkpoint.append(0, &block).unwrap();
        let line = std::fs::metadata(&path).unwrap().len() - before;
        let mut total = block.clone();
        let pending: BTreeMap<u64, Outcome> = (10..18).map(|b| (b, block.clone())).collect();
        let (mut ser, mut parse, mut merge, mut line_cpu, mut append_wall, mut compact0, mut compact8) =
            (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
        for round in 0..rounds {
            // Interleaved: every operation once per round, in a fixed order.
            ser.push(per_op(|| {
                black_box(message(vec![(0, Ok(block.clone()))]));
            }));
            parse.push(per_op(|| {
                black_box(read_message(black_box(&bytes)));
            }));
            merge.push(per_op(|| total.merge(black_box(&block)).expect("one layout")));
            line_cpu.push(per_op(|| {
                black_box(serde_json::to_vec(black_box(&block)).unwrap());
            }));
            let k = 10;
            let w = Instant::now();
            for b in 0..k {
                checkpoint.append(1 + (round * k + b) as u64, &block).unwrap();
            }
            append_wall.push(w.elapsed().as_secs_f64() / k as f64);
            let w = Instant::now();
            checkpoint.compact(&header, 1, &block, &BTreeMap::new()).unwrap();
            compact0.push(w.elapsed().as_secs_f64());
            let w = Instant::now();
            checkpoint.compact(&header, 1, &block, &pending).unwrap();
            compact8.push(w.elapsed().as_secs_f64());
        }
        black_box(&total);
        let (s, p, mg, ac, aw, c0, c8) = (
            best_median(ser),
            best_median(parse),
            best_median(merge),
            best_median(line_cpu),
            best_median(append_wall),
            best_median(compact0),
            best_median(compact8),
        );
        println!(
            "| {scene} | {:.0} | {} | {} / {} | {} / {} | {} / {} | {line} | {} / {} | {:.2} / {:.2} | {:.2} / {:.2} |",
            compute * 1e3,
            bytes.len(),
            us(s.0),
            us(s.1),
            us(p.0),
            us(p.1),
            us(mg.0),
            us(mg.1),
            us(ac.0),
            us(ac.1),
            aw.0 * 1e3,
            aw.1 * 1e3,
            c0.1 * 1e3,
            c8.1 * 1e3,
        );
        let _ = std::fs::remove_file(&path);
    }
    println!("(best / median of {rounds} rounds; compaction: median; load average after: {})", load());
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map_or_else(|_| "?".into(), |t| t.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
}
