//! The drag loop of a session, in process and without the server (the
//! interactive figures of docs/performance.md): a handle dragged along a path in `--drags` target changes with
//! `--per-drag` iterations after each (what the session's frames run while
//! a person drags), then the settle (one-iteration steps until converged or
//! `max_iters` since the last change), against the one-shot solve of the
//! final target from rest. Prints one JSON line. With `--previews` each
//! drag is answered as a session answers a WebSocket drag on a large mesh
//! (`Deformer::preview`, corrections held; meshes without a preview level
//! step as without it), and the settle starts by refining the preview
//! until its coarse problem converges (`settle.preview_*`), as a session
//! does before its quiet time ends.
//!
//! ```text
//! cargo run --release --example drag_sim -- MESH [--drags 60] [--per-drag 1]
//!     [--path line|arc|twist] [--preset characters|elastica] [--previews] [--levels 1|2|3 (default 3)]
//!     [--correction-period K] [--coarse-ratio R] [--tol T] [--anderson W]
//!     [--area KA] [--stretch KS] [--error-trace] [--galerkin off|DEPTH[,LAG[,PERIOD[,SMOOTH]]]]
//!     [--newton-level on|off] [--level-minima] [--level-minima-detail S]
//!     [--gestures N] [--settle-trace]
//! ```
//!
//! `--galerkin` makes the coarse corrections Galerkin ones
//! (`dend::deform::Galerkin`: aggregates spanning DEPTH levels, the coarse
//! matrix reused for LAG corrections, one every PERIOD fine iterations,
//! the aggregates' weights smoothed SMOOTH times across their borders;
//! defaults 2, 6, 1, 1); without it, or with `off`, they are the
//! hierarchy's coarse problems' (the library's default). `--newton-level
//! on` corrects the drags' and the settle's sequences on the mesh's Newton
//! level where it has one (`Deformer::set_newton_level`; off by default).
//!
//! `fine_iteration_ms` is the median time of one fine iteration in the same
//! run (eleven timed before the one-shot and eleven after the settle); the
//! one-shot solve (timed after the constraint set's precomputation: its
//! fine factor and `Deformer::prepare_levels`) and the settle are also
//! reported in those units (`fine_iteration_equivalents`: time over it)
//! and as `work` (fine iterations plus `StepReport::coarse_work`, each
//! level's iterations weighted by its vertex count: a count that does not
//! depend on the host or on what else it runs).
//!
//! With `--gestures N` the gesture runs N times on the same deformer, along
//! the path and back in turn, as a session's later gestures with the same
//! constraint set (what a deformer learns from its first corrections, the
//! coarse levels' detail weight, carries over): `settle` is the last
//! gesture's, `first_settle` the first's.
//! With `--level-minima`, `level_minima` holds each coarse level's own
//! minimum of the final target against the fine minimum (solves to
//! tolerance 1e-5, `dend::deform::level_minima`): how far the levels'
//! models stand from the fine one, whatever the solver's schedule.
//! `--level-minima-detail S` measures them with each level's detail weight
//! `S` times the level above's (`dend::deform::level_minima_with_detail`:
//! the softer levels the solver fits where they are too stiff).
//!
//! With `--error-trace`, `one_shot_trace` has one row per iteration of the
//! one-shot solve: its distance to the tight-tolerance minimum (objective
//! excess, pose rms and max in mean edge lengths), its update and the
//! coarse iterations of a correction (`one_shot_trace` below).
//!
//! With `--settle-trace`, `settle_trace` has the same distances for the
//! (last) gesture's settle: a first row for the pose it starts from (the
//! last preview's with `--previews`), then one per settle step, with its
//! time since the settle started. Shows where a settle's time goes: which
//! part of the pose is far from the minimum when it starts, and how much
//! of it each fine iteration and each correction removes.
//!
//! MESH is a file, `tube:N` or `creature:LEVELS` (`dend gen creature`). The edit is the load test's: the lowest
//! 10 % of the vertices along the longest axis fixed, the highest 10 % the
//! handle, dragged along `dend loadtest`'s path (`dend_client::gesture`,
//! the same drag deltas composed as a session composes them): `line` moves
//! it by 0.3 of that extent across it, `arc` swings it 60° about the fixed
//! end while it turns with the swing. `twist` is another edit, not the
//! load test's: the handle moved by 0.3 of the extent across, out and back
//! along a bow of 0.15, while it turns 60° about the longest axis (this
//! tool's `arc` until 2026-12-07: docs/performance.md's figures of
//! `drag_sim --path arc` before then are of this edit).
//! The drags hold the coarse corrections, as a session's do, and the
//! settle runs them: a replay whose drags ran Galerkin corrections (one
//! after every iteration) kept the pose near the minimum through the
//! gesture, which a session does not, and overstated their settle against
//! the server's (docs/performance.md).

use std::sync::Arc;
use std::time::Instant;

use dend::deform::{
    Constraints, Deformer, Factor, Galerkin, Levels, Preset, Rest, RigidTransform, StepReport,
};
use dend::mesh::{Mesh, Point};
use dend_client::gesture::{self, DragPath};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

fn arg<T: std::str::FromStr>(args: &[String], name: &str) -> Option<T> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
}

fn load(spec: &str) -> Result<Mesh, String> {
    if let Some(n) = spec.strip_prefix("tube:") {
        let n: usize = n.parse().map_err(|_| format!("bad tube size {n:?}"))?;
        return Ok(dend_testkit::tube_of_size(n));
    }
    if let Some(levels) = spec.strip_prefix("creature:") {
        use dend::mesh::gen::{generate, Shape, ShapeSpec};
        let mut s = ShapeSpec::default_for(Shape::Creature);
        s.params.nu = Some(
            levels
                .parse()
                .map_err(|_| format!("bad levels {levels:?}"))?,
        );
        return generate(&s).map_err(|e| e.to_string());
    }
    dend::mesh::io::read_path(std::path::Path::new(spec)).map_err(|e| e.to_string())
}

/// The edit the handle follows (module docs).
#[derive(Clone, Copy)]
enum Edit {
    /// `dend loadtest`'s path.
    Load(DragPath),
    /// Across, along a bow, turning about the longest axis.
    Twist,
}

impl Edit {
    fn name(self) -> String {
        match self {
            Edit::Load(p) => p.to_string(),
            Edit::Twist => "twist".into(),
        }
    }

    /// The handle's target after drag `k` (1-based; 0: before the first)
    /// of gesture `g` (0-based: even gestures go along the path, odd ones
    /// back), from the rest pose (identity about `pivot`) before gesture 0.
    fn target(
        self,
        g: usize,
        k: usize,
        drags: usize,
        (axis, extent, pivot): (usize, f64, Point),
    ) -> RigidTransform {
        let mut target = RigidTransform {
            rotation: UnitQuaternion::identity(),
            translation: [0.0; 3],
            pivot,
        };
        match self {
            Edit::Load(kind) => {
                // the session's composition of the load test's deltas
                let path = gesture::Gesture {
                    kind,
                    axis,
                    extent,
                    drags: drags as u64,
                };
                for gg in 0..=g {
                    let n = if gg == g { k } else { drags };
                    for j in 0..n {
                        let (t, q) = path.delta_of(gg as u64, j as u64);
                        let r = q.map_or(UnitQuaternion::identity(), |[x, y, z, w]| {
                            UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
                        });
                        target = target.then(r, t);
                    }
                }
            }
            Edit::Twist => {
                let s = k as f64 / drags as f64;
                let s = if g % 2 == 1 { 1.0 - s } else { s };
                let mut t = [0.0; 3];
                t[(axis + 1) % 3] = 0.3 * extent * s;
                t[(axis + 2) % 3] += 0.15 * extent * (std::f64::consts::PI * s).sin();
                let mut a = Vector3::zeros();
                a[axis] = 1.0;
                target.rotation = UnitQuaternion::from_scaled_axis(a * (60f64.to_radians() * s));
                target.translation = t;
            }
        }
        target
    }
}

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}

fn run() -> Result<(), String> {
    // the solver's debug events (its corrections and Newton steps) with
    // RUST_LOG=dend=debug, on stderr beside the JSON report
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let spec = args.first().ok_or("usage: drag_sim MESH [options]")?;
    let mesh = load(spec)?;
    let drags: usize = arg(&args, "--drags").unwrap_or(60);
    let per_drag: usize = arg(&args, "--per-drag").unwrap_or(1);
    let edit = match arg::<String>(&args, "--path").as_deref() {
        None => Edit::Load(DragPath::Line),
        Some("twist") => Edit::Twist,
        Some(p) => Edit::Load(p.parse::<DragPath>()?),
    };
    let previews = args.iter().any(|a| a == "--previews");
    let error_trace = args.iter().any(|a| a == "--error-trace");
    let settle_trace = args.iter().any(|a| a == "--settle-trace");
    let level_detail: Option<f64> = arg(&args, "--level-minima-detail");
    let with_level_minima = args.iter().any(|a| a == "--level-minima") || level_detail.is_some();
    let gestures: usize = arg(&args, "--gestures").unwrap_or(1);
    let preset = arg::<String>(&args, "--preset")
        .map(|p| Preset::from_name(&p).ok_or(format!("unknown preset {p}")))
        .transpose()?
        .unwrap_or_default();
    let (period, ratio) = (
        arg(&args, "--correction-period"),
        arg(&args, "--coarse-ratio"),
    );
    let (area, stretch): (Option<f64>, Option<f64>) =
        (arg(&args, "--area"), arg(&args, "--stretch"));
    let mut params = preset.params().with_elastic(|e| {
        if let Some(k) = period {
            e.correction_period = k;
        }
        if let Some(a) = area {
            e.area = a;
        }
        if let Some(k) = stretch {
            e.stretch = k;
        }
        if let Some(r) = ratio {
            e.coarse_ratio = r;
        }
    });
    if let Some(t) = arg(&args, "--tol") {
        params.tol = t;
    }
    if let Some(w) = arg(&args, "--anderson") {
        params.anderson = w;
    }
    let galerkin = match arg::<String>(&args, "--galerkin").as_deref() {
        None | Some("off") => None,
        Some(g) => {
            let mut v = g.split(',').map(|x| x.parse::<usize>());
            let d = Galerkin::default();
            let mut next = |dflt: usize| v.next().unwrap_or(Ok(dflt));
            match (next(d.depth), next(d.lag), next(d.period), next(d.smooth)) {
                (Ok(depth), Ok(lag), Ok(period), Ok(smooth)) => Some(Galerkin {
                    depth,
                    lag,
                    period,
                    smooth,
                }),
                _ => {
                    return Err(format!(
                        "--galerkin {g}: off or DEPTH[,LAG[,PERIOD[,SMOOTH]]]"
                    ))
                }
            }
        }
    };
    let newton_level = match arg::<String>(&args, "--newton-level").as_deref() {
        Some("on") => true,
        None | Some("off") => false,
        Some(v) => return Err(format!("--newton-level {v}: on or off")),
    };
    let levels = match arg::<String>(&args, "--levels").as_deref() {
        None | Some("many") | Some("3") => Levels::Many,
        Some("1") => Levels::One,
        Some("2") => Levels::Two,
        Some(l) => return Err(format!("--levels {l}: 1, 2 or many")),
    };
    let (lo, hi) = bbox(&mesh);
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(0);
    let extent = hi[axis] - lo[axis];
    let n = mesh.num_vertices() as u32;
    let fixed: Vec<u32> = (0..n)
        .filter(|&v| mesh.positions()[v as usize][axis] < lo[axis] + 0.1 * extent)
        .collect();
    let handle: Vec<u32> = (0..n)
        .filter(|&v| mesh.positions()[v as usize][axis] > hi[axis] - 0.1 * extent)
        .collect();
    let mut c = Constraints::new(&mesh, fixed, vec![("h".into(), handle, None)])
        .map_err(|e| e.to_string())?;
    let pivot = c.handles[0].rest_centroid;
    let rest = Arc::new(Rest::new(mesh.clone()).map_err(|e| e.to_string())?);
    let factor = Factor::build(&rest, &params, &c).map_err(|e| e.to_string())?;
    let diag = mesh.diagonal();

    // one shot: the final target from rest
    let place = (axis, extent, pivot);
    c.handles[0].target = edit.target(0, drags, drags, place);
    // the unit: eleven fine iterations before the one-shot and eleven
    // after the settle (below), one median, so that a drift of the host's
    // speed over the run weighs on both solves alike
    let mut clock = dend_testkit::FineIterationClock::new(rest.clone(), params);
    let mut unit = fine_iterations_ms(&mut clock, &factor, &c)?;
    let setup = Setup {
        params,
        levels,
        galerkin,
        newton_level,
    };
    let mut one = setup.deformer(&rest);
    // every level's factor is the constraint set's precomputation, as the
    // fine factor is (a session builds them before it is ready)
    one.prepare_levels(&factor, &c);
    let t = Instant::now();
    let r1 = one
        .step(&factor, &c, params.max_iters)
        .map_err(|e| e.to_string())?;
    let one_ms = t.elapsed().as_secs_f64() * 1e3;

    // the drag loop: `--gestures N` runs the gesture N times on the same
    // deformer, along the arc and back in turn (N odd ends at the one-shot's
    // target), as a session's later gestures with the same constraint set;
    // the report's settle is the last gesture's
    let mut d = setup.deformer(&rest);
    // its levels built ahead too, as a session builds them beside the
    // constraint set's factor (without them the settle's first correction
    // built the coarse problems: on igea_134k 940 ms against 550 for the
    // next ones)
    d.prepare_levels(&factor, &c);
    let mut seen = Vec::new();
    for g in 0..gestures {
        seen.push(gesture(
            &mut d,
            (&factor, &mut c),
            (drags, per_drag, previews, params.max_iters),
            // (only the reported gesture's poses are kept)
            settle_trace && g + 1 == gestures,
            |k| edit.target(g, k, drags, place),
        )?);
    }
    let (Some(first), Some(g)) = (seen.first(), seen.last()) else {
        return Err("--gestures 0".into());
    };
    let last = &g.last;
    unit.extend(fine_iterations_ms(&mut clock, &factor, &c)?);
    let fine_ms = dend_testkit::median(unit);
    let dist = |a: &[Point], b: &[Point]| {
        a.iter()
            .zip(b)
            .map(|(p, q)| {
                ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
            })
            .fold(0.0, f64::max)
    };
    let gap = dist(d.pose(), one.pose());
    // the minimum near the one-shot pose, to a tight tolerance
    let mut tight = params;
    tight.tol = 1e-7;
    tight.max_iters = 2000;
    let mut reference = Deformer::new(rest.clone(), tight);
    reference
        .set_pose(one.pose().to_vec())
        .map_err(|e| e.to_string())?;
    let r_ref = reference
        .step(&factor, &c, tight.max_iters)
        .map_err(|e| e.to_string())?;
    let h = rest.mesh().mean_edge_length();
    let settle_rows: Vec<serde_json::Value> = g
        .trace
        .iter()
        .map(|s| {
            let (rms, max) = distance_to(&s.pose, reference.pose(), h);
            serde_json::json!({
                "iteration": s.iterations,
                "ms": s.ms,
                "excess": s.objective.map(|e| (e - r_ref.objective) / r_ref.objective.abs()),
                "rms": rms,
                "max": max,
                "update": s.update,
                "coarse_iterations": s.coarse_iterations,
            })
        })
        .collect();
    let trace = if error_trace {
        one_shot_trace(
            &rest,
            &factor,
            &c,
            setup,
            (reference.pose(), r_ref.objective),
        )?
    } else {
        Vec::new()
    };
    let minima = if with_level_minima {
        let mut p = params;
        p.tol = 1e-5;
        p.max_iters = 3000;
        let detail = level_detail.unwrap_or(1.0);
        Some(
            dend::deform::level_minima_with_detail(&rest, &p, &c, detail)
                .map_err(|e| e.to_string())?,
        )
    } else {
        None
    };
    let out = serde_json::json!({
        "mesh": spec,
        "vertices": mesh.num_vertices(),
        "preset": preset.name(),
        "path": edit.name(),
        "galerkin": galerkin.map(|g| [g.depth, g.lag, g.period, g.smooth]),
        "drags": drags,
        "per_drag": per_drag,
        "fine_iteration_ms": fine_ms,
        "one_shot": {"iterations": r1.iterations, "converged": r1.converged,
                     "objective": r1.objective, "ms": one_ms,
                     "fine_iteration_equivalents": one_ms / fine_ms,
                     "work": r1.iterations as f64 + r1.coarse_work},
        "drag_ms_per_drag": g.drag_ms / drags as f64,
        "drag_iterations": g.drag_iters,
        "gestures": gestures,
        "first_settle": {"iterations": first.settle_iters, "ms": first.settle_ms,
                         "fine_iteration_equivalents": first.settle_ms / fine_ms,
                         "work": first.work()},
        "settle": {"iterations": g.settle_iters, "converged": last.converged,
                   "objective": last.objective, "ms": g.settle_ms,
                   "fine_iteration_equivalents": g.settle_ms / fine_ms,
                   "work": g.work(),
                   "coarse_iterations": g.coarse_its, "coarse_ms": g.coarse_ms,
                   "preview_iterations": g.preview_its, "preview_ms": g.preview_ms},
        "reference": {"objective": r_ref.objective, "iterations": r_ref.iterations,
                      "one_shot_gap": dist(one.pose(), reference.pose()) / diag,
                      "settled_gap": dist(d.pose(), reference.pose()) / diag},
        "one_shot_trace": trace,
        "settle_trace": settle_rows,
        "level_minima": minima,
        "objective_ratio": last.objective / r1.objective,
        "gap_over_diagonal": gap / diag,
    });
    println!("{out}");
    Ok(())
}

/// One gesture and its settle, as a session runs them ([`run`]'s drag
/// loop): the handle's target at drag `k` is `target(k)`.
fn gesture(
    d: &mut Deformer,
    (factor, c): (&Factor, &mut Constraints),
    (drags, per_drag, previews, max_iters): (usize, usize, bool, usize),
    trace: bool,
    target: impl Fn(usize) -> RigidTransform,
) -> Result<Gesture, String> {
    // a session holds the coarse corrections while a person drags (a
    // correction behind a drag delays its frame) and runs them in the
    // settle: so does the replay
    d.hold_corrections(true);
    let t = Instant::now();
    let mut drag_iters = 0;
    let (mut preview_its, mut preview_ms) = (0, 0.0);
    for k in 1..=drags {
        c.handles[0].target = target(k);
        if previews {
            // what a session answers a WebSocket drag with on a large mesh
            let its = dend::deform::PREVIEW_ITERATIONS;
            if d.preview(factor, c, its)
                .map_err(|e| e.to_string())?
                .is_some()
            {
                continue;
            }
        }
        let r = d.step(factor, c, per_drag).map_err(|e| e.to_string())?;
        drag_iters += r.iterations;
    }
    let drag_ms = t.elapsed().as_secs_f64() * 1e3;
    let t = Instant::now();
    if previews {
        // between the last drag and the end of the quiet time the session
        // refines the preview until its coarse problem converges
        for _ in 0..100 {
            let its = dend::deform::PREVIEW_ITERATIONS;
            match d.preview(factor, c, its).map_err(|e| e.to_string())? {
                Some(r) => {
                    preview_its += r.iterations;
                    preview_ms += r.ms;
                    if r.converged {
                        break;
                    }
                }
                None => break,
            }
        }
    }
    d.hold_corrections(false);
    // the pose the settle starts from (a preview's where previews answered
    // the drags), then every settle step's
    let mut poses = Vec::new();
    if trace {
        poses.push(SettlePose {
            pose: d.shown_pose().to_vec(),
            ms: t.elapsed().as_secs_f64() * 1e3,
            iterations: 0,
            coarse_iterations: 0,
            update: None,
            objective: None,
        });
    }
    let (mut settle_iters, mut last) = (0, None);
    let (mut coarse_its, mut coarse_ms, mut coarse_work) = (0, 0.0, 0.0);
    while settle_iters < max_iters {
        let r = d.step(factor, c, 1).map_err(|e| e.to_string())?;
        settle_iters += r.iterations;
        coarse_its += r.coarse_iterations;
        coarse_ms += r.coarse_ms;
        coarse_work += r.coarse_work;
        if std::env::var_os("DEND_TRACE").is_some() {
            eprintln!(
                "settle {settle_iters}: update {:.2e} objective {:.6} coarse {}",
                r.last_update, r.objective, r.coarse_iterations
            );
        }
        let done = r.converged || r.diverged || r.iterations == 0;
        if trace {
            poses.push(SettlePose {
                pose: d.pose().to_vec(),
                ms: t.elapsed().as_secs_f64() * 1e3,
                iterations: settle_iters,
                coarse_iterations: r.coarse_iterations,
                update: Some(r.last_update),
                objective: Some(r.objective),
            });
        }
        last = Some(r);
        if done {
            break;
        }
    }
    Ok(Gesture {
        drag_ms,
        drag_iters,
        preview_its,
        preview_ms,
        settle_iters,
        coarse_its,
        coarse_ms,
        coarse_work,
        settle_ms: t.elapsed().as_secs_f64() * 1e3,
        last: last.ok_or("no settle step")?,
        trace: poses,
    })
}

/// What [`gesture`] measured.
struct Gesture {
    drag_ms: f64,
    drag_iters: usize,
    preview_its: usize,
    preview_ms: f64,
    settle_iters: usize,
    coarse_its: usize,
    coarse_ms: f64,
    coarse_work: f64,
    settle_ms: f64,
    last: StepReport,
    /// With `--settle-trace`, the settle's poses ([`SettlePose`]).
    trace: Vec<SettlePose>,
}

/// A pose of the settle (`--settle-trace`): its time since the last drag
/// (the previews' refinement included, as the settle's `ms`), the settle's
/// fine iterations and the step's coarse ones, the step's update (what the
/// convergence test reads) and objective (`None` for the pose the settle
/// starts from).
struct SettlePose {
    pose: Vec<Point>,
    ms: f64,
    iterations: usize,
    coarse_iterations: usize,
    update: Option<f64>,
    objective: Option<f64>,
}

impl Gesture {
    /// The settle's work: fine iterations plus the coarse ones by size.
    fn work(&self) -> f64 {
        self.settle_iters as f64 + self.coarse_work
    }
}

/// The solver's settings a run compares: every deformer of the run is
/// made with them.
#[derive(Clone, Copy)]
struct Setup {
    params: dend::deform::Params,
    levels: Levels,
    galerkin: Option<Galerkin>,
    newton_level: bool,
}

impl Setup {
    /// A deformer at the rest pose with these settings.
    fn deformer(&self, rest: &Arc<Rest>) -> Deformer {
        let mut d = Deformer::new(rest.clone(), self.params);
        d.set_levels(self.levels);
        d.set_galerkin(self.galerkin);
        d.set_newton_level(self.newton_level);
        d
    }
}

/// The one-shot solve again, one iteration per step (the same iterates as
/// one call), with each iteration's distance to the minimum `star` (its
/// pose and objective, solved to a tight tolerance): the objective's
/// relative excess, and the pose's root-mean-square and largest vertex
/// distance in mean edge lengths, beside the iteration's update (what the
/// convergence test reads) and the coarse iterations it ran (a correction).
/// Shows which part of a solve reduces which error: a convergence test on
/// the update stops where the iteration moves slowly, not where the pose
/// is near the minimum.
fn one_shot_trace(
    rest: &Arc<Rest>,
    factor: &Factor,
    c: &Constraints,
    setup: Setup,
    (star, e_star): (&[Point], f64),
) -> Result<Vec<serde_json::Value>, String> {
    let h = rest.mesh().mean_edge_length();
    let mut d = setup.deformer(rest);
    d.prepare_levels(factor, c);
    let mut rows = Vec::new();
    for k in 1..=setup.params.max_iters {
        let r = d.step(factor, c, 1).map_err(|e| e.to_string())?;
        let (rms, max) = distance_to(d.pose(), star, h);
        rows.push(serde_json::json!({
            "iteration": k,
            "excess": (r.objective - e_star) / e_star.abs(),
            "rms": rms,
            "max": max,
            "update": r.last_update,
            "coarse_iterations": r.coarse_iterations,
        }));
        if r.converged || r.diverged || r.iterations == 0 {
            break;
        }
    }
    Ok(rows)
}

/// The root-mean-square and the largest distance of `pose`'s vertices to
/// `star`'s, in units of `h`.
fn distance_to(pose: &[Point], star: &[Point], h: f64) -> (f64, f64) {
    let d2: Vec<f64> = pose
        .iter()
        .zip(star)
        .map(|(p, q)| (0..3).map(|a| (p[a] - q[a]).powi(2)).sum())
        .collect();
    let rms = (d2.iter().sum::<f64>() / d2.len().max(1) as f64).sqrt() / h;
    let max = d2.iter().fold(0.0f64, |m, &x| m.max(x)).sqrt() / h;
    (rms, max)
}

/// The times of one sequence's worth of fine iterations (one level,
/// Anderson as set): iterations 2 to 12 of a one-level solve of `c` from
/// rest, one call each (the first, which spreads the handles' rotations,
/// is not counted). Their median is the unit work is reported in, which
/// does not depend on the host.
fn fine_iterations_ms(
    clock: &mut dend_testkit::FineIterationClock,
    factor: &Factor,
    c: &Constraints,
) -> Result<Vec<f64>, String> {
    (0..dend_testkit::FineIterationClock::PER_SEQUENCE)
        .map(|_| {
            clock
                .time(factor, c)
                .map(|t| t.as_secs_f64() * 1e3)
                .map_err(|e| e.to_string())
        })
        .collect()
}

fn bbox(mesh: &Mesh) -> (Point, Point) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in mesh.positions() {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}
