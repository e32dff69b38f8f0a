//! The Newton iteration's matrix and steps (`solver/newton.rs`): the
//! matrix written into its analysed pattern is the one summed from its
//! terms, symmetric and positive semi-definite at any rotations, and
//! Newton steps reach the minimum the local/global iteration reaches.

use std::sync::Arc;

use nalgebra::{DMatrix, UnitQuaternion, Vector3};

use super::newton_state::NewtonPattern;
use super::test_util::{assert_same_symmetric_semidefinite, dense, max_dist, patch_edit};
use crate::deform::elastic::hessian::blocks::each_block;
use crate::deform::elastic::hessian::Curvature;
use crate::deform::{Constraints, Deformer, Factor, Params, Rest, RigidTransform};
use crate::mesh::gen::{irregular_patch, PatchSurface};
use crate::mesh::Real;

/// `H` as the pattern holds it (dense), and `H` summed from its terms
/// directly: `Q ⊗ I₃` plus every element block (and its transpose for a
/// pair), elements in order.
fn assembled_and_summed(
    d: &mut Deformer,
    f: &Factor,
    curvature: Curvature,
) -> (DMatrix<Real>, DMatrix<Real>) {
    let (el, set) = f.elastic.as_ref().unwrap();
    d.assemble_newton(f, (el, set), curvature, false).unwrap();
    let pattern = d.elastic.newton.pattern.as_ref().unwrap();
    (dense(&pattern.h), summed(f, pattern))
}

/// `Q ⊗ I₃` plus the pattern's element blocks, scattered one by one in
/// the elements' order.
fn summed(f: &Factor, pattern: &NewtonPattern) -> DMatrix<Real> {
    let n = pattern.h.rows();
    let mut summed = DMatrix::zeros(n, n);
    for (v, (r, c)) in f.sys.m.iter() {
        for a in 0..3 {
            summed[(3 * r + a, 3 * c + a)] += *v;
        }
    }
    each_block(&pattern.elements, &pattern.blocks, |k, l, b| {
        for r in 0..3 {
            for s in 0..3 {
                summed[(3 * k as usize + r, 3 * l as usize + s)] += b[(r, s)];
            }
        }
    });
    summed
}

#[test]
fn the_matrix_in_its_pattern_is_the_sum_of_its_terms_and_semi_definite() {
    let mesh = irregular_patch(PatchSurface::Saddle, 9, 0.4, 5);
    let c = patch_edit(&mesh, 1.0);
    let params = Params::default();
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    d.set_levels(super::Levels::One);
    // at the first rotations, then at the turned ones of a few iterations
    // (the pattern analysed once serves both)
    for its in [0, 4] {
        d.step(&f, &c, its).unwrap();
        let (held, summed) = assembled_and_summed(&mut d, &f, Curvature::Projected);
        assert_same_symmetric_semidefinite(&held, &summed, 1e-12, &format!("{its} iterations"));
    }
}

#[test]
fn newton_steps_reach_the_local_global_minimum_in_fewer_iterations() {
    // a far part turned 70° as a whole: the local/global iteration's slow
    // mode
    let mesh = irregular_patch(PatchSurface::Wavy, 14, 0.4, 3);
    let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -1.2);
    let c = super::test_util::x_edit(&mesh, -0.8, 0.8, [-0.5, 0.0, 0.6], r);
    let params = Params {
        tol: 1e-6,
        ..Params::default()
    };
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let solve = |newton: bool| {
        let mut d = Deformer::new(rest.clone(), params);
        d.set_levels(super::Levels::One);
        d.newton = newton;
        let r = d.step(&f, &c, 2000).unwrap();
        assert!(r.converged, "newton {newton}: {r:?}");
        (r, d.pose().to_vec())
    };
    let (plain, plain_pose) = solve(false);
    let (newton, newton_pose) = solve(true);
    eprintln!(
        "{} Newton against {} local/global iterations",
        newton.iterations, plain.iterations
    );
    let rel = (newton.objective - plain.objective).abs() / plain.objective;
    assert!(
        rel < 1e-6,
        "objectives {} and {}",
        newton.objective,
        plain.objective
    );
    let gap = max_dist(&newton_pose, &plain_pose);
    assert!(gap < 1e-3, "poses {gap} apart");
    assert!(
        newton.iterations < plain.iterations,
        "{} Newton against {} local/global iterations",
        newton.iterations,
        plain.iterations
    );
}

/// The local/global map after a Newton trial
/// (`Deformer::global_step_from_trial`): from trial poses near and far
/// from the current one, the pose it leaves has at most the trial's
/// energy, and its energy is that of the pose and rotations it leaves (a
/// local step from scratch there gives the same).
#[test]
fn the_global_step_after_a_trial_never_raises_its_energy() {
    let mesh = irregular_patch(PatchSurface::Wavy, 9, 0.4, 3);
    let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -0.8);
    let c = super::test_util::x_edit(&mesh, -0.8, 0.8, [-0.5, 0.0, 0.6], r);
    let params = Params::default();
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let (el, set) = f.elastic.as_ref().unwrap();
    let mut d = Deformer::new(rest, params);
    d.set_levels(super::Levels::One);
    d.step(&f, &c, 3).unwrap();
    let nu = f.sys.unknowns.len();
    let base: Vec<_> = f.sys.unknowns.iter().map(|&u| d.y[u as usize]).collect();
    for scale in [0.0, 0.01, 0.1, 0.5] {
        // a smooth field that bends and stretches the free part
        for (k, p) in base.iter().enumerate() {
            let w = [(3.0 * p[0]).sin(), (2.0 * p[1]).cos(), p[0] * p[1]];
            for a in 0..3 {
                d.elastic.cand[a * nu + k] = p[a] + scale * w[a];
            }
        }
        d.set_unknowns(&f, super::local_global::Flat::Candidate);
        let e_try = d.local_step(&f, (el, set), true, true);
        let e_g = d.global_step_from_trial(&f, (el, set)).unwrap();
        let e_again = d.local_step(&f, (el, set), true, false);
        let tol = 1e-9 * e_try.abs().max(1.0);
        assert!(
            e_g <= e_try + tol,
            "scale {scale}: {e_g} after the global step, {e_try} at the trial"
        );
        assert!(
            (e_again - e_g).abs() <= tol,
            "scale {scale}: {e_g} returned, {e_again} at the pose left"
        );
        if scale > 0.0 {
            assert!(
                e_g < e_try,
                "scale {scale}: nothing lowered ({e_g}, {e_try})"
            );
        }
    }
}

/// `H v` and the change of the reduced gradient along `v`, by central
/// differences (`r = −½ ∇E` at refitted rotations and area targets), at
/// the pose of a few iterations of an edit: their largest relative
/// difference over a few directions.
fn hessian_error(params: Params, curvature: Curvature) -> Real {
    let mesh = irregular_patch(PatchSurface::Wavy, 9, 0.4, 3);
    let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -0.8);
    let c = super::test_util::x_edit(&mesh, -0.8, 0.8, [-0.3, 0.0, 0.4], r);
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    d.set_levels(super::Levels::One);
    d.step(&f, &c, 6).unwrap();
    let (held, _) = assembled_and_summed(&mut d, &f, curvature);
    let (el, set) = f.elastic.as_ref().unwrap();
    let y0 = d.y.clone();
    let unknowns = f.sys.unknowns.clone();
    let n = 3 * unknowns.len();
    let gradient_at = |d: &mut Deformer, v: &[Real], h: Real| -> Vec<Real> {
        d.y.clone_from(&y0);
        for (k, &u) in unknowns.iter().enumerate() {
            for a in 0..3 {
                d.y[u as usize][a] += h * v[3 * k + a];
            }
        }
        d.local_step(&f, (el, set), true, false);
        let res = d.residual_now(el, set);
        unknowns.iter().flat_map(|&u| res[u as usize]).collect()
    };
    let mut worst: Real = 0.0;
    for seed in 0..4u64 {
        // a smooth direction and a rough one
        let v: Vec<Real> = (0..n)
            .map(|i| {
                let x = ((i as u64 * 2654435761 + seed * 40503) % 1000) as Real / 1000.0 - 0.5;
                if seed % 2 == 0 {
                    ((i / 3) as Real * 0.01 + seed as Real).sin() * 0.5 + 0.1 * x
                } else {
                    x
                }
            })
            .collect();
        let h = 1e-5;
        let plus = gradient_at(&mut d, &v, h);
        let minus = gradient_at(&mut d, &v, -h);
        let fd: Vec<Real> = plus
            .iter()
            .zip(&minus)
            .map(|(p, m)| -(p - m) / (2.0 * h))
            .collect();
        let hv = &held * nalgebra::DVector::from_column_slice(&v);
        let scale = fd.iter().map(|x| x * x).sum::<Real>().sqrt();
        let diff = fd
            .iter()
            .zip(hv.iter())
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<Real>()
            .sqrt();
        worst = worst.max(diff / scale);
    }
    worst
}

/// With all of the elements' curvature the matrix is the Hessian of the
/// energy reduced over the rotations and area targets (central
/// differences of its gradient agree to rounding), for each term alone
/// and together; its positive semi-definite part differs where elements
/// are compressed (which this edit has).
#[test]
fn the_matrix_is_the_reduced_energys_hessian() {
    let base = Params::default();
    for (name, p) in [
        ("all terms", base),
        ("no area term", base.with_elastic(|e| e.area = 0.0)),
        (
            "area term only",
            base.with_elastic(|e| {
                e.stretch = 0.0;
                e.bending = 1e-9;
            }),
        ),
    ] {
        let full = hessian_error(p, Curvature::Full);
        assert!(full < 1e-6, "{name}: {full:e}");
        let projected = hessian_error(p, Curvature::Projected);
        assert!(projected > 1e-3, "{name}: {projected:e}");
    }
}

/// The generated bar bent 180° in three steps (the posing suite's
/// `bar-bend-180`): the local/global iteration crawls down a slow mode
/// and reached the 100-iteration cap at every step; a sequence that
/// predicts a long crawl switches to Newton steps (at least one step
/// does), and every step converges within the cap, each from the last
/// one's pose. The switch reads only ratios of updates and the tolerance
/// in mean edge lengths, so the bar scaled by 37 or 1/37 takes the same
/// iterations at every step and reaches the same pose to 1e-9 of the
/// diagonal.
#[test]
fn a_crawling_bend_switches_to_newton_steps_and_converges() {
    use crate::deform::ConstraintsSpec;
    use crate::mesh::gen::{generate, Shape, ShapeSpec};
    let mesh = generate(&ShapeSpec::default_for(Shape::Bar)).unwrap();
    assert!(mesh.num_vertices() <= super::newton::NEWTON_MAX_VERTICES);
    let spec: ConstraintsSpec =
        serde_json::from_str(include_str!("../../../../../examples/bar-bend-180.json")).unwrap();
    let c = spec.resolve(&mesh).unwrap();
    let bend = |s: Real| {
        let mesh = super::test_util::scaled(&mesh, s);
        let handles = c
            .handles
            .iter()
            .map(|h| (h.name.clone(), h.vertices.clone(), None))
            .collect();
        let mut cs = Constraints::new(&mesh, c.fixed.clone(), handles).unwrap();
        let full = c.handles[0].target;
        let params = Params::default();
        let rest = Arc::new(Rest::new(mesh).unwrap());
        let f = Factor::build(&rest, &params, &cs).unwrap();
        let mut d = Deformer::new(rest, params);
        let (mut its, mut switched) = (Vec::new(), 0);
        for k in 1..=3 {
            let t = full.fraction(k as Real / 3.0);
            cs.handles[0].target = RigidTransform {
                rotation: t.rotation,
                translation: t.translation.map(|v| v * s),
                pivot: t.pivot.map(|v| v * s),
            };
            let r = d.step(&f, &cs, 100).unwrap();
            assert!(r.converged, "scale {s}, step {k}: {r:?}");
            its.push(r.iterations);
            switched += d.elastic.newton_now as usize;
        }
        let pose: Vec<_> = d.pose().iter().map(|p| p.map(|v| v / s)).collect();
        (its, switched, pose)
    };
    let (its, switched, pose) = bend(1.0);
    assert!(switched > 0, "no step switched to Newton steps: {its:?}");
    for s in [37.0, 1.0 / 37.0] {
        let (its_s, switched_s, pose_s) = bend(s);
        let gap = max_dist(&pose, &pose_s) / mesh.diagonal();
        assert!(
            its_s == its && switched_s == switched && gap <= 1e-9,
            "scale {s}: iterations {its_s:?} against {its:?}, switched {switched_s} against {switched}, pose gap {gap:.2e}"
        );
    }
}

/// The assembly's mechanisms: the planned gather gives the matrix the
/// elements' blocks make when scattered one by one (to the bit: the same
/// sums in the same order), on any number of threads; where the exact
/// Hessian does not factor, computing again only the elements whose
/// curvature is indefinite gives the convex model computed afresh; and a
/// pose whose elements degenerate (a vertex's whole ring collapsed to a
/// point: its `C` vanishes to rounding and its triangles are flat) is assembled
/// through the same plan.
#[test]
fn the_planned_assembly_is_the_scattered_sum_on_any_thread_count() {
    let mesh = irregular_patch(PatchSurface::Wavy, 12, 0.4, 7);
    let c = patch_edit(&mesh, 1.0);
    let params = Params::default();
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let (el, set) = f.elastic.as_ref().unwrap();
    let mut d = Deformer::new(rest.clone(), params);
    d.set_levels(super::Levels::One);
    d.step(&f, &c, 4).unwrap();
    let assemble = |d: &mut Deformer, threads: usize, curvature: Curvature, patch: bool| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| d.assemble_newton(&f, (el, set), curvature, patch))
            .unwrap();
        let p = d.elastic.newton.pattern.as_ref().unwrap();
        (
            p.h.data().to_vec(),
            p.blocks.clone(),
            dense(&p.h),
            summed(&f, p),
        )
    };
    // a free vertex away from the constraints, its ring collapsed
    let centre = (0..rest.mesh.num_vertices())
        .filter(|&v| f.sys.col_of[v] != u32::MAX)
        .min_by(|&a, &b| {
            let n = |v: usize| Vector3::from(rest.mesh.positions()[v]).norm();
            n(a).total_cmp(&n(b))
        })
        .unwrap();
    for collapse in [false, true] {
        if collapse {
            let ring = rest.ops.lbar.outer_view(centre).unwrap();
            for &v in ring.indices() {
                d.y[v] = [0.0; 3];
            }
        }
        for curvature in [Curvature::Full, Curvature::Projected] {
            let (one, blocks_one, held, sum) = assemble(&mut d, 1, curvature, false);
            assert!(held == sum, "{curvature:?}, collapsed {collapse}");
            assert!(sum.amax() > 0.0);
            let (three, blocks_three, ..) = assemble(&mut d, 3, curvature, false);
            assert!(one == three && blocks_one == blocks_three);
        }
        assemble(&mut d, 2, Curvature::Full, false);
        let p = d.elastic.newton.pattern.as_ref().unwrap();
        assert!(p.indefinite.contains(&true), "collapsed {collapse}");
        let patched = assemble(&mut d, 2, Curvature::Projected, true);
        let fresh = assemble(&mut d, 2, Curvature::Projected, false);
        assert!(patched.0 == fresh.0 && patched.1 == fresh.1);
    }
}
