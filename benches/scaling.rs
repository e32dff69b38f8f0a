//! Whether the solver's work grows with the mesh: the time to convergence
//! of one edit at three resolutions of the same generated shape, in fine
//! iterations (docs/performance.md, "Commands": fine-iteration
//! equivalents). Run:
//! `cargo bench --bench scaling`.
//!
//! The shape is `dend_testkit::tube_of_size` at about 8k, 32k and 128k
//! vertices, the edit `dend_testkit::standard_edit` (the lowest 10 % in z
//! fixed, the highest 10 % moved by 0.15 of the diagonal and turned 30°).
//! For each resolution and each of [`Levels::Two`] and [`Levels::Many`]
//! (the default), criterion times one fine iteration (one of the 2nd to
//! 12th of a one-level sequence from rest, `dend_testkit::FineIterationClock`,
//! the unit `examples/drag_sim.rs` reports in too) and the solve from rest
//! to convergence. Three fine iterations are also timed before each solve
//! (outside criterion's timing): the equivalents are the solves' median
//! over theirs, so that both are measured in the same seconds of a host
//! whose speed drifts. stderr gets the medians and their ratio, the
//! fine-iteration equivalents, which should stay flat across the three
//! resolutions (the largest within 1.5× of the smallest).
//!
//! Environment: `DEND_BENCH_SIZES=8000,32000` to pick resolutions.

use std::cell::RefCell;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use dend::deform::{Deformer, Factor, Levels, Params, Rest};

/// Fine iterations timed beside each solve, the unit of its equivalents.
const UNIT_BESIDE_SOLVE: usize = 3;

fn sizes() -> Vec<usize> {
    std::env::var("DEND_BENCH_SIZES")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![8_000, 32_000, 128_000])
}

fn bench(c: &mut Criterion) {
    let params = Params::default();
    let mut rows = Vec::new();
    for n in sizes() {
        let mesh = dend_testkit::tube_of_size(n);
        let nv = mesh.num_vertices();
        let edit = dend_testkit::standard_edit(&mesh);
        let rest = Arc::new(Rest::new(mesh).expect("rest"));
        let factor = Factor::build(&rest, &params, &edit).expect("factor");
        let mut g = c.benchmark_group(format!("tube_{}k", n / 1000));
        g.sample_size(10);
        g.warm_up_time(Duration::from_millis(200));
        g.measurement_time(Duration::from_secs(if nv > 60_000 { 20 } else { 5 }));
        let iteration = RefCell::new(Vec::new());
        g.bench_function(BenchmarkId::new("iteration", nv), |b| {
            let mut clock = dend_testkit::FineIterationClock::new(rest.clone(), params);
            b.iter_custom(|iters| {
                let mut total = Duration::ZERO;
                for _ in 0..iters {
                    let dt = clock.time(&factor, &edit).expect("step");
                    iteration.borrow_mut().push(dt);
                    total += dt;
                }
                total
            })
        });
        let fine = dend_testkit::median(
            iteration
                .borrow()
                .iter()
                .map(Duration::as_secs_f64)
                .collect(),
        );
        for (name, levels) in [("two", Levels::Two), ("many", Levels::Many)] {
            let solves = RefCell::new(Vec::new());
            // the unit timed beside each solve (untimed by criterion): the
            // host's speed drifts by 15-20 % over the seconds between the
            // iteration's samples and the solves', and a ratio of medians
            // taken apart inherits that drift
            let beside = RefCell::new(Vec::new());
            let report = RefCell::new(None);
            g.bench_function(BenchmarkId::new(format!("converge_{name}"), nv), |b| {
                let mut d = Deformer::new(rest.clone(), params);
                d.set_levels(levels);
                let mut clock = dend_testkit::FineIterationClock::new(rest.clone(), params);
                b.iter_custom(|iters| {
                    let mut total = Duration::ZERO;
                    for _ in 0..iters {
                        for _ in 0..UNIT_BESIDE_SOLVE {
                            let dt = clock.time(&factor, &edit).expect("step");
                            beside.borrow_mut().push(dt.as_secs_f64());
                        }
                        d.reset();
                        let t = Instant::now();
                        let r = d.step(&factor, &edit, 200).expect("step");
                        let dt = t.elapsed();
                        solves.borrow_mut().push(dt);
                        total += dt;
                        *report.borrow_mut() = Some(r);
                    }
                    total
                })
            });
            let unit = dend_testkit::median(beside.borrow().clone());
            let solve =
                dend_testkit::median(solves.borrow().iter().map(Duration::as_secs_f64).collect());
            let r = (*report.borrow()).expect("a solve ran");
            rows.push(format!(
                "{nv:>7} vertices, {name:>4} levels: fine iteration {:.2} ms ({:.2} ms beside \
                 the solves), solve {:.1} ms = {:.1} fine-iteration equivalents ({} fine \
                 iterations, {:.1} coarse work, converged {})",
                fine * 1e3,
                unit * 1e3,
                solve * 1e3,
                solve / unit,
                r.iterations,
                r.coarse_work,
                r.converged
            ));
        }
        g.finish();
    }
    for row in rows {
        eprintln!("{row}");
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
