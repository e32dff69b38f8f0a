//! `dend loadtest`: drive N sessions with M WebSocket drags each and report
//! per stream mode: frames/s while dragging, drag→frame latency (p50/p99),
//! settle time and iterations, converged, the level of the frames and the
//! bytes/s to each client.
//!
//! By default each session is closed-loop: send drag `seq`, wait for the
//! first frame acknowledging it, send the next; `--drag-hz` sends drags on a
//! clock instead (a mouse), `--slow-ms` makes the client spend that long on
//! each frame (a slow browser). `--stream legacy,q16` runs the same drags
//! once per stream mode, in one run: `legacy` is a version 2 client (no flow
//! control, f32 frames), `f32`/`q16` declare a window of one frame and take
//! version 3 frames in that encoding. Without `--url` the command starts a
//! server in-process on a free port.

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::ValueEnum;
use dend_client::constraints::BoxSel;
use dend_client::ws::{DeltaJson, StreamOptions};
use dend_client::{
    Client, ConstraintsSpec, FrameEncoding, HandleSpec, MeshInfo, SessionParams, VertexSet,
};
use dend_server::{self as server, AppState, Config};

use super::preset::PresetArg;
use drive::{median, DragPath, Pace, Path, Summary};

#[path = "loadtest_drive.rs"]
mod drive;

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
    fn options(self) -> StreamOptions {
        match self {
            StreamMode::Legacy => StreamOptions::default(),
            StreamMode::F32 => StreamOptions::flow(1, FrameEncoding::F32),
            StreamMode::Q16 => StreamOptions::flow(1, FrameEncoding::Q16),
            StreamMode::Delta => StreamOptions::flow(1, FrameEncoding::Delta),
        }
    }
    fn name(self) -> &'static str {
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
    sessions: usize,
    /// Drags per session.
    #[arg(long, default_value_t = 200)]
    drags: u64,
    /// Mesh file (OBJ/OFF/PLY/STL); default: a generated 100×100 grid.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Server base URL; default: start a server in this process.
    #[arg(long)]
    url: Option<String>,
    /// Iterations per frame of the in-process server.
    #[arg(long, default_value_t = 1)]
    iters_per_frame: usize,
    /// The in-process server's `--preview-above-ms`: drags are answered by
    /// coarse previews while a fine iteration takes longer (0 always, a
    /// negative value never).
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true)]
    preview_above_ms: f64,
    /// The clients declare this frame rate cap (`max_fps`). Default: none.
    #[arg(long)]
    max_fps: Option<u32>,
    /// The clients declare this cap on refinement frames (`refine_fps`);
    /// 0: none. The default is the web editor's.
    #[arg(long, default_value_t = 30)]
    refine_fps: u32,
    /// Side of the generated grid mesh (vertices per side) when no `--mesh`.
    #[arg(long, default_value_t = 100)]
    grid: usize,
    /// The in-process server stores in this directory (SQLite, fsynced
    /// journal) instead of memory.
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Factor cache budget of the in-process server, bytes.
    #[arg(long, default_value_t = 2 << 30)]
    factor_cache_bytes: usize,
    /// After the drag phase, open this many sessions with distinct
    /// constraints and leave them idle; report the factor cache against its
    /// budget, then check each one still answers its pose and a drag.
    #[arg(long, default_value_t = 0)]
    idle: usize,
    /// The drag sessions' parameter preset, sent as `{"preset": NAME}`
    /// (characters is the server's default; elastica the paper's even
    /// bend and twist).
    #[arg(long, visible_alias = "weights", value_enum, default_value_t = PresetArg::Characters)]
    preset: PresetArg,
    /// Solver worker threads of the in-process server (0: one per core).
    #[arg(long, default_value_t = 0)]
    solver_threads: usize,
    /// Admission limit of the in-process server (sessions waiting for a
    /// solver; 0: the server's default, 16 per solver thread).
    #[arg(long, default_value_t = 0)]
    admission_waiting_sessions: usize,
    /// Once a fifth of the drags are done, try to open this many more
    /// sessions, one every 50 ms, and report how many the server refused
    /// with 503 `overloaded` (admission control).
    #[arg(long, default_value_t = 0)]
    extra_sessions: usize,
    /// Fail (exit status 1) when the drag→frame maximum exceeds this, ms.
    #[arg(long)]
    check_max_ms: Option<f64>,
    /// Fail when the drag→frame p99 exceeds this, ms.
    #[arg(long)]
    check_p99_ms: Option<f64>,
    /// Fail when a session's median drag→frame latency exceeds this many
    /// times the overall median (fairness between sessions).
    #[arg(long)]
    check_fairness: Option<f64>,
    /// Fail unless at least this many of the `--extra-sessions` were
    /// refused with 503 `overloaded`.
    #[arg(long)]
    check_refused: Option<usize>,
    /// The handle's path: a line, or an arc while the handle turns.
    #[arg(long, value_enum, default_value_t = DragPath::Line)]
    path: DragPath,
    /// Drags per second on a clock (a mouse); 0: closed loop, the next
    /// drag when a frame acknowledges the last.
    #[arg(long, default_value_t = 0.0)]
    drag_hz: f64,
    /// Milliseconds the client spends on each frame (a slow client).
    #[arg(long, default_value_t = 0)]
    slow_ms: u64,
    /// Stream modes to run, one after the other on the same mesh
    /// (comma-separated): legacy (version 2 client), f32, q16, delta
    /// (the editor's).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "delta")]
    stream: Vec<StreamMode>,
    /// Write every drag's drag→frame latency to this CSV file (`mode,
    /// session, drag, latency_ms`, in the order each session sent them):
    /// which drags make the tail.
    #[arg(long)]
    latencies: Option<std::path::PathBuf>,
}

/// The `params` object of the drag sessions: the preset by name, as the
/// web editor sends it.
fn session_params(preset: PresetArg) -> SessionParams {
    SessionParams::preset(preset.preset().name())
}

/// Constraints fixing the box `fixed` and dragging the box `handle` (named
/// `h`), each `[min, max]`.
fn box_constraints(fixed: [[f64; 3]; 2], handle: [[f64; 3]; 2]) -> ConstraintsSpec {
    let boxed = |[min, max]: [[f64; 3]; 2]| VertexSet::Box {
        bbox: BoxSel { min, max },
    };
    ConstraintsSpec::new(boxed(fixed), vec![HandleSpec::named("h", boxed(handle))])
}

/// Runs the load test and prints its report.
pub fn run(args: LoadtestArgs) -> anyhow::Result<()> {
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(run_async(args))
}

fn grid(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut p = vec![];
    for j in 0..n {
        for i in 0..n {
            p.push([i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64, 0.0]);
        }
    }
    let mut t = vec![];
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
            t.extend([[a, b, d], [a, d, c]]);
        }
    }
    (p, t)
}

async fn run_async(args: LoadtestArgs) -> anyhow::Result<()> {
    let base = match &args.url {
        Some(u) => u.clone(),
        None => in_process_server(&args).await?,
    };
    let client = Client::new(&base);
    let uploaded = Instant::now();
    let mesh = upload(&client, &args).await?;
    let upload = uploaded.elapsed();
    let [lo, hi] = mesh.bbox;
    let ext: Vec<f64> = (0..3).map(|k| hi[k] - lo[k]).collect();
    let k = (0..3)
        .max_by(|a, b| ext[*a].total_cmp(&ext[*b]))
        .unwrap_or(0);
    let (mut fixed_max, mut handle_min) = (hi, lo);
    fixed_max[k] = lo[k] + 0.1 * ext[k];
    handle_min[k] = hi[k] - 0.1 * ext[k];
    let spec = box_constraints([lo, fixed_max], [handle_min, hi]);
    let path = Path {
        kind: args.path,
        axis: k,
        extent: ext[k],
        drags: args.drags,
    };
    let pace = Pace {
        drag_hz: args.drag_hz,
        slow_ms: args.slow_ms,
    };
    let params = session_params(args.preset);
    println!(
        "mesh: {} vertices, {} triangles; {} session(s) x {} drags; preset {}; path {:?}; \
         drags {}; client spends {} ms per frame; max_fps {}, refine_fps {}",
        mesh.vertices,
        mesh.triangles,
        args.sessions,
        args.drags,
        args.preset
            .to_possible_value()
            .expect("no skipped variant")
            .get_name(),
        args.path,
        if args.drag_hz > 0.0 {
            format!("at {} Hz", args.drag_hz)
        } else {
            "closed loop".into()
        },
        args.slow_ms,
        args.max_fps.map_or("none".into(), |f| f.to_string()),
        args.declared_refine_fps()
            .map_or("none".into(), |f| f.to_string()),
    );
    println!("upload {:.1} ms", upload.as_secs_f64() * 1e3);
    let mut failed = vec![];
    for mode in &args.stream {
        let run = (&client, mesh.id.as_str(), &spec, &params);
        failed.extend(run_mode(run, *mode, &args, path, pace).await?);
    }
    if args.idle > 0 {
        idle_sessions(
            &client,
            &mesh.id,
            (lo, hi, k),
            args.idle,
            args.factor_cache_bytes,
        )
        .await?;
    }
    println!(
        "peak RSS of this process (server + clients): {:.1} MiB",
        peak_rss_kib() as f64 / 1024.0
    );
    if !failed.is_empty() {
        anyhow::bail!("load test checks failed: {}", failed.join("; "));
    }
    Ok(())
}

impl LoadtestArgs {
    /// The `refine_fps` the clients declare (`--refine-fps 0`: none).
    fn declared_refine_fps(&self) -> Option<u32> {
        Some(self.refine_fps).filter(|f| *f > 0)
    }
}

/// Runs the sessions' drags with one stream mode (on the mesh, with the
/// constraints and parameters of `run`) and prints its report; returns the
/// `--check-*` rules it broke.
async fn run_mode(
    (client, mesh_id, spec, params): (&Client, &str, &ConstraintsSpec, &SessionParams),
    mode: StreamMode,
    args: &LoadtestArgs,
    path: Path,
    pace: Pace,
) -> anyhow::Result<Vec<String>> {
    let t0 = Instant::now();
    let progress = Arc::new(AtomicU64::new(0));
    let extra = (args.extra_sessions > 0).then(|| {
        let (client, mesh_id, progress) = (client.clone(), mesh_id.to_owned(), progress.clone());
        let (n, at) = (args.extra_sessions, args.sessions as u64 * args.drags / 5);
        tokio::spawn(async move { extra_sessions(client, mesh_id, n, progress, at).await })
    });
    let mut tasks = vec![];
    let max_fps = args.max_fps;
    let refine_fps = args.declared_refine_fps();
    for _ in 0..args.sessions {
        let (client, mesh_id, spec, params, progress) = (
            client.clone(),
            mesh_id.to_owned(),
            spec.clone(),
            params.clone(),
            progress.clone(),
        );
        tasks.push(tokio::spawn(async move {
            let run = (client, mesh_id, params, spec);
            let mut opts = mode.options();
            opts.max_fps = max_fps;
            // a version 2 client asks for nothing
            opts.refine_fps = refine_fps.filter(|_| mode != StreamMode::Legacy);
            one_session(run, opts, path, pace, &progress).await
        }));
    }
    let mut sum = Summary::default();
    let (mut ready, mut constraints_ready) = (vec![], vec![]);
    let mut rows = String::new();
    for (session, t) in tasks.into_iter().enumerate() {
        let (seen, r, c) = t.await??;
        if args.latencies.is_some() {
            for (drag, l) in seen.latencies.iter().enumerate() {
                let ms = l.as_secs_f64() * 1e3;
                rows.push_str(&format!("{},{session},{drag},{ms:.3}\n", mode.name()));
            }
        }
        sum.add(seen);
        ready.push(r);
        constraints_ready.push(c);
    }
    if let Some(path) = &args.latencies {
        // appended: one file for every stream mode of the run
        use std::io::Write;
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)?;
        f.write_all(rows.as_bytes())?;
    }
    sum.sort();
    ready.sort();
    constraints_ready.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let m = mode.name();
    println!(
        "[{m}] session created -> ready to drag: median {:.1} ms, max {:.1} ms \
         (constraints sent -> ready: median {:.1} ms, max {:.1} ms)",
        ms(percentile(&ready, 0.5)),
        ms(percentile(&ready, 1.0)),
        ms(percentile(&constraints_ready, 0.5)),
        ms(percentile(&constraints_ready, 1.0)),
    );
    let pct = |p: f64| percentile(&sum.latencies, p);
    println!(
        "[{m}] drag->frame latency: p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms over {} drags",
        ms(pct(0.5)),
        ms(pct(0.99)),
        ms(pct(1.0)),
        sum.latencies.len()
    );
    let overall = ms(pct(0.5)).max(1e-9);
    let fairness = ms(percentile(&sum.medians, 1.0)) / overall;
    println!(
        "[{m}] per-session median drag->frame: min {:.2} ms, max {:.2} ms; \
         worst session / overall median: {:.2}x",
        ms(percentile(&sum.medians, 0.0)),
        ms(percentile(&sum.medians, 1.0)),
        fairness
    );
    let refused = match extra {
        Some(t) => {
            let (refused, admitted) = t.await??;
            println!(
                "[{m}] admission: {} more session(s) opened during the drags: \
                 {refused} refused (503 overloaded), {admitted} admitted",
                args.extra_sessions
            );
            refused
        }
        None => 0,
    };
    println!(
        "[{m}] while dragging, per client (median of sessions): {:.1} frames/s, {:.2} MB/s, \
         {:.1} KB per frame; frames by level: full {}, coarse {}",
        median(&sum.fps),
        median(&sum.bytes_per_sec) / 1e6,
        median(&sum.bytes_per_frame) / 1e3,
        sum.levels[0],
        sum.levels[1],
    );
    println!(
        "[{m}] settle (last drag sent -> settled frame): median {:.1} ms, max {:.1} ms; \
         iterations after the last change: median {}, max {}; converged {}/{}",
        ms(percentile(&sum.settles, 0.5)),
        ms(percentile(&sum.settles, 1.0)),
        sum.settle_iterations
            .get(sum.settle_iterations.len() / 2)
            .copied()
            .unwrap_or(0),
        sum.settle_iterations.last().copied().unwrap_or(0),
        sum.converged,
        sum.settles.len()
    );
    println!(
        "[{m}] {} frames in all; phase {:.2} s; errors: 0 (any error aborts the run)",
        sum.frames,
        t0.elapsed().as_secs_f64()
    );
    let mut failed = vec![];
    if let Some(limit) = args.check_max_ms.filter(|&l| ms(pct(1.0)) > l) {
        failed.push(format!("[{m}] max {:.1} ms > {limit} ms", ms(pct(1.0))));
    }
    if let Some(limit) = args.check_p99_ms.filter(|&l| ms(pct(0.99)) > l) {
        failed.push(format!("[{m}] p99 {:.1} ms > {limit} ms", ms(pct(0.99))));
    }
    if let Some(limit) = args.check_fairness.filter(|&l| fairness > l) {
        failed.push(format!(
            "[{m}] a session's median is {fairness:.2}x the overall median (> {limit}x)"
        ));
    }
    if let Some(want) = args.check_refused.filter(|&w| refused < w) {
        failed.push(format!(
            "[{m}] {refused} extra session(s) refused with 503 overloaded, expected at least {want}"
        ));
    }
    Ok(failed)
}

/// Once `at` drags were acknowledged in all, opens `n` more sessions one
/// every 50 ms; (refused with 503 `overloaded`, admitted). Admitted ones
/// are deleted at once.
async fn extra_sessions(
    client: Client,
    mesh_id: String,
    n: usize,
    progress: Arc<AtomicU64>,
    at: u64,
) -> anyhow::Result<(usize, usize)> {
    while progress.load(Ordering::Relaxed) < at {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let (mut refused, mut admitted) = (0, 0);
    for _ in 0..n {
        match client
            .create_session(&mesh_id, SessionParams::default())
            .await
        {
            Ok(s) => {
                admitted += 1;
                s.delete().await?;
            }
            Err(dend_client::ClientError::Api {
                status: 503,
                code: dend_client::ErrorCode::Overloaded,
                ..
            }) => refused += 1,
            Err(e) => return Err(e.into()),
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    Ok((refused, admitted))
}

/// Starts a server in this process (in memory, or on `--data-dir`) and
/// returns its URL.
async fn in_process_server(args: &LoadtestArgs) -> anyhow::Result<String> {
    let config = Config {
        addr: ([127, 0, 0, 1], 0).into(),
        iters_per_frame: args.iters_per_frame,
        preview_above_ms: args.preview_above_ms,
        ws_max_messages_per_sec: 1_000_000,
        factor_cache_bytes: args.factor_cache_bytes,
        max_sessions: (args.sessions + args.idle + 8).max(256),
        in_memory: args.data_dir.is_none(),
        data_dir: args.data_dir.clone().unwrap_or_default(),
        solver_threads: args.solver_threads,
        admission_waiting_sessions: args.admission_waiting_sessions,
        ..Config::default()
    };
    let listener = tokio::net::TcpListener::bind(config.addr).await?;
    let addr = listener.local_addr()?;
    let store = server::recover::open_store(&config)?;
    let app = server::app(AppState::with_store(config, store)?);
    drop(tokio::spawn(async move {
        server::serve_on(listener, app).await
    }));
    Ok(format!("http://{addr}"))
}

/// Uploads `--mesh`, or the generated `--grid`.
async fn upload(client: &Client, args: &LoadtestArgs) -> anyhow::Result<MeshInfo> {
    Ok(match &args.mesh {
        Some(path) => {
            let bytes =
                std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
            let ext = path
                .extension()
                .and_then(|e| e.to_str())
                .unwrap_or("")
                .to_ascii_lowercase();
            client.upload_file(bytes, &ext).await?
        }
        None => {
            let (p, t) = grid(args.grid.max(2));
            client.upload_json(&p, &t).await?
        }
    })
}

/// The `p`-quantile (0..=1, nearest rank) of sorted durations; zero when
/// there are none.
fn percentile(sorted: &[Duration], p: f64) -> Duration {
    sorted
        .get(((sorted.len() as f64 - 1.0) * p).round() as usize)
        .copied()
        .unwrap_or_default()
}

/// `VmHWM` of this process in KiB (0 when unknown).
fn peak_rss_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let line = status
        .lines()
        .find(|l| l.starts_with("VmHWM:"))
        .unwrap_or("");
    line.split_whitespace()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// A gauge of the server's `/metrics` (`dend_` + `name`), NaN when absent.
async fn metric(client: &Client, name: &str) -> anyhow::Result<f64> {
    Ok(client
        .metric(&format!("dend_{name}"))
        .await?
        .unwrap_or(f64::NAN))
}

/// Opens `n` idle sessions whose constraints all differ (so each needs its
/// own factor), reports the cache against its budget, then checks every
/// session kept its data: pose readable, a drag solved (factor rebuilt).
async fn idle_sessions(
    client: &Client,
    mesh_id: &str,
    (lo, hi, k): ([f64; 3], [f64; 3], usize),
    n: usize,
    budget: usize,
) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let mut sessions = vec![];
    for i in 0..n {
        let s = client
            .create_session(mesh_id, SessionParams::default())
            .await?;
        let ext = hi[k] - lo[k];
        let (mut fixed_max, mut handle_min) = (hi, lo);
        fixed_max[k] = lo[k] + (0.05 + 0.3 * i as f64 / n as f64) * ext;
        handle_min[k] = hi[k] - 0.1 * ext;
        let spec = box_constraints([lo, fixed_max], [handle_min, hi]);
        s.set_constraints(&spec).await?;
        s.wait_ready(Duration::from_secs(600)).await?;
        let _ = s
            .drag(0, DeltaJson::new([0.0, 0.01 * ext, 0.0], None), Some(2))
            .await?;
        sessions.push(s);
    }
    println!(
        "idle: {n} sessions opened in {:.1} s; factor cache {:.1} MiB in {} factors (budget {:.1} MiB), {} built",
        t0.elapsed().as_secs_f64(),
        metric(client, "factor_cache_bytes").await? / 1048576.0,
        metric(client, "factor_cache_entries").await?,
        budget as f64 / 1048576.0,
        metric(client, "factor_cache_builds").await?,
    );
    let mut moved = 0;
    for s in &sessions {
        let p = s.pose().await?;
        moved += usize::from(p.positions.iter().flatten().all(|x| x.is_finite()) && p.revision > 0);
        let _ = s.drag(0, DeltaJson::new([0.0; 3], None), Some(1)).await?;
    }
    println!(
        "idle: {moved}/{n} sessions kept their pose and solved a drag after eviction; factor cache now {:.1} MiB, {} built",
        metric(client, "factor_cache_bytes").await? / 1048576.0,
        metric(client, "factor_cache_builds").await?,
    );
    Ok(())
}

/// One session: created, constrained, connected with `opts`, dragged.
/// Returns what its client saw, and the times to ready (from creation and
/// from the constraints).
async fn one_session(
    (client, mesh_id, params, spec): (Client, String, SessionParams, ConstraintsSpec),
    opts: StreamOptions,
    path: Path,
    pace: Pace,
    progress: &AtomicU64,
) -> anyhow::Result<(drive::Seen, Duration, Duration)> {
    let created = Instant::now();
    let s = client.create_session(&mesh_id, params).await?;
    let constrained = Instant::now();
    s.set_constraints(&spec).await?;
    s.wait_ready(Duration::from_secs(600)).await?;
    let (ready, constraints_ready) = (created.elapsed(), constrained.elapsed());
    let mut ws = s.connect_with(opts).await?;
    let seen = drive::drag(&mut ws, &path, pace, progress).await?;
    ws.close().await?;
    s.delete().await?;
    Ok((seen, ready, constraints_ready))
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
