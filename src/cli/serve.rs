//! `dend serve`: run the deformation server.

use dend_server::{self as server, Config};

/// Arguments of `dend serve`: the server [`Config`] (every flag also reads
/// a `DEND_*` environment variable).
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    #[command(flatten)]
    config: Config,
}

/// Runs the server until SIGINT/SIGTERM.
pub fn run(args: ServeArgs) -> anyhow::Result<()> {
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(server::serve(args.config))
}
