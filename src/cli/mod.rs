//! Command-line interface: one module per subcommand, dispatched from here.
//!
//! Every failure prints `error: …` on stderr and exits with code 2 (clap's
//! own usage errors exit with 2 as well); the tool never panics on user input.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod curvature;
mod deform;
mod gen;
mod info;
mod loadtest;
mod measure;
mod preset;
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
    /// Write a procedural test shape (bar, cylinder, flag, plane, bumpy-plane, torus, creature, saddle, wavy-sheet, limb).
    Gen(gen::GenArgs),
    /// Print counts, bounding box, topology and the validation result of a mesh file.
    Info(info::InfoArgs),
    /// Per-vertex area, mean, Gaussian curvature and G as CSV (mesh units).
    Curvature(curvature::CurvatureArgs),
    /// Deform a mesh with a constraints file or a survey .sel/.def pair.
    Deform(deform::Args),
    /// Paper-reproduction figures of a pose (twisted bar or bent cylinder) as JSON.
    Measure(measure::Args),
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
        Command::Gen(a) => gen::run(a),
        Command::Info(a) => info::run(a),
        Command::Curvature(a) => curvature::run(&a),
        Command::Deform(a) => deform::run(a),
        Command::Measure(a) => measure::run(a),
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
