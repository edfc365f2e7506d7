//! The `rovib` command line. The commands live in [`rovib::cli`]; this file only parses
//! arguments and turns an error into one line on stderr and a non-zero exit status.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    // First, before any code built for the CPU features runs.
    if let Some(e) = rovib::cpu::check() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let cli = rovib::cli::Cli::parse();
    match rovib::cli::execute(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(rovib::cli::CliError::File(e)) => {
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
