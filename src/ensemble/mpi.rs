//! `mpirun -np K rovib ensemble SCENE.toml` (the `mpi` cargo feature): one ensemble over K
//! processes, with the outputs of the single-process run, byte for byte.
//!
//! Every rank reads the scene and builds the same plan and sampler (both are functions of the
//! scene and seed only). Rank 0 coordinates ([`super::schedule::coordinate`]): it hands out the
//! blocks of 64 trajectories in index order, on demand, to its own worker threads one at a time
//! and to the other ranks a batch at a time (twice their thread count), so fast and slow ranks
//! and cheap and costly trajectories balance themselves. A rank runs its batch on its rayon
//! threads and sends the blocks' outcomes (accumulators, counts, failures; JSON with exact
//! floats) back with its next request. Rank 0 records each block in the checkpoint, merges them
//! in block order and alone writes the outputs.
//!
//! Messages (point to point, MPI's `COMM_WORLD`): to rank 0, tag [`TO_ROOT`], a JSON
//! [`ToRoot`]; to a worker, tag [`TO_WORKER`], the block indices of its next batch as `u64`s
//! (none: the run is over, the rank ends). Only each process's main thread calls MPI
//! (`MPI_THREAD_FUNNELED`).
//!
//! Every request carries the rank's run ([`Identity`]: the hash of its scene and states file,
//! seed, N, block size, lane setting and statistics layout). Rank 0 compares it with its own
//! before it accepts any block: a rank started on another scene (an MPMD launch `mpirun -np 1
//! rovib ensemble A.toml : -np 1 rovib ensemble B.toml`) or with other options gets no block,
//! none of its results is merged, and the run fails naming the rank and what differs.
//!
//! A trajectory that panics is caught with its block and reported to rank 0, which hands out no
//! more blocks, waits for the running ones (recorded in the checkpoint), releases every rank and
//! fails with the panic's message. A rank that dies (killed, out of memory, a lost node) cannot
//! be waited for: Open MPI's `mpirun` notices the lost process and ends the whole job; the
//! checkpoint then holds every block rank 0 had received, and `--resume` continues from them.

use std::path::Path;
use std::sync::atomic::AtomicBool;
use std::sync::{Mutex, PoisonError};

use mpi::Threading;
use mpi::topology::SimpleCommunicator;
use mpi::traits::*;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::checkpoint::Identity;
use super::schedule::{BlockResult, Dispatcher, Remote, Work};
use super::{EnsembleOptions, EnsembleReport, Link, Serve, load_scene, run_linked};
use crate::error::Error;

/// Tag of the messages to rank 0.
pub const TO_ROOT: i32 = 1;
/// Tag of the messages to the other ranks.
pub const TO_WORKER: i32 = 2;

/// Environment variables set by the MPI launchers (Open MPI's `mpirun`, MPICH's Hydra, Slurm's
/// `srun --mpi=pmi2` or `--mpi=pmix`): `rovib ensemble` runs as one rank of several when one is
/// set.
pub const LAUNCHER_VARIABLES: [&str; 4] = ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK", "PMI_RANK"];

/// What a rank sends to rank 0.
#[derive(Debug, Serialize, Deserialize)]
pub enum ToRoot {
    /// The outcomes of the last batch (none at first) and a request for `want` more blocks.
    Ready {
        /// The rank's run; rank 0 accepts blocks only of its own.
        identity: Identity,
        /// Blocks wanted.
        want: u64,
        /// The last batch's blocks and their outcomes (or panics).
        results: Vec<(u64, BlockResult)>,
    },
    /// The rank could not start (its scene, states file or sampler failed); it has ended.
    Failed(String),
}

/// Whether this process was started by an MPI launcher.
pub fn launched() -> bool {
    LAUNCHER_VARIABLES.iter().any(|v| std::env::var_os(v).is_some())
}

/// Runs the ensemble of the scene at `path` as one rank of the MPI job: the report on rank 0,
/// `None` on the others.
pub fn run(
    path: &Path,
    options: &EnsembleOptions,
    progress: &mut dyn FnMut(crate::Progress),
) -> Result<Option<EnsembleReport>, Error> {
    let (universe, threading) = mpi::initialize_with_threading(Threading::Funneled)
        .ok_or_else(|| Error::Message("MPI is already initialised in this process".into()))?;
    if threading == Threading::Single {
        return Err(Error::Message(
            "the MPI library gives no thread support (MPI_THREAD_SINGLE); rovib needs MPI_THREAD_FUNNELED".into(),
        ));
    }
    let world = universe.world();
    let ranks = usize::try_from(world.size()).unwrap_or(1);
    if world.rank() == 0 {
        let mut root = Root { world: &world, active: ranks - 1, ranks, expected: None };
        let result = load_scene(path).and_then(|scene| run_linked(&scene, options, Link::Root(&mut root), progress));
        // Whatever happened here, every other rank is told to end before MPI is finalised.
        let released = root.release();
        let report = result?;
        released?;
        Ok(report)
    } else {
        let mut worker = Worker { world: &world, started: false, ranks };
        match load_scene(path).and_then(|scene| run_linked(&scene, options, Link::Worker(&mut worker), &mut |_| {})) {
            Ok(_) => Ok(None),
            // Rank 0 reports it (once, with the rank), and ends the run.
            Err(e) if !worker.started => {
                worker.send(&ToRoot::Failed(e.to_string()));
                Ok(None)
            }
            Err(e) => Err(e),
        }
    }
}

/// Rank 0's side of the other ranks.
struct Root<'w> {
    world: &'w SimpleCommunicator,
    /// Ranks not yet told to end.
    active: usize,
    ranks: usize,
    /// Rank 0's run: a rank whose run differs gets no block and its results are dropped.
    expected: Option<Identity>,
}

impl Root<'_> {
    /// Answers every rank still running with "no more work" (results they still send are
    /// dropped: the run has failed or ended).
    fn release(&mut self) -> Result<(), Error> {
        let mut failure = None;
        while self.active > 0 {
            let (bytes, status) = self.world.any_process().receive_vec_with_tag::<u8>(TO_ROOT);
            let from = status.source_rank();
            match serde_json::from_slice::<ToRoot>(&bytes) {
                Ok(ToRoot::Failed(m)) => {
                    failure.get_or_insert(format!("rank {from} could not start: {m}"));
                }
                _ => self.world.process_at_rank(from).send_with_tag(&[] as &[u64], TO_WORKER),
            }
            self.active -= 1;
        }
        failure.map_or(Ok(()), |m| Err(Error::Message(m)))
    }
}

impl Remote for Root<'_> {
    fn poll(
        &mut self,
        dispatcher: &Mutex<Dispatcher>,
        stop: &AtomicBool,
        sink: &mut dyn FnMut(usize, u64, BlockResult),
    ) -> Result<bool, String> {
        let mut any = false;
        let mut error = None;
        while self.active > 0 {
            let Some(probed) = self.world.any_process().immediate_matched_probe_with_tag(TO_ROOT) else {
                break;
            };
            any = true;
            let (bytes, status) = probed.matched_receive_vec::<u8>();
            let from = status.source_rank();
            let want = match serde_json::from_slice::<ToRoot>(&bytes) {
                Ok(ToRoot::Ready { identity, want, results }) => {
                    let differences = match &self.expected {
                        Some(e) => e.differences(&identity, "rank 0"),
                        None => vec!["rank 0 has not started its run".to_owned()],
                    };
                    if differences.is_empty() {
                        for (b, r) in results {
                            sink(usize::try_from(from).unwrap_or(0), b, r);
                        }
                        want
                    } else {
                        error.get_or_insert(format!(
                            "rank {from} runs another ensemble than rank 0 ({}); none of its blocks was merged. \
                             Start every rank with the same scene file, states file and options",
                            differences.join("; ")
                        ));
                        0
                    }
                }
                Ok(ToRoot::Failed(m)) => {
                    self.active -= 1;
                    error.get_or_insert(format!("rank {from} could not start: {m}"));
                    continue;
                }
                Err(e) => {
                    error.get_or_insert(format!("rank {from} sent a message rank 0 cannot read ({e})"));
                    0
                }
            };
            let blocks = if error.is_some() {
                Vec::new()
            } else {
                dispatcher
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .take(usize::try_from(want).unwrap_or(usize::MAX), stop)
            };
            if blocks.is_empty() {
                self.active -= 1;
            }
            self.world.process_at_rank(from).send_with_tag(&blocks[..], TO_WORKER);
        }
        error.map_or(Ok(any), Err)
    }

    fn finished(&self) -> bool {
        self.active == 0
    }

    fn expect(&mut self, identity: Identity) {
        self.expected = Some(identity);
    }

    fn ranks(&self) -> usize {
        self.ranks
    }
}

/// A rank other than 0.
struct Worker<'w> {
    world: &'w SimpleCommunicator,
    started: bool,
    ranks: usize,
}

impl Worker<'_> {
    fn send(&self, message: &ToRoot) {
        let bytes = serde_json::to_vec(message).expect("outcomes serialise");
        self.world.process_at_rank(0).send_with_tag(&bytes[..], TO_ROOT);
    }
}

impl Serve for Worker<'_> {
    fn serve(&mut self, work: &Work<'_>, identity: &Identity) -> Result<(), Error> {
        self.started = true;
        let want = 2 * work.threads as u64;
        let mut results = Vec::new();
        loop {
            self.send(&ToRoot::Ready { identity: identity.clone(), want, results: std::mem::take(&mut results) });
            let (blocks, _) = self.world.process_at_rank(0).receive_vec_with_tag::<u64>(TO_WORKER);
            if blocks.is_empty() {
                return Ok(());
            }
            results = work.pool.install(|| blocks.par_iter().map(|&b| (b, (work.run)(b))).collect());
        }
    }

    fn ranks(&self) -> usize {
        self.ranks
    }
}
