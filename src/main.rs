//! The `rovib` command line, on the `rovib` library. The commands live in [`cli`]; this file
//! only parses arguments and turns an error into one line on stderr and a non-zero exit status.

use std::process::ExitCode;

use clap::Parser;

mod cli;

fn main() -> ExitCode {
    // First, before any code built for the CPU features runs.
    if let Some(e) = rovib::cpu::check() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let cli = cli::Cli::parse();
    match cli::execute(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(rovib::Error::File(e)) => {
            // Already formatted as `error: ...` with its place and help.
            eprintln!("{e}");
            ExitCode::FAILURE
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
