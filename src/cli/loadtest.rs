//! `dend loadtest`: drive N sessions with M WebSocket drags each and report
//! drag→frame latency (p50/p99) and frames per second.
//!
//! Each session is closed-loop: send drag `seq`, wait for the first frame
//! acknowledging it, record the time, send the next. Without `--url` the
//! command starts a server in-process on a free port.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::ValueEnum;
use dend_client::{Client, MeshInfo, WsEvent};
use dend_server::{self as server, AppState, Config};
use serde_json::json;

use super::PresetArg;

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
}

/// The `params` object of the drag sessions: the preset by name, as the
/// web editor sends it.
fn session_params(preset: PresetArg) -> serde_json::Value {
    json!({ "preset": preset.preset().name() })
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

struct SessionStats {
    latencies: Vec<Duration>,
    frames: u64,
    /// Session creation → ready to drag (rest operators when the mesh's
    /// are not built yet, the constraint set's factor).
    ready: Duration,
    /// Constraints sent → ready (the factor build, as a client sees it).
    constraints_ready: Duration,
    /// Last drag sent → the settled frame after it.
    settle: Duration,
    /// Iterations since the last change in the settled frame.
    settle_iterations: u32,
    /// Whether the settled frame converged.
    settle_converged: bool,
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
    let spec = json!({
        "fixed": {"box": {"min": lo, "max": fixed_max}},
        "handles": [{"name": "h", "vertices": {"box": {"min": handle_min, "max": hi}}}],
    });
    let mut step = [0.0; 3];
    step[(k + 1) % 3] = 0.3 * ext[k] / args.drags.max(1) as f64;
    let params = session_params(args.preset);
    println!(
        "mesh: {} vertices, {} triangles; {} session(s) x {} drags; preset {}",
        mesh.vertices,
        mesh.triangles,
        args.sessions,
        args.drags,
        args.preset
            .to_possible_value()
            .expect("no skipped variant")
            .get_name()
    );
    let t0 = Instant::now();
    let acked = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let extra = (args.extra_sessions > 0).then(|| {
        let (client, mesh_id, acked) = (client.clone(), mesh.id.clone(), acked.clone());
        let (n, at) = (args.extra_sessions, args.sessions as u64 * args.drags / 5);
        tokio::spawn(async move { extra_sessions(client, mesh_id, n, acked, at).await })
    });
    let mut tasks = vec![];
    for _ in 0..args.sessions {
        let (client, mesh_id, spec, params, drags, acked) = (
            client.clone(),
            mesh.id.clone(),
            spec.clone(),
            params.clone(),
            args.drags,
            acked.clone(),
        );
        tasks.push(tokio::spawn(async move {
            one_session(client, mesh_id, params, spec, drags, step, &acked).await
        }));
    }
    let mut all = vec![];
    let mut medians = vec![];
    let (mut ready, mut constraints_ready) = (vec![], vec![]);
    let mut frames = 0;
    let mut drag_time = Duration::ZERO;
    let (mut settles, mut settle_its, mut settled_converged) = (vec![], vec![], 0);
    for t in tasks {
        let (stats, elapsed) = t.await??;
        settles.push(stats.settle);
        settle_its.push(stats.settle_iterations);
        settled_converged += usize::from(stats.settle_converged);
        let mut own = stats.latencies.clone();
        own.sort();
        medians.push(percentile(&own, 0.5));
        all.extend(stats.latencies);
        ready.push(stats.ready);
        constraints_ready.push(stats.constraints_ready);
        frames += stats.frames;
        drag_time = drag_time.max(elapsed);
    }
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    ready.sort();
    constraints_ready.sort();
    println!(
        "upload {:.1} ms; session created -> ready to drag: median {:.1} ms, max {:.1} ms \
         (constraints sent -> ready: median {:.1} ms, max {:.1} ms)",
        ms(upload),
        ms(percentile(&ready, 0.5)),
        ms(percentile(&ready, 1.0)),
        ms(percentile(&constraints_ready, 0.5)),
        ms(percentile(&constraints_ready, 1.0)),
    );
    all.sort();
    let pct = |p: f64| percentile(&all, p);
    println!(
        "drag->frame latency: p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms over {} drags",
        ms(pct(0.5)),
        ms(pct(0.99)),
        ms(pct(1.0)),
        all.len()
    );
    medians.sort();
    let overall = ms(pct(0.5)).max(1e-9);
    let fairness = ms(percentile(&medians, 1.0)) / overall;
    println!(
        "per-session median drag->frame: min {:.2} ms, max {:.2} ms; worst session / overall median: {:.2}x",
        ms(percentile(&medians, 0.0)),
        ms(percentile(&medians, 1.0)),
        fairness
    );
    let refused = match extra {
        Some(t) => {
            let (refused, admitted) = t.await??;
            println!(
                "admission: {} more session(s) opened during the drags: {refused} refused (503 overloaded), {admitted} admitted",
                args.extra_sessions
            );
            refused
        }
        None => 0,
    };
    println!(
        "frames/s: {:.0} (all sessions), drags/s: {:.0}; drag phase {:.2} s, total {:.2} s",
        frames as f64 / drag_time.as_secs_f64(),
        all.len() as f64 / drag_time.as_secs_f64(),
        drag_time.as_secs_f64(),
        t0.elapsed().as_secs_f64()
    );
    settles.sort();
    settle_its.sort();
    println!(
        "settle (last drag sent -> settled frame): median {:.1} ms, max {:.1} ms; \
         iterations after the last change: median {}, max {}; converged {}/{}",
        ms(percentile(&settles, 0.5)),
        ms(percentile(&settles, 1.0)),
        settle_its.get(settle_its.len() / 2).copied().unwrap_or(0),
        settle_its.last().copied().unwrap_or(0),
        settled_converged,
        settles.len()
    );
    println!("errors: 0 (any error aborts the run)");
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
    let mut failed = vec![];
    if let Some(limit) = args.check_max_ms.filter(|&l| ms(pct(1.0)) > l) {
        failed.push(format!("max {:.1} ms > {limit} ms", ms(pct(1.0))));
    }
    if let Some(limit) = args.check_p99_ms.filter(|&l| ms(pct(0.99)) > l) {
        failed.push(format!("p99 {:.1} ms > {limit} ms", ms(pct(0.99))));
    }
    if let Some(limit) = args.check_fairness.filter(|&l| fairness > l) {
        failed.push(format!(
            "a session's median is {fairness:.2}x the overall median (> {limit}x)"
        ));
    }
    if let Some(want) = args.check_refused.filter(|&w| refused < w) {
        failed.push(format!(
            "{refused} extra session(s) refused with 503 overloaded, expected at least {want}"
        ));
    }
    if !failed.is_empty() {
        anyhow::bail!("load test checks failed: {}", failed.join("; "));
    }
    Ok(())
}

/// Once `at` drags were acknowledged in all, opens `n` more sessions one
/// every 50 ms; (refused with 503 `overloaded`, admitted). Admitted ones
/// are deleted at once.
async fn extra_sessions(
    client: Client,
    mesh_id: String,
    n: usize,
    acked: std::sync::Arc<std::sync::atomic::AtomicU64>,
    at: u64,
) -> anyhow::Result<(usize, usize)> {
    while acked.load(std::sync::atomic::Ordering::Relaxed) < at {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let (mut refused, mut admitted) = (0, 0);
    for _ in 0..n {
        match client.create_session(&mesh_id, json!({})).await {
            Ok(s) => {
                admitted += 1;
                s.delete().await?;
            }
            Err(dend_client::ClientError::Api {
                status: 503, code, ..
            }) if code == "overloaded" => refused += 1,
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
        let s = client.create_session(mesh_id, json!({})).await?;
        let ext = hi[k] - lo[k];
        let (mut fixed_max, mut handle_min) = (hi, lo);
        fixed_max[k] = lo[k] + (0.05 + 0.3 * i as f64 / n as f64) * ext;
        handle_min[k] = hi[k] - 0.1 * ext;
        let spec = json!({
            "fixed": {"box": {"min": lo, "max": fixed_max}},
            "handles": [{"name": "h", "vertices": {"box": {"min": handle_min, "max": hi}}}],
        });
        s.set_constraints(&spec).await?;
        s.wait_ready(Duration::from_secs(600)).await?;
        let _ = s
            .drag(
                json!(0),
                json!({"translate": [0.0, 0.01 * ext, 0.0]}),
                Some(2),
            )
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
        let _ = s
            .drag(json!(0), json!({"translate": [0.0, 0.0, 0.0]}), Some(1))
            .await?;
    }
    println!(
        "idle: {moved}/{n} sessions kept their pose and solved a drag after eviction; factor cache now {:.1} MiB, {} built",
        metric(client, "factor_cache_bytes").await? / 1048576.0,
        metric(client, "factor_cache_builds").await?,
    );
    Ok(())
}

async fn one_session(
    client: Client,
    mesh_id: String,
    params: serde_json::Value,
    spec: serde_json::Value,
    drags: u64,
    step: [f64; 3],
    acked: &std::sync::atomic::AtomicU64,
) -> anyhow::Result<(SessionStats, Duration)> {
    let created = Instant::now();
    let s = client.create_session(&mesh_id, params).await?;
    let constrained = Instant::now();
    s.set_constraints(&spec).await?;
    s.wait_ready(Duration::from_secs(600)).await?;
    let mut ws = s.connect().await?;
    let mut stats = SessionStats {
        latencies: Vec::with_capacity(drags as usize),
        frames: 0,
        ready: created.elapsed(),
        constraints_ready: constrained.elapsed(),
        settle: Duration::ZERO,
        settle_iterations: 0,
        settle_converged: false,
    };
    let start = Instant::now();
    let mut last_sent = Instant::now();
    let mut already_settled = false;
    for seq in 1..=drags {
        let sent = Instant::now();
        last_sent = sent;
        ws.drag(0, step, None, seq).await?;
        loop {
            match ws.next().await? {
                WsEvent::Frame(h, _) => {
                    stats.frames += 1;
                    if h.ack_seq >= seq {
                        stats.latencies.push(sent.elapsed());
                        let _ = acked.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if seq == drags && h.settled {
                            // already settled: no further frame will come
                            stats.settle = sent.elapsed();
                            stats.settle_iterations = h.iteration;
                            stats.settle_converged = h.converged;
                            already_settled = true;
                        }
                        break;
                    }
                }
                WsEvent::Event(v) if v["type"] == "error" => anyhow::bail!("server error: {v}"),
                WsEvent::Closed(c) => anyhow::bail!("connection closed ({c:?})"),
                WsEvent::Event(_) => {}
            }
        }
    }
    let elapsed = start.elapsed();
    // after the last drag: frames until the server says settled
    while !already_settled {
        match ws.next().await? {
            WsEvent::Frame(h, _) => {
                stats.frames += 1;
                if h.ack_seq >= drags && h.settled {
                    stats.settle = last_sent.elapsed();
                    stats.settle_iterations = h.iteration;
                    stats.settle_converged = h.converged;
                    already_settled = true;
                }
            }
            WsEvent::Event(v) if v["type"] == "error" => anyhow::bail!("server error: {v}"),
            WsEvent::Closed(c) => anyhow::bail!("connection closed ({c:?})"),
            WsEvent::Event(_) => {}
        }
    }
    ws.close().await?;
    s.delete().await?;
    Ok((stats, elapsed))
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
        let read =
            |p: PresetArg| -> Params { serde_json::from_value(session_params(p)).expect("parse") };
        assert_eq!(read(PresetArg::Characters), Params::default());
        assert_eq!(read(PresetArg::Elastica), Preset::Elastica.params());
        assert_ne!(read(PresetArg::Characters), read(PresetArg::Elastica));
    }
}
