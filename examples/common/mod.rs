//! What the cost examples share: this thread's CPU time, which a shared, loaded machine does not
//! inflate the way it inflates wall time.

use nix::time::{ClockId, clock_gettime};

/// CPU time of this thread, s (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`: exact to the
/// nanosecond at every call, unlike `/proc/thread-self/schedstat`, which the kernel brings up to
/// date only at its ticks and so reads 0 for a window shorter than one).
pub fn thread_cpu() -> f64 {
    let t = clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID).expect("thread CPU clock");
    t.tv_sec() as f64 + t.tv_nsec() as f64 * 1e-9
}
