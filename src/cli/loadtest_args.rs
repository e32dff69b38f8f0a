//! The command line of `dend loadtest`: its arguments, the stream modes
//! a client takes frames in, and the sessions' parameters.

use std::path::PathBuf;

use clap::ValueEnum;
use dend_client::ws::StreamOptions;
use dend_client::{FrameEncoding, SessionParams};

use super::drive::DragPath;
use crate::cli::preset::PresetArg;

/// How a loadtest client takes its frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum StreamMode {
    /// A version 2 client: no flow control, f32 frames (before protocol 3).
    Legacy,
    /// One frame in flight, acknowledged; version 3 f32 frames.
    F32,
    /// One frame in flight, acknowledged; version 3 q16 frames.
    Q16,
    /// One frame in flight, acknowledged; version 3 delta frames (what the
    /// editor uses).
    Delta,
}

impl StreamMode {
    pub(super) fn options(self) -> StreamOptions {
        match self {
            StreamMode::Legacy => StreamOptions::default(),
            StreamMode::F32 => StreamOptions::flow(1, FrameEncoding::F32),
            StreamMode::Q16 => StreamOptions::flow(1, FrameEncoding::Q16),
            StreamMode::Delta => StreamOptions::flow(1, FrameEncoding::Delta),
        }
    }
    pub(super) fn name(self) -> &'static str {
        match self {
            StreamMode::Legacy => "legacy",
            StreamMode::F32 => "f32",
            StreamMode::Q16 => "q16",
            StreamMode::Delta => "delta",
        }
    }
}

/// Arguments of `dend loadtest`.
#[derive(Debug, clap::Args)]
pub struct LoadtestArgs {
    /// Concurrent sessions.
    #[arg(long, default_value_t = 1)]
    pub(super) sessions: usize,
    /// Drags per session.
    #[arg(long, default_value_t = 200)]
    pub(super) drags: u64,
    /// Gestures per session, each of `--drags` drags and its settle: along
    /// the path, back, along again, in turn (a person's later gestures
    /// with the same constraint set). The report is the last gesture's,
    /// with a line of every gesture's settle.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    pub(super) gestures: u64,
    /// Mesh file (OBJ/OFF/PLY/STL); default: a generated 100×100 grid.
    #[arg(long)]
    pub(super) mesh: Option<PathBuf>,
    /// Server base URL; default: start a server in this process.
    #[arg(long)]
    pub(super) url: Option<String>,
    /// Iterations per frame of the in-process server.
    #[arg(long, default_value_t = 1)]
    pub(super) iters_per_frame: usize,
    /// The in-process server's `--preview-above-ms`: drags are answered by
    /// coarse previews while a fine iteration takes longer (0 always, a
    /// negative value never).
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    pub(super) preview_above_ms: f64,
    /// The clients declare this frame rate cap (`max_fps`). Default: none.
    #[arg(long)]
    pub(super) max_fps: Option<u32>,
    /// The clients declare this cap on refinement frames (`refine_fps`);
    /// 0: none. The default is the web editor's.
    #[arg(long, default_value_t = 30)]
    pub(super) refine_fps: u32,
    /// Side of the generated grid mesh (vertices per side) when no `--mesh`.
    #[arg(long, default_value_t = 100)]
    pub(super) grid: usize,
    /// The in-process server stores in this directory (SQLite, fsynced
    /// journal) instead of memory.
    #[arg(long)]
    pub(super) data_dir: Option<PathBuf>,
    /// Factor cache budget of the in-process server, bytes.
    #[arg(long, default_value_t = 2 << 30)]
    pub(super) factor_cache_bytes: usize,
    /// After the drag phase, open this many sessions with distinct
    /// constraints and leave them idle; report the factor cache against its
    /// budget, then check each one still answers its pose and a drag.
    #[arg(long, default_value_t = 0)]
    pub(super) idle: usize,
    /// The drag sessions' parameter preset, sent as `{"preset": NAME}`
    /// (characters is the server's default; elastica the paper's even
    /// bend and twist).
    #[arg(long, visible_alias = "weights", value_enum, default_value_t = PresetArg::Characters)]
    pub(super) preset: PresetArg,
    /// Solver worker threads of the in-process server (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub(super) solver_threads: usize,
    /// Admission limit of the in-process server (sessions waiting for a
    /// solver; 0: the server's default, 16 per solver thread).
    #[arg(long, default_value_t = 0)]
    pub(super) admission_waiting_sessions: usize,
    /// Once a fifth of the drags are done, try to open this many more
    /// sessions, one every 50 ms, and report how many the server refused
    /// with 503 `overloaded` (admission control).
    #[arg(long, default_value_t = 0)]
    pub(super) extra_sessions: usize,
    /// Fail (exit status 1) when the drag→frame maximum exceeds this, ms.
    #[arg(long)]
    pub(super) check_max_ms: Option<f64>,
    /// Fail when the drag→frame p99 exceeds this, ms.
    #[arg(long)]
    pub(super) check_p99_ms: Option<f64>,
    /// Fail when a session's median drag→frame latency exceeds this many
    /// times the overall median (fairness between sessions).
    #[arg(long)]
    pub(super) check_fairness: Option<f64>,
    /// Fail unless at least this many of the `--extra-sessions` were
    /// refused with 503 `overloaded`.
    #[arg(long)]
    pub(super) check_refused: Option<usize>,
    /// The handle's path: `line`, or `arc` (the handle swings 60° about
    /// the fixed end and turns with it).
    #[arg(long, default_value_t = DragPath::Line)]
    pub(super) path: DragPath,
    /// Drags per second on a clock (a mouse); 0: closed loop, the next
    /// drag when a frame acknowledges the last.
    #[arg(long, default_value_t = 0.0)]
    pub(super) drag_hz: f64,
    /// Milliseconds the client spends on each frame (a slow client).
    #[arg(long, default_value_t = 0)]
    pub(super) slow_ms: u64,
    /// Stream modes to run, one after the other on the same mesh
    /// (comma-separated): legacy (version 2 client), f32, q16, delta
    /// (the editor's).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "delta")]
    pub(super) stream: Vec<StreamMode>,
    /// Write every drag's drag→frame latency to this CSV file (`mode,
    /// session, drag, latency_ms`, in the order each session sent them):
    /// which drags make the tail.
    #[arg(long)]
    pub(super) latencies: Option<std::path::PathBuf>,
}

impl LoadtestArgs {
    /// The `refine_fps` the clients declare (`--refine-fps 0`: none).
    pub(super) fn declared_refine_fps(&self) -> Option<u32> {
        Some(self.refine_fps).filter(|f| *f > 0)
    }
}

/// The `params` object of the drag sessions: the preset by name, as the
/// web editor sends it.
pub(super) fn session_params(preset: PresetArg) -> SessionParams {
    SessionParams::preset(preset.preset().name())
}

#[cfg(test)]
mod tests {
    use super::{session_params, PresetArg};
    use dend::deform::{Params, Preset};

    /// The server reads a session's `params` with serde into `Params`: the
    /// objects the loadtest sends must read back as the presets they name,
    /// the default preset as `Params::default()`.
    #[test]
    fn session_params_read_back_as_the_named_presets() {
        let read = |p: PresetArg| -> Params {
            let wire = serde_json::to_value(session_params(p)).expect("write");
            serde_json::from_value(wire).expect("parse")
        };
        assert_eq!(read(PresetArg::Characters), Params::default());
        assert_eq!(read(PresetArg::Elastica), Preset::Elastica.params());
        assert_ne!(read(PresetArg::Characters), read(PresetArg::Elastica));
    }
}
