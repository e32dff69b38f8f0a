//! The Galerkin coarse corrections (`solver/galerkin.rs`): the coarse
//! matrix assembled from the elements' factors is `Pᵀ H P` of the Newton
//! matrix, and a solve with Galerkin corrections reaches the minimum the
//! local/global iteration reaches.

use std::sync::Arc;

use nalgebra::{DMatrix, Matrix3, UnitQuaternion, Vector3};

use super::test_util::{assert_same_symmetric_semidefinite, dense, patch_edit};
use crate::deform::elastic::hessian::galerkin::{RigidSpace, Weights};
use crate::deform::elastic::hessian::Curvature;
use crate::deform::{Deformer, Factor, Galerkin, Levels, Params, Rest};
use crate::mesh::gen::{irregular_patch, PatchSurface};
use crate::mesh::Real;

#[test]
fn the_coarse_matrix_is_the_newton_matrix_projected_on_the_rigid_motions() {
    let mesh = irregular_patch(PatchSurface::Wavy, 11, 0.4, 7);
    let n = mesh.num_vertices();
    let c = patch_edit(&mesh, 1.0);
    let params = Params::default();
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let (el, set) = f.elastic.as_ref().unwrap();
    let mut d = Deformer::new(rest.clone(), params);
    d.set_levels(Levels::One);
    // a bent pose with its rotations fitted
    d.step(&f, &c, 3).unwrap();
    let nu = f.sys.unknowns.len();
    // aggregates: vertical strips of the patch, numbered in order of
    // first appearance (any partition of the unknowns is a coarse space)
    let xs = rest.ops.positions.iter().map(|p| p[0]);
    let lo = xs.clone().fold(Real::INFINITY, Real::min);
    let hi = xs.fold(Real::NEG_INFINITY, Real::max);
    let mut ids = [u32::MAX; 8];
    let mut n_agg = 0;
    let agg: Vec<u32> = f
        .sys
        .unknowns
        .iter()
        .map(|&u| {
            let x = rest.ops.positions[u as usize][0];
            let strip = (((x - lo) / (hi - lo) * 8.0).floor() as usize).min(7);
            if ids[strip] == u32::MAX {
                ids[strip] = n_agg;
                n_agg += 1;
            }
            ids[strip]
        })
        .collect();
    assert!(n_agg >= 5, "{n_agg} aggregates");
    let elements = el.coupling_elements(set, &rest.ops, &f.sys.col_of);
    // the strips' weights smoothed across their borders, so that unknowns
    // blend the motions of up to three strips (the general case)
    let unsmoothed = Weights::partition(agg);
    let weights = super::galerkin::smoothed_weights(
        unsmoothed.agg.clone(),
        2,
        &rest.ops.l,
        &f.sys.unknowns,
        &f.sys.col_of,
    );
    let q = el.without_area(&elements, &f.sys.m);
    let blended = (0..nu).filter(|&k| weights.entries(k).len() > 1).count();
    assert!(blended > nu / 10, "{blended} of {nu} unknowns blend strips");
    for k in 0..nu {
        let sum: Real = weights.w[weights.entries(k)].iter().sum();
        assert!((sum - 1.0).abs() < 1e-12, "weights of {k} sum to {sum}");
    }
    // one aggregate per task, a few, all: the groups change the order
    // of the sums only
    for group in [1, 3, 64] {
        let space = RigidSpace::with_groups(weights.clone(), n_agg as usize, &elements, &q, group);
        let wts = &space.weights;
        // lever arms about points off the centroids (any centre spans the
        // same space; these test the general formula)
        let lever: Vec<Vector3<Real>> = (0..wts.agg.len())
            .map(|e| {
                let k = space.entry_unknown[e] as usize;
                let y = Vector3::from(d.y[f.sys.unknowns[k] as usize]);
                y - Vector3::new(0.1 * wts.agg[e] as Real, -0.2, 0.3)
            })
            .collect();
        // P, dense: 3 nu × 6 n_agg, P_ka = w_ka [I | −[r_ka]×]
        let mut p = DMatrix::zeros(3 * nu, 6 * n_agg as usize);
        for k in 0..nu {
            for e in wts.entries(k) {
                let (a, w, r) = (wts.agg[e] as usize, wts.w[e], lever[e]);
                let cross = Matrix3::new(0.0, -r.z, r.y, r.z, 0.0, -r.x, -r.y, r.x, 0.0);
                for i in 0..3 {
                    p[(3 * k + i, 6 * a + i)] += w;
                    for j in 0..3 {
                        p[(3 * k + i, 6 * a + 3 + j)] -= w * cross[(i, j)];
                    }
                }
            }
        }
        for curvature in [Curvature::Projected, Curvature::GaussNewton] {
            let mut g = space.pattern();
            el.galerkin_matrix(
                &space,
                &elements,
                &rest.ops,
                &q,
                (&d.y, &d.elastic.rot, &d.elastic.proj),
                &lever,
                curvature,
                &mut g,
            );
            // H from the Newton iteration's own assembly, dense
            d.assemble_newton(&f, (el, set), curvature, false).unwrap();
            let h = dense(&d.elastic.newton.pattern.as_ref().unwrap().h);
            let expected = p.transpose() * &h * &p;
            assert_same_symmetric_semidefinite(
                &dense(&g),
                &expected,
                1e-10,
                &format!("{curvature:?}, groups of {group} ({n} vertices)"),
            );
        }
    }
}

#[test]
fn galerkin_corrections_reach_the_minimum_and_never_raise_the_objective() {
    // a patch with a coarse level (over 1000 vertices), its far side
    // folded over and turned: slow modes for the local/global iteration
    let mesh = irregular_patch(PatchSurface::Saddle, 36, 0.4, 11);
    let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -1.2);
    let c = super::test_util::x_edit(&mesh, -0.8, 0.8, [-0.5, 0.0, 0.6], r);
    let params = Params::default();
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let solve = |galerkin: Option<Galerkin>, p: Params| {
        let mut d = Deformer::new(rest.clone(), p);
        d.set_galerkin(galerkin);
        d.prepare_levels(&f, &c);
        let mut objectives = Vec::new();
        let mut corrections = 0;
        let mut report = None;
        // one iteration per step: each step's objective is the pose's
        // (the first step's coarse iterations are the coarse start's)
        for k in 0..p.max_iters {
            let r = d.step(&f, &c, 1).unwrap();
            objectives.push(r.objective);
            if k > 0 {
                corrections += r.coarse_iterations;
            }
            report = Some(r);
            if r.converged {
                break;
            }
        }
        (report.unwrap(), objectives, corrections, d.pose().to_vec())
    };
    let galerkin = Galerkin {
        depth: 1,
        lag: 3,
        period: 1,
        smooth: 1,
    };
    let (r, objectives, corrections, _) = solve(Some(galerkin), params);
    assert!(r.converged, "{r:?}");
    assert!(corrections > 0, "no Galerkin correction ran");
    for w in objectives.windows(2) {
        assert!(w[1] <= w[0] * (1.0 + 1e-12), "objective rose: {w:?}");
    }
    // the tight-tolerance minimum, by the plain hierarchy
    let tight = Params {
        tol: 1e-6,
        max_iters: 3000,
        ..params
    };
    let (r_star, ..) = solve(None, tight);
    assert!(r_star.converged, "{r_star:?}");
    let gap = r.objective / r_star.objective - 1.0;
    assert!(
        gap.abs() < 1e-3,
        "objective {} against {}",
        r.objective,
        r_star.objective
    );
}
