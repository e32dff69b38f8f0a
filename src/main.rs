//! The `dend` command-line tool: a thin layer over the `dend` library.
use std::process::ExitCode;

mod cli;

fn main() -> ExitCode {
    cli::run()
}
