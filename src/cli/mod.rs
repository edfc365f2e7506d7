//! The `rovib` commands: `list`, `eval`, `run`.
//!
//! Each command is generic over the molecule: [`crate::molecules::visit`] calls it with the
//! generated type, so it runs on fixed-size, monomorphised code.

use std::fmt;
use std::path::PathBuf;

use clap::{Parser, Subcommand};

mod eval;
mod list;

/// Classical rotation-vibration dynamics of polyatomic molecules.
#[derive(Debug, Parser)]
#[command(name = "rovib", version, about, long_about = None)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// A `rovib` subcommand.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// List the compiled-in molecules with their atoms and internal coordinates.
    List,
    /// Evaluate H, the kinetic and G matrices and Hamilton's equations at one state; print JSON.
    Eval {
        /// The molecule's name, as in `rovib list`.
        #[arg(long)]
        molecule: String,
        /// A JSON state `{"q": [...], "p": [...], "euler": [phi, theta, psi], "pe": [...]}` in
        /// atomic units; `-` reads standard input. Without it: the reference geometry at rest,
        /// with euler = [0, pi/2, 0].
        #[arg(long)]
        state: Option<PathBuf>,
    },
}

/// A command's failure: one line for the user.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CliError(pub String);

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // One line, whatever the cause contained.
        f.write_str(&self.0.replace('\n', " "))
    }
}

impl std::error::Error for CliError {}

impl CliError {
    /// An error from anything displayable, prefixed with context.
    pub fn context(context: impl fmt::Display, e: impl fmt::Display) -> Self {
        CliError(format!("{context}: {e}"))
    }
}

/// Runs one command.
pub fn execute(cli: Cli) -> Result<(), CliError> {
    match cli.command {
        Command::List => {
            print!("{}", list::list());
            Ok(())
        }
        Command::Eval { molecule, state } => {
            let json = eval::eval(&molecule, state.as_deref())?;
            println!("{json}");
            Ok(())
        }
    }
}

/// The error for a molecule name that is not compiled in.
pub(crate) fn unknown_molecule(name: &str) -> CliError {
    CliError(format!(
        "unknown molecule `{name}`; the compiled-in molecules are {} (add molecules/{name}.toml and rebuild to add it)",
        crate::molecules::NAMES.join(", ")
    ))
}
