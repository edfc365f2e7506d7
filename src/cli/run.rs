//! `rovib run SCENE.toml` and `rovib run --resume DIR`: one [`Simulation`], with a progress bar
//! on a terminal and Ctrl-C as its stop flag.

use std::io::IsTerminal as _;

use rovib::{Error, RunReport, Simulation};

use super::interrupt;
use super::progress::Bar;

/// Runs `sim`; prints the scene's warnings on stderr unless `quiet`.
pub fn run(sim: Simulation, quiet: bool) -> Result<RunReport, Error> {
    let mut bar = Bar::new(!quiet && std::io::stderr().is_terminal(), "outputs", false);
    let report = sim.run(&interrupt::flag(), &mut |p| bar.update(p));
    drop(bar);
    let report = report?;
    for w in &report.warnings {
        eprintln!("warning: {w}");
    }
    Ok(report)
}
