//! Command-line interface: one module per subcommand, dispatched from here.
//!
//! Every failure prints `error: …` on stderr and exits with code 2 (clap's
//! own usage errors exit with 2 as well); the tool never panics on user input.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod loadtest;
mod serve;

/// Deform triangle meshes with Discrete Elastica Nonlinear Deformation.
#[derive(Debug, Parser)]
#[command(name = "dend", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the deformation server (HTTP + WebSocket; prints its URL).
    Serve(serve::ServeArgs),
    /// Drive N server sessions with M drags each; report drag→frame latency.
    Loadtest(loadtest::LoadtestArgs),
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
    let result: anyhow::Result<()> = match cli.command {
        Command::Serve(a) => serve::run(a),
        Command::Loadtest(a) => loadtest::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
