//! Ctrl-C (SIGINT) and SIGTERM (and SIGHUP, through `ctrlc`'s `termination` feature): one
//! process-wide flag that long commands poll to stop cleanly, keeping consistent outputs for the
//! work that finished. Installed once; shared by every command.

use std::sync::atomic::AtomicBool;
use std::sync::{Arc, OnceLock};

static FLAG: OnceLock<Arc<AtomicBool>> = OnceLock::new();

/// The flag, set when the user presses Ctrl-C or the process receives SIGTERM. The first call installs the handler; if it
/// cannot be installed (another handler is already set), the flag simply never fires.
pub fn flag() -> Arc<AtomicBool> {
    FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let f = Arc::clone(&flag);
        // A second signal while stopping still ends the process the usual way.
        let _ = ctrlc::set_handler(move || {
            if f.swap(true, std::sync::atomic::Ordering::SeqCst) {
                std::process::exit(130);
            }
        });
        flag
    })
    .clone()
}
