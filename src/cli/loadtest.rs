//! `dend loadtest`: drive N sessions with M WebSocket drags each and report
//! per stream mode: frames/s while dragging, drag→frame latency (p50/p99),
//! settle time and iterations, converged, when the settled pose is shown
//! (every later frame within 1e-3 of the diagonal of it), the level of the
//! frames and the bytes/s to each client.
//!
//! By default each session is closed-loop: send drag `seq`, wait for the
//! first frame acknowledging it, send the next; `--drag-hz` sends drags on a
//! clock instead (a mouse), `--slow-ms` makes the client spend that long on
//! each frame (a slow browser). `--stream legacy,q16` runs the same drags
//! once per stream mode, in one run: `legacy` is a version 2 client (no flow
//! control, f32 frames), `f32`/`q16` declare a window of one frame and take
//! version 3 frames in that encoding. Without `--url` the command starts a
//! server in-process on a free port.

use std::sync::atomic::AtomicU64;
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::ValueEnum;
use dend_client::ws::StreamOptions;
use dend_client::{Client, ConstraintsSpec, SessionParams};

use dend_client::gesture::Gesture;
use drive::{median, Pace, Path, Summary, VISIBLE_SHARE};

#[path = "loadtest_args.rs"]
mod args;
#[path = "loadtest_drive.rs"]
mod drive;
#[path = "loadtest_setup.rs"]
mod setup;

use args::session_params;
pub use args::{LoadtestArgs, StreamMode};
use setup::{
    box_constraints, extra_sessions, idle_sessions, in_process_server, peak_rss_kib, upload,
};

/// Runs the load test and prints its report.
pub fn run(args: LoadtestArgs) -> anyhow::Result<()> {
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(run_async(args))
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
        gesture: Gesture {
            kind: args.path,
            axis: k,
            extent: ext[k],
            drags: args.drags,
        },
        diagonal: ext.iter().map(|e| e * e).sum::<f64>().sqrt(),
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
    let (max_fps, gestures) = (args.max_fps, args.gestures);
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
            one_session(run, opts, (path, gestures), pace, &progress).await
        }));
    }
    let mut sum = Summary::default();
    let (mut ready, mut constraints_ready) = (vec![], vec![]);
    let mut rows = String::new();
    let mut gesture_settles: Vec<Vec<Duration>> = vec![Vec::new(); gestures as usize];
    for (session, t) in tasks.into_iter().enumerate() {
        let (seen, settles, r, c) = t.await??;
        for (g, d) in settles.into_iter().enumerate() {
            gesture_settles[g].push(d);
        }
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
        "[{m}] settled pose shown (last drag sent -> every later frame within {} of the \
         diagonal of the settled pose): median {:.1} ms, max {:.1} ms",
        VISIBLE_SHARE,
        ms(percentile(&sum.settles_visible, 0.5)),
        ms(percentile(&sum.settles_visible, 1.0)),
    );
    if gestures > 1 {
        let each: Vec<String> = gesture_settles
            .iter_mut()
            .enumerate()
            .map(|(g, d)| {
                d.sort();
                format!("{}: {:.1} ms", g + 1, ms(percentile(d, 0.5)))
            })
            .collect();
        println!("[{m}] settle by gesture (median): {}", each.join(", "));
    }
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

/// The `p`-quantile (0..=1, nearest rank) of sorted durations; zero when
/// there are none.
fn percentile(sorted: &[Duration], p: f64) -> Duration {
    sorted
        .get(((sorted.len() as f64 - 1.0) * p).round() as usize)
        .copied()
        .unwrap_or_default()
}

/// What one session's client saw in its last gesture, every gesture's
/// settle, and its times to ready (from creation and from the
/// constraints).
type SessionRun = (drive::Seen, Vec<Duration>, Duration, Duration);

/// One session: created, constrained, connected with `opts`, dragged
/// through `gestures` gestures.
async fn one_session(
    (client, mesh_id, params, spec): (Client, String, SessionParams, ConstraintsSpec),
    opts: StreamOptions,
    (path, gestures): (Path, u64),
    pace: Pace,
    progress: &AtomicU64,
) -> anyhow::Result<SessionRun> {
    let created = Instant::now();
    let s = client.create_session(&mesh_id, params).await?;
    let constrained = Instant::now();
    s.set_constraints(&spec).await?;
    s.wait_ready(Duration::from_secs(600)).await?;
    let (ready, constraints_ready) = (created.elapsed(), constrained.elapsed());
    let mut ws = s.connect_with(opts).await?;
    let mut settles = Vec::new();
    let mut seen = drive::Seen::default();
    for g in 0..gestures {
        seen = drive::drag(&mut ws, (&path, g), pace, progress).await?;
        settles.push(seen.settle);
    }
    ws.close().await?;
    s.delete().await?;
    Ok((seen, settles, ready, constraints_ready))
}
