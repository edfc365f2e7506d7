//! How far a simulation or an ensemble has come, for a progress callback.

/// Passed to the progress callback of [`crate::simulation::Simulation::run`] (output records)
/// and [`crate::ensemble::run_ensemble_with`] (trajectories), on the calling thread. The callback
/// may set the run's stop flag (for instance when the user asked to stop); the run then ends
/// cleanly at its next output record, or, for an ensemble, when the running trajectories reach
/// their next output time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Progress {
    /// Units of work done: output records written (a simulation) or trajectories finished,
    /// failed or not (an ensemble, including those a resumed run found done).
    pub done: u64,
    /// Units of work in all.
    pub total: u64,
    /// Trajectories that failed so far (always 0 for a simulation).
    pub failed: u64,
}
