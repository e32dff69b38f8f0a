//! Prints JSON timings of dend on one mesh and one constraint set, for
//! `scripts/compare_arap.py` and the scaling table of `docs/performance.md`.
//!
//! ```text
//! cargo run --release --example dend_bench -- MESH [--sets FILE.json]
//!     [--iters 30] [--cg] [--subdivide K] [--write-sets FILE.json]
//!     [--write-mesh FILE.off] [--formulation elastic|least_squares|square|square_lu|both|all]
//!     [--precision double|single|both] [--rebuilds K]
//!     [--ordering auto|given|breadth_first]
//! ```
//!
//! MESH is a file (OFF/OBJ/PLY) or `tube:N` (a generated tube of about N
//! vertices). Without `--sets` the standard edit is used (lowest 10 % of the
//! vertices in z fixed, highest 10 % translated by 0.15·diagonal along x and
//! rotated 30° about y); `--write-sets` saves it as
//! `{"fixed": [...], "handle": [...], "handle_target": [[x,y,z], ...]}`
//! so that libigl runs on exactly the same sets and targets. `--sets` reads
//! that format back.
//!
//! Reported (milliseconds, medians over `--iters` repetitions where noted):
//! `rest` (operators + STEP 1), `assembly`/`symbolic`/`numeric` (one factor
//! build), `iteration` (median of one-iteration steps, chained from the rest
//! pose towards the target), `converge` (a full solve from rest, the
//! second of two: the first builds the coarse level), and with
//! `--cg` the same iteration with Jacobi-PCG at tolerance 1e-4 and no factor.
//! `--rebuilds K` builds the factor K more times in the same process and
//! reports the medians as `warm_*` (the first build pays for page faults and
//! thread start-up; a server building a new constraint set's factor is warm),
//! and `warm_precompute_ms`, the median of K new `Rest`s with their first
//! factor in the same process (a server receiving a new upload).
//! `--formulation both` measures eq. (24) and eq. (23) in the same process and
//! prints one JSON line each, then a line of square / least-squares ratios;
//! `--precision both` likewise the factor stored in `f64` (the default) and
//! in `f32`, with the ratios of the second over the first. `--ordering`
//! picks the solver's vertex order (`Rest::with_ordering`; default `auto`).

use std::sync::Arc;
use std::time::Instant;

use dend::deform::{
    Constraints, Deformer, Factor, FactorPrecision, Formulation, Params, Rest, RigidTransform,
    SolveOptions, SolverChoice, StepReport, VertexOrdering,
};
use dend::mesh::{Mesh, Point};

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}

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
    dend::mesh::io::read_path(std::path::Path::new(spec)).map_err(|e| e.to_string())
}

fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let spec = args.first().ok_or("usage: dend_bench MESH [options]")?;
    let mut mesh = load(spec)?;
    for _ in 0..arg::<usize>(&args, "--subdivide").unwrap_or(0) {
        mesh = dend_testkit::subdivide(&mesh);
    }
    let iters: usize = arg(&args, "--iters").unwrap_or(30);
    let with_cg = args.iter().any(|a| a == "--cg");
    let rebuilds: usize = arg(&args, "--rebuilds").unwrap_or(0);
    let constraints = match arg::<String>(&args, "--sets") {
        Some(path) => read_sets(&mesh, &path)?,
        None => dend_testkit::standard_edit(&mesh),
    };
    if let Some(path) = arg::<String>(&args, "--write-mesh") {
        dend::mesh::io::write_path(std::path::Path::new(&path), &mesh)
            .map_err(|e| e.to_string())?;
    }
    if let Some(path) = arg::<String>(&args, "--write-sets") {
        write_sets(&constraints, &path)?;
    }
    let t = Instant::now();
    let ordering = match arg::<String>(&args, "--ordering").as_deref() {
        None | Some("auto") => VertexOrdering::Auto,
        Some("given") => VertexOrdering::AsGiven,
        Some("breadth_first") => VertexOrdering::BreadthFirst,
        Some(o) => return Err(format!("--ordering {o}: auto, given or breadth_first")),
    };
    let rest = Arc::new(Rest::with_ordering(mesh.clone(), ordering).map_err(|e| e.to_string())?);
    let rest_ms = ms(t.elapsed());
    let which = arg::<String>(&args, "--formulation").unwrap_or("elastic".into());
    let formulations = match which.as_str() {
        "both" => vec![Formulation::LeastSquares, Formulation::Square],
        "all" => vec![
            Formulation::LeastSquares,
            Formulation::Square,
            Formulation::SquareLu,
            Formulation::Elastic,
        ],
        name => vec![Formulation::from_name(name).ok_or(format!("bad formulation {name:?}"))?],
    };
    let precisions = match arg::<String>(&args, "--precision").as_deref() {
        None => vec![FactorPrecision::default()],
        Some("both") => vec![FactorPrecision::Double, FactorPrecision::Single],
        Some(p) => vec![p.parse()?],
    };
    let mut lines = Vec::new();
    for formulation in formulations {
        for &precision in &precisions {
            let params = Params::default().with_formulation(formulation);
            let out = bench(
                spec,
                &mesh,
                &rest,
                rest_ms,
                &params,
                precision,
                &constraints,
                iters,
                with_cg,
                rebuilds,
            )?;
            println!("{out}");
            lines.push(out);
        }
    }
    for sq in lines.iter().skip(1) {
        let ls = &lines[0];
        let ratio =
            |k: &str| sq[k].as_f64().unwrap_or(f64::NAN) / ls[k].as_f64().unwrap_or(f64::NAN);
        let keys = [
            "factor_nnz",
            "symbolic_ms",
            "numeric_ms",
            "precompute_ms",
            "iteration_ms",
            "converge_ms",
            "converge_iterations",
            "session_bytes",
        ];
        let ratios: serde_json::Map<String, serde_json::Value> = keys
            .iter()
            .map(|&k| (k.to_string(), ratio(k).into()))
            .collect();
        let name = format!(
            "{}_{}_over_{}_{}",
            sq["formulation"].as_str().unwrap_or("?"),
            sq["precision"].as_str().unwrap_or("?"),
            lines[0]["formulation"].as_str().unwrap_or("?"),
            lines[0]["precision"].as_str().unwrap_or("?"),
        );
        println!("{}", serde_json::json!({ name: ratios }));
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn bench(
    spec: &str,
    mesh: &Mesh,
    rest: &Arc<Rest>,
    rest_ms: f64,
    params: &Params,
    precision: FactorPrecision,
    constraints: &Constraints,
    iters: usize,
    with_cg: bool,
    rebuilds: usize,
) -> Result<serde_json::Value, String> {
    let params = *params;
    let direct = SolveOptions {
        solver: SolverChoice::Direct,
        precision,
        ..SolveOptions::default()
    };
    let rss0 = rss_bytes();
    let t = Instant::now();
    let factor =
        Factor::build_with(rest, &params, constraints, &direct).map_err(|e| e.to_string())?;
    let build_ms = ms(t.elapsed());
    let rss_growth = rss_bytes().saturating_sub(rss0);
    let ft = factor.timings();
    let mut warm: [Vec<f64>; 4] = Default::default();
    for _ in 0..rebuilds {
        let t = Instant::now();
        let again =
            Factor::build_with(rest, &params, constraints, &direct).map_err(|e| e.to_string())?;
        let total = ms(t.elapsed());
        let at = again.timings();
        for (w, v) in warm
            .iter_mut()
            .zip([ms(at.assembly), ms(at.symbolic), ms(at.numeric), total])
        {
            w.push(v);
        }
    }
    let [warm_assembly, warm_symbolic, warm_numeric, warm_build] = warm.map(dend_testkit::median);
    // a new upload in a warm process (a server's case): the rest
    // precomputation and the first factor of a new `Rest`, whose energy
    // matrix is not cached yet
    let mut warm_precompute = Vec::new();
    for _ in 0..rebuilds {
        let t = Instant::now();
        let ordering = match rest.vertex_order() {
            Some(_) => VertexOrdering::BreadthFirst,
            None => VertexOrdering::AsGiven,
        };
        let fresh = Rest::with_ordering(mesh.clone(), ordering).map_err(|e| e.to_string())?;
        let again =
            Factor::build_with(&fresh, &params, constraints, &direct).map_err(|e| e.to_string())?;
        warm_precompute.push(ms(t.elapsed()));
        drop(again);
    }
    let warm_precompute = dend_testkit::median(warm_precompute);
    let (iteration, converge, report) =
        time_iterations(rest, &params, &factor, constraints, iters)?;
    let n = mesh.num_vertices();
    let mut out = serde_json::json!({
        "mesh": spec,
        "formulation": params.formulation.kind(),
        "precision": precision,
        "vertices": n,
        "unknowns": factor.num_unknowns(),
        "threads": rayon::current_num_threads(),
        "rest_ms": rest_ms,
        "assembly_ms": ms(ft.assembly),
        "symbolic_ms": ms(ft.symbolic),
        "numeric_ms": ms(ft.numeric),
        "factor_build_ms": build_ms,
        "precompute_ms": rest_ms + build_ms,
        "warm_assembly_ms": warm_assembly,
        "warm_symbolic_ms": warm_symbolic,
        "warm_numeric_ms": warm_numeric,
        "warm_factor_build_ms": warm_build,
        "warm_precompute_ms": warm_precompute,
        "iteration_ms": iteration,
        "converge_ms": converge,
        "converge_iterations": report.iterations,
        "converge_coarse_iterations": report.coarse_iterations,
        "converge_coarse_ms": report.coarse_ms,
        "converged": report.converged,
        "factor_nnz": factor.factor_nnz(),
        "factor_bytes": factor.factor_bytes(),
        "factor_gflop": factor.factor_flops() / 1e9,
        "session_bytes": factor.memory_bytes(),
        "rss_growth_bytes": rss_growth,
        "bytes_per_vertex": factor.memory_bytes() as f64 / n as f64,
    });
    if with_cg {
        let cg_opts = SolveOptions {
            solver: SolverChoice::Cg,
            ..SolveOptions::default()
        };
        let t = Instant::now();
        let cg =
            Factor::build_with(rest, &params, constraints, &cg_opts).map_err(|e| e.to_string())?;
        let cg_build = ms(t.elapsed());
        let before = cg.cg_iterations();
        let cg_iters = iters.min(3);
        let (it, _, conv) = time_iterations(rest, &params, &cg, constraints, cg_iters)?;
        // one 3-column solve per iteration: 2 warm-up, the timed ones, and
        // the full solve that `time_iterations` ends with
        let solves = 2 + cg_iters + conv.iterations;
        let per_solve = (cg.cg_iterations() - before) as f64 / solves as f64 / 3.0;
        out["cg_build_ms"] = cg_build.into();
        out["cg_iteration_ms"] = it.into();
        out["cg_iterations_per_column"] = per_solve.into();
    }
    Ok(out)
}

/// Median time of one-iteration steps chained from rest (as an interactive
/// drag does), and the time and count of a full solve from rest.
fn time_iterations(
    rest: &Arc<Rest>,
    params: &Params,
    factor: &Factor,
    constraints: &Constraints,
    iters: usize,
) -> Result<(f64, f64, StepReport), String> {
    let params = *params;
    let mut d = Deformer::new(rest.clone(), params);
    d.step(factor, constraints, 2).map_err(|e| e.to_string())?;
    let mut times = Vec::with_capacity(iters);
    for _ in 0..iters {
        let t = Instant::now();
        d.step(factor, constraints, 1).map_err(|e| e.to_string())?;
        times.push(ms(t.elapsed()));
    }
    // twice: the first pays for the coarse level and its factor (which a
    // server builds when a mesh or constraint set arrives)
    let mut last = None;
    for _ in 0..2 {
        d.reset();
        let t = Instant::now();
        let r = d
            .step(factor, constraints, params.max_iters)
            .map_err(|e| e.to_string())?;
        last = Some((ms(t.elapsed()), r));
    }
    let (converge, r) = last.expect("two runs");
    Ok((dend_testkit::median(times), converge, r))
}

/// Resident set size (Linux `/proc/self/statm`), 0 elsewhere: the growth
/// around a factor build measures the LU, whose size faer does not expose.
fn rss_bytes() -> usize {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1)?.parse::<usize>().ok())
        .map_or(0, |pages| pages * 4096)
}

fn write_sets(c: &Constraints, path: &str) -> Result<(), String> {
    let h = &c.handles[0];
    let targets: Vec<Point> = h.target_positions().map(|(_, p)| p).collect();
    let json = serde_json::json!({
        "fixed": c.fixed,
        "handle": h.vertices,
        "handle_target": targets,
    });
    std::fs::write(path, json.to_string()).map_err(|e| format!("{path}: {e}"))
}

fn read_sets(mesh: &Mesh, path: &str) -> Result<Constraints, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| e.to_string())?;
    let ids = |k: &str| -> Vec<u32> {
        v[k].as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|x| x.as_u64())
                    .map(|x| x as u32)
                    .collect()
            })
            .unwrap_or_default()
    };
    let (fixed, handle) = (ids("fixed"), ids("handle"));
    let targets: Vec<Point> = serde_json::from_value(v["handle_target"].clone())
        .map_err(|e| format!("{path}: handle_target: {e}"))?;
    let mut c = Constraints::new(
        mesh,
        fixed,
        vec![(
            "handle".into(),
            handle,
            Some(RigidTransform::identity([0.0; 3])),
        )],
    )
    .map_err(|e| e.to_string())?;
    if targets.len() != c.handles[0].vertices.len() {
        return Err(format!("{path}: handle_target has the wrong length"));
    }
    c.handles[0].base = targets;
    Ok(c)
}
