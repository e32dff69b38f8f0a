//! Criterion benchmarks of every stage of a DEND session over meshes of
//! growing size (docs/performance.md). Run: `cargo bench --bench dend`.
//!
//! Stages per mesh: operator assembly (`Operators::new`), `Rest::new`
//! (operators + STEP 1 μ), assembly of `M`, symbolic analysis (AMD), numeric
//! Cholesky, one DEND iteration (STEP 2 + local rotations + 3-RHS solve +
//! the safeguard's objective evaluation), and convergence of the standard
//! edit (lowest 10 % in z fixed, highest 10 % moved and rotated; see
//! `dend_testkit::standard_edit`). Factor nonzeros and bytes per vertex are
//! printed on stderr (criterion measures time only).
//!
//! Environment:
//! - `DEND_MESHES`: the shared meshes folder (default `../shared/meshes`);
//!   absent meshes are skipped (`dend_testkit::shared_mesh`).
//! - `DEND_BENCH_LARGE=1`: also the ~540k-vertex subdivided igea and
//!   convergence on meshes above 60k vertices (slow: minutes).
//! - `DEND_BENCH_ONLY=name1,name2`: only these meshes.

use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use dend::deform::{Constraints, Deformer, Factor, Params, Rest};
use dend::mesh::Mesh;
use dend::operators::Operators;

fn meshes() -> Vec<(String, Mesh)> {
    let large = std::env::var_os("DEND_BENCH_LARGE").is_some();
    let only: Option<Vec<String>> = std::env::var("DEND_BENCH_ONLY")
        .ok()
        .map(|s| s.split(',').map(str::to_owned).collect());
    let wanted = |name: &str| only.as_ref().is_none_or(|o| o.iter().any(|w| w == name));
    let mut out = Vec::new();
    for n in [2_000, 8_000, 32_000] {
        let name = format!("tube_{}k", n / 1000);
        if wanted(&name) {
            out.push((name, dend_testkit::tube_of_size(n)));
        }
    }
    for file in [
        "camel_9770.off",
        "armadillo_43k.obj",
        "feline_50k.off",
        "igea_134k.ply",
    ] {
        let name = file.rsplit_once('.').map_or(file, |(s, _)| s).to_owned();
        if wanted(&name) {
            if let Some(m) = dend_testkit::shared_mesh(file) {
                out.push((name, m));
            }
        }
    }
    if large && wanted("igea_sub_537k") {
        if let Some(m) = dend_testkit::shared_mesh("igea_134k.ply") {
            out.push(("igea_sub_537k".into(), dend_testkit::subdivide(&m)));
        }
    }
    out
}

fn configure<'a>(
    c: &'a mut Criterion,
    name: &str,
    n: usize,
) -> criterion::BenchmarkGroup<'a, criterion::measurement::WallTime> {
    let mut g = c.benchmark_group(name.to_owned());
    g.sample_size(10);
    g.warm_up_time(Duration::from_millis(if n > 60_000 { 100 } else { 500 }));
    g.measurement_time(Duration::from_secs(if n > 60_000 { 5 } else { 2 }));
    g
}

fn bench(c: &mut Criterion) {
    let large = std::env::var_os("DEND_BENCH_LARGE").is_some();
    let params = Params::default();
    for (name, mesh) in meshes() {
        let n = mesh.num_vertices();
        let constraints = dend_testkit::standard_edit(&mesh);
        let rest = Arc::new(Rest::new(mesh.clone()).expect("rest"));
        let factor = Factor::build(&rest, &params, &constraints).expect("factor");
        eprintln!(
            "{name}: {n} vertices, {} unknowns, factor nnz {} ({:.1} per unknown), \
             factor bytes {}, session bytes {} ({:.0} B/vertex)",
            factor.num_unknowns(),
            factor.factor_nnz(),
            factor.factor_nnz() as f64 / factor.num_unknowns() as f64,
            factor.factor_bytes(),
            factor.memory_bytes(),
            factor.memory_bytes() as f64 / n as f64,
        );
        let mut g = configure(c, &name, n);
        g.bench_function(BenchmarkId::new("operators", n), |b| {
            b.iter(|| Operators::new(&mesh))
        });
        g.bench_function(BenchmarkId::new("rest_mu", n), |b| {
            b.iter(|| Rest::new(mesh.clone()).expect("rest"))
        });
        let stage = |pick: fn(&Factor) -> Duration| {
            let (rest, params, constraints) = (&rest, &params, &constraints);
            move |b: &mut criterion::Bencher| {
                b.iter_custom(|iters| {
                    (0..iters)
                        .map(|_| pick(&Factor::build(rest, params, constraints).expect("factor")))
                        .sum()
                })
            }
        };
        g.bench_function(
            BenchmarkId::new("assemble_m", n),
            stage(|f| f.timings().assembly),
        );
        g.bench_function(
            BenchmarkId::new("symbolic", n),
            stage(|f| f.timings().symbolic),
        );
        g.bench_function(
            BenchmarkId::new("numeric", n),
            stage(|f| f.timings().numeric),
        );
        g.bench_function(BenchmarkId::new("iteration", n), |b| {
            let mut d = Deformer::new(rest.clone(), params);
            // Start from a deformed pose so that the iteration does real work.
            d.step(&factor, &constraints, 2).expect("step");
            b.iter(|| d.step(&factor, &constraints, 1).expect("step"))
        });
        if n <= 60_000 || large {
            g.bench_function(BenchmarkId::new("converge", n), |b| {
                let mut d = Deformer::new(rest.clone(), params);
                b.iter_custom(|iters| converge(&mut d, &factor, &constraints, iters))
            });
        }
        g.finish();
    }
}

fn converge(d: &mut Deformer, factor: &Factor, constraints: &Constraints, iters: u64) -> Duration {
    let mut total = Duration::ZERO;
    for _ in 0..iters {
        d.reset();
        let t = Instant::now();
        let r = d.step(factor, constraints, 200).expect("step");
        total += t.elapsed();
        std::hint::black_box(r);
    }
    total
}

criterion_group!(benches, bench);
criterion_main!(benches);
