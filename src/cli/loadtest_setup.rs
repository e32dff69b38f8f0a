//! What a load test runs against: the in-process server, the mesh, the
//! sessions opened beside the dragged ones (refused or admitted, idle on
//! a factor budget), and the server's and this process's figures.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use dend_client::constraints::BoxSel;
use dend_client::ws::DeltaJson;
use dend_client::{Client, ConstraintsSpec, HandleSpec, MeshInfo, SessionParams, VertexSet};
use dend_server::{self as server, AppState, Config};

use super::args::LoadtestArgs;

/// Constraints fixing the box `fixed` and dragging the box `handle` (named
/// `h`), each `[min, max]`.
pub(super) fn box_constraints(fixed: [[f64; 3]; 2], handle: [[f64; 3]; 2]) -> ConstraintsSpec {
    let boxed = |[min, max]: [[f64; 3]; 2]| VertexSet::Box {
        bbox: BoxSel { min, max },
    };
    ConstraintsSpec::new(boxed(fixed), vec![HandleSpec::named("h", boxed(handle))])
}

/// Once `at` drags were acknowledged in all, opens `n` more sessions one
/// every 50 ms; (refused with 503 `overloaded`, admitted). Admitted ones
/// are deleted at once.
pub(super) async fn extra_sessions(
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
pub(super) async fn in_process_server(args: &LoadtestArgs) -> anyhow::Result<String> {
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
pub(super) async fn upload(client: &Client, args: &LoadtestArgs) -> anyhow::Result<MeshInfo> {
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
pub(super) async fn idle_sessions(
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

/// `VmHWM` of this process in KiB (0 when unknown).
pub(super) fn peak_rss_kib() -> u64 {
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
