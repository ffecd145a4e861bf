//! `dflat` — discrete-flatness MPC flight-control daemon for multirotors.
//!
//! One binary, several subcommands: `daemon`, `sitl`, `demo`, `experiment`,
//! `check-config`. See the README for each.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// Discrete-flatness MPC flight control for multirotors (MAVLink).
#[derive(Debug, Parser)]
#[command(name = "dflat", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Validate a configuration file and print the effective configuration.
    CheckConfig {
        /// The TOML file.
        file: PathBuf,
    },
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::CheckConfig { file } => {
            let cfg = dflat_daemon::config::Config::load(&file)?;
            print!("{}", cfg.to_toml());
            Ok(())
        }
    }
}
