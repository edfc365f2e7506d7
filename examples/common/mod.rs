//! What the cost examples share: this thread's CPU time, which a shared, loaded machine does not
//! inflate the way it inflates wall time.

/// CPU time of this thread, s: the first field of Linux's `/proc/thread-self/schedstat`.
pub fn thread_cpu() -> f64 {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").expect("Linux /proc/thread-self/schedstat");
    text.split_whitespace().next().and_then(|t| t.parse::<f64>().ok()).expect("a number of nanoseconds") * 1e-9
}
