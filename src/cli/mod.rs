//! Command-line interface: one module per subcommand, dispatched from here.
//!
//! Every failure prints `error: …` on stderr and exits with code 2 (clap's
//! own usage errors exit with 2 as well); the tool never panics on user input.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod curvature;

/// Deform triangle meshes with Discrete Elastica Nonlinear Deformation.
#[derive(Debug, Parser)]
#[command(name = "dend", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Per-vertex area, mean, Gaussian curvature and G as CSV (mesh units).
    Curvature(curvature::CurvatureArgs),
}

/// Parses the command line, runs the command, maps errors to exit code 2.
pub fn run() -> ExitCode {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let result: anyhow::Result<()> = match &cli.command {
        Command::Curvature(args) => curvature::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
