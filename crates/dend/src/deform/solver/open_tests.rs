//! The elastic iteration on irregular open patches and on the generated
//! creature: its path does not depend on the unit of length,
//! and open surfaces converge as fast as closed ones.

use std::sync::Arc;

use super::test_util::{max_dist, patch_edit, scaled};
use crate::deform::{Constraints, Deformer, Factor, Levels, Params, Rest, StepReport};
use crate::mesh::gen::{
    creature_constraints, generate, irregular_patch, PatchSurface, Shape, ShapeSpec,
};
use crate::mesh::{Mesh, Point, Real};

/// Runs the default parameters' edit from rest on `mesh` scaled by `s`,
/// on the fine level only; returns the report and the pose divided by `s`.
fn run_scaled(mesh: &Mesh, s: Real, params: Params) -> (StepReport, Vec<Point>) {
    run_scaled_with(mesh, s, params, |d, f, c| d.step(f, c, 300).unwrap())
}

/// [`run_scaled`] with the solve given: `solve` runs on the fine-level
/// deformer, the factor and the edit's constraints.
fn run_scaled_with(
    mesh: &Mesh,
    s: Real,
    params: Params,
    solve: impl FnOnce(&mut Deformer, &Factor, &Constraints) -> StepReport,
) -> (StepReport, Vec<Point>) {
    let m = scaled(mesh, s);
    let rest = Arc::new(Rest::new(m.clone()).unwrap());
    let c = patch_edit(&m, s);
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    d.set_levels(Levels::One);
    let rep = solve(&mut d, &f, &c);
    let pose = d
        .pose()
        .iter()
        .map(|p| [p[0] / s, p[1] / s, p[2] / s])
        .collect();
    (rep, pose)
}

/// The fine iteration's path does not depend on the unit of length: on
/// irregular open patches (obtuse and skinny triangles, free boundary),
/// the same edit on the mesh scaled by 37 and by 1/37 takes the same
/// iterations and gives the pose scaled, to 1e-9 of the diagonal, at the
/// default tolerance, so every decision of the loop (the convergence
/// test, the acceleration's safeguard) is exercised.
///
/// On the fine level only here; the levels' own independence of the unit
/// (the simplification is fed the mesh divided by its largest side, and a
/// collapse that pinches two sheets is locked and run again:
/// `coarse/simplify.rs`) is tested in `solver/hierarchy_tests.rs`.
///
/// Not here: testkit's random Delaunay discs, whose hull slivers (boundary
/// edges 5× the mean, cotangent weights −11 and +92) leave the energy nearly
/// flat along some directions. There the accelerated iteration amplifies the
/// last-bit differences of the scaled input about tenfold every five
/// iterations (1e-13 relative at the first, 1e-3 by the 76th) with every
/// accept/reject decision the same; without Anderson the poses stay within
/// 1.3e-9 of the diagonal after 300 iterations. The poses end 1e-6 to
/// 6e-3 of the diagonal apart (700 vertices: 80 iterations at every scale;
/// 1500: 124 at scale 1, 154 and 161 at 37 and 1/37): where the iteration
/// crawls, its last update (what the tolerance bounds) is far smaller than
/// its distance from the minimum.
#[test]
fn the_fine_iteration_path_does_not_depend_on_the_unit_of_length() {
    let mut failures = Vec::new();
    for (surface, n, jitter, seed) in [
        (PatchSurface::Saddle, 24, 0.4, 3),
        (PatchSurface::Wavy, 26, 0.45, 4),
        (PatchSurface::Saddle, 40, 0.4, 17),
        (PatchSurface::Wavy, 45, 0.45, 8),
    ] {
        let mesh = irregular_patch(surface, n, jitter, seed);
        let params = Params::default();
        let (base, p1) = run_scaled(&mesh, 1.0, params);
        assert!(base.converged, "{surface:?} {n}: {base:?}");
        for s in [37.0, 1.0 / 37.0] {
            let (rep, ps) = run_scaled(&mesh, s, params);
            let gap = max_dist(&p1, &ps) / mesh.diagonal();
            let row = format!(
                "{surface:?} {n}² seed {seed}, scale {s:.4}: {}+{} iterations (fine+coarse) against {}+{}, pose gap {gap:.2e} of the diagonal",
                rep.iterations, rep.coarse_iterations, base.iterations, base.coarse_iterations
            );
            eprintln!("{row}");
            let same_path = (rep.iterations, rep.coarse_iterations)
                == (base.iterations, base.coarse_iterations);
            if !same_path || gap > 1e-9 {
                failures.push(row);
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The same on the generated creature, a closed mesh that is symmetric
/// left to right, on the fine level only (see above).
#[test]
fn the_creature_fine_path_does_not_depend_on_the_unit_of_length() {
    let mesh = generate(&ShapeSpec::default_for(Shape::Creature)).unwrap();
    let run = |s: Real| {
        let m = scaled(&mesh, s);
        let mut spec = creature_constraints(&m);
        spec.handles[0].translate = Some([0.0, 0.3 * s, 0.4 * s]);
        let c = spec.resolve(&m).unwrap();
        let params = Params::default();
        let rest = Arc::new(Rest::new(m).unwrap());
        let f = Factor::build(&rest, &params, &c).unwrap();
        let mut d = Deformer::new(rest, params);
        d.set_levels(Levels::One);
        let rep = d.step(&f, &c, 300).unwrap();
        let pose: Vec<Point> = d
            .pose()
            .iter()
            .map(|p| [p[0] / s, p[1] / s, p[2] / s])
            .collect();
        (rep, pose)
    };
    let (base, p1) = run(1.0);
    assert!(base.converged, "{base:?}");
    for s in [37.0, 1.0 / 37.0, 0.3] {
        let (rep, ps) = run(s);
        let gap = max_dist(&p1, &ps) / mesh.diagonal();
        assert_eq!(
            (rep.iterations, rep.coarse_iterations),
            (base.iterations, base.coarse_iterations),
            "scale {s}: a different path"
        );
        assert!(gap <= 1e-9, "scale {s}: pose gap {gap:e}");
    }
}

/// Open surfaces converge as fast as closed ones: on the saddle and the
/// wavy sheet (obtuse and skinny triangles, a free boundary; `dend gen
/// saddle` and `wavy-sheet`, 2025 vertices, and another draw of 1600, so
/// with a coarse level), the default parameters converge on
/// the representative edit ([`patch_edit`]: one side fixed, the other
/// lifted and turned 52°) within 30 iterations, run one iteration per
/// step as a settle loop does, and the objective never grows.
#[test]
fn open_patches_converge_within_30_iterations() {
    for (surface, shape) in [
        (PatchSurface::Saddle, Shape::Saddle),
        (PatchSurface::Wavy, Shape::WavySheet),
    ] {
        // `dend gen saddle` / `wavy-sheet` (45², seed 1) and another draw
        for (n, seed) in [(45, 1), (40, 2)] {
            let mesh = if (n, seed) == (45, 1) {
                generate(&ShapeSpec::default_for(shape)).unwrap()
            } else {
                irregular_patch(surface, n, 0.4, seed)
            };
            let params = Params::default();
            let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
            let c = patch_edit(&mesh, 1.0);
            let f = Factor::build(&rest, &params, &c).unwrap();
            let mut d = Deformer::new(rest, params);
            let mut objective = Vec::new();
            let mut iterations = 0;
            let mut converged = false;
            while iterations < 60 && !converged {
                let r = d.step(&f, &c, 1).unwrap();
                assert!(!r.diverged, "{surface:?} {n}: {r:?}");
                if objective.is_empty() {
                    objective.push(r.initial_objective);
                }
                objective.push(r.objective);
                iterations += r.iterations;
                converged = r.converged;
            }
            eprintln!("{surface:?} {n}² seed {seed}: {iterations} iterations");
            assert!(converged, "{surface:?} {n}²: not converged in 60");
            assert!(
                iterations <= 30,
                "{surface:?} {n}² seed {seed}: {iterations} iterations"
            );
            for (k, w) in objective.windows(2).enumerate() {
                assert!(
                    w[1] <= w[0] * (1.0 + 1e-12),
                    "{surface:?} {n}²: the objective grew at iteration {k}: {} -> {}",
                    w[0],
                    w[1]
                );
            }
        }
    }
}

/// The stalled solve of a slow coarse problem's correction
/// (`multilevel::solve_until_stalled`) runs the same iterates as one
/// `step` call of as many iterations (its chunks continue one sequence),
/// never raises the objective, and decides when to stop by a ratio of
/// energies: the patch scaled by 37 stops after the same iterations at
/// the same pose.
#[test]
fn a_stalled_coarse_solve_is_one_sequence_cut_short_by_a_unit_free_rule() {
    use super::multilevel::{solve_until_stalled, CORRECTION_MAX_ITERS, CORRECTION_STALL};
    // an irregular open patch whose iteration crawls (tens of iterations
    // at the default tolerance): where a stall rule has something to cut
    let mesh = irregular_patch(PatchSurface::Saddle, 40, 0.4, 17);
    let params = Params::default();
    let run = |s: Real, stalled: bool, budget: usize| {
        run_scaled_with(&mesh, s, params, |d, f, c| {
            if stalled {
                solve_until_stalled(d, f, c).unwrap()
            } else {
                d.step(f, c, budget).unwrap()
            }
        })
    };
    let (cut, cut_pose) = run(1.0, true, 0);
    let (full, _) = run(1.0, false, CORRECTION_MAX_ITERS);
    eprintln!(
        "stalled solve: {} iterations (converged {}), objective {:.6e}; one call: {} iterations, objective {:.6e}",
        cut.iterations, cut.converged, cut.objective, full.iterations, full.objective
    );
    assert!(cut.iterations > 0 && cut.iterations <= CORRECTION_MAX_ITERS);
    assert!(cut.objective <= cut.initial_objective, "{cut:?}");
    // stopped by the rule (or converged): the stall rule had to act on
    // this patch for the test to mean anything
    assert!(
        cut.converged || cut.iterations < full.iterations,
        "the stall rule never acted: {} against {} iterations",
        cut.iterations,
        full.iterations
    );
    // the same iterates as one call of as many iterations
    let (same, same_pose) = run(1.0, false, cut.iterations);
    assert_eq!(same.iterations, cut.iterations);
    let gap = max_dist(&cut_pose, &same_pose) / mesh.diagonal();
    assert!(
        gap < 1e-12,
        "chunks and one call differ by {gap:.2e} of the diagonal"
    );
    // a ratio of energies: the unit of length does not move the stop
    for s in [37.0, 1.0 / 37.0] {
        let (rep, pose) = run(s, true, 0);
        let gap = max_dist(&cut_pose, &pose) / mesh.diagonal();
        assert_eq!(
            rep.iterations, cut.iterations,
            "scale {s}: {} iterations against {} (stall share {CORRECTION_STALL})",
            rep.iterations, cut.iterations
        );
        assert!(
            gap < 1e-9,
            "scale {s}: poses {gap:.2e} of the diagonal apart"
        );
    }
}

/// A step with a drift limit (`Deformer::drift_limit`, which a
/// correction's coarse solve gets: `multilevel::CORRECTION_DRIFT`) stops
/// right after its update has grown that many iterations in a row, at the
/// iterates of an unlimited run cut there; the rule compares updates with
/// each other, so the patch scaled by 37 stops at the same iteration and
/// pose.
#[test]
fn a_drifting_solve_stops_once_its_update_has_grown_k_times_in_a_row() {
    // an irregular open patch whose iteration crawls, one level: its
    // updates rise now and then before they fall
    let mesh = irregular_patch(PatchSurface::Saddle, 40, 0.4, 17);
    let params = Params::default();
    // every update of the unlimited sequence (one-iteration calls
    // continue it)
    let mut updates = Vec::new();
    run_scaled_with(&mesh, 1.0, params, |d, f, c| loop {
        let r = d.step(f, c, 1).unwrap();
        updates.push(r.last_update);
        if r.converged || updates.len() >= 300 {
            break r;
        }
    });
    // the first iteration where the update has grown k times in a row
    let first_run_of = |k: usize| {
        let mut grew = 0;
        (1..updates.len()).find(|&i| {
            grew = if updates[i] > updates[i - 1] {
                grew + 1
            } else {
                0
            };
            grew >= k
        })
    };
    let k = (2..=4).rev().find(|&k| first_run_of(k).is_some());
    let Some(k) = k else {
        panic!("no update grows twice in a row on this patch ({updates:?}): the test needs one that does");
    };
    let stop = first_run_of(k).unwrap() + 1;
    eprintln!(
        "{} iterations unlimited; updates grow {k} times in a row by iteration {stop}",
        updates.len()
    );
    let limited = |s: Real| {
        run_scaled_with(&mesh, s, params, |d, f, c| {
            d.drift_limit = Some(k);
            d.step(f, c, 300).unwrap()
        })
    };
    let (cut, cut_pose) = limited(1.0);
    assert_eq!(cut.iterations, stop, "{cut:?}");
    assert!(!cut.converged);
    let (same, same_pose) =
        run_scaled_with(&mesh, 1.0, params, |d, f, c| d.step(f, c, stop).unwrap());
    assert_eq!(same.iterations, stop);
    let gap = max_dist(&cut_pose, &same_pose) / mesh.diagonal();
    assert!(
        gap < 1e-12,
        "cut and unlimited runs differ by {gap:.2e} of the diagonal"
    );
    for s in [37.0, 1.0 / 37.0] {
        let (rep, pose) = limited(s);
        assert_eq!(rep.iterations, stop, "scale {s}");
        let gap = max_dist(&cut_pose, &pose) / mesh.diagonal();
        assert!(
            gap < 1e-9,
            "scale {s}: poses {gap:.2e} of the diagonal apart"
        );
    }
}
