//! Tests of the coarse level and the two-level start on generated meshes.

use std::sync::Arc;

use nalgebra::{UnitQuaternion, Vector3};

use super::*;
use crate::deform::{Constraints, Deformer, Factor, Levels, Params, RigidTransform};
use crate::mesh::gen::{generate, Shape, ShapeParams, ShapeSpec};
use crate::mesh::{Mesh, Point};

/// An open tube of radius 1 and length 12 along z, 32 × 130 = 4160
/// vertices: a limb whose lower quarter is held.
fn limb() -> Mesh {
    generate(&ShapeSpec {
        shape: Shape::Cylinder,
        params: ShapeParams {
            nu: Some(32),
            nv: Some(130),
            size: Some(1.0),
            size2: Some(12.0),
            ..Default::default()
        },
    })
    .expect("cylinder")
}

/// The lower quarter fixed, the top ring a handle with `target`.
fn limb_constraints(mesh: &Mesh, target: impl Fn(Point) -> RigidTransform) -> Constraints {
    let p = mesh.positions();
    let (lo, hi) = mesh.bounding_box();
    let len = hi[2] - lo[2];
    let fixed = (0..p.len() as u32)
        .filter(|&v| p[v as usize][2] < lo[2] + 0.25 * len)
        .collect();
    let tip: Vec<u32> = (0..p.len() as u32)
        .filter(|&v| p[v as usize][2] > hi[2] - 0.05 * len)
        .collect();
    let mut c = Constraints::new(mesh, fixed, vec![("tip".into(), tip, None)]).unwrap();
    c.handles[0].target = target(c.handles[0].rest_centroid);
    c
}

/// The tip swung 60° about x about the limb's held end, pulled in a little.
fn swing(centroid: Point) -> RigidTransform {
    let pivot = [0.0, 0.0, centroid[2] - 9.0];
    let r = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 60f64.to_radians());
    let moved = r * Vector3::new(0.0, 0.0, 9.0);
    let t = [moved.x, moved.y, moved.z + pivot[2]];
    RigidTransform {
        rotation: r,
        translation: [t[0] - centroid[0], t[1] - centroid[1], t[2] - centroid[2]],
        pivot: centroid,
    }
}

/// The largest distance between the two deformers' poses, vertex by
/// vertex (the dend crate's unit tests cannot use `dend_testkit`).
fn pose_gap(a: &Deformer, b: &Deformer) -> Real {
    a.pose()
        .iter()
        .zip(b.pose())
        .map(|(p, q)| crate::mesh::norm(crate::mesh::sub(*p, *q)))
        .fold(0.0, Real::max)
}

fn solve(
    rest: &Arc<Rest>,
    params: Params,
    c: &Constraints,
    levels: Levels,
) -> (Deformer, crate::deform::StepReport) {
    let factor = Factor::build(rest, &params, c).unwrap();
    let mut d = Deformer::new(rest.clone(), params);
    d.set_levels(levels);
    let r = d.step(&factor, c, 2000).unwrap();
    (d, r)
}

#[test]
fn the_level_of_a_limb_is_a_valid_vertex_subset() {
    let mesh = limb();
    let rest = Rest::new(mesh.clone()).unwrap();
    let level = rest.coarse().expect("4160 vertices have a coarse level");
    let nc = level.num_vertices();
    assert!(
        nc * 4 < mesh.num_vertices() && nc * 16 > mesh.num_vertices(),
        "{nc}"
    );
    for (c, &v) in level.fine_of.iter().enumerate() {
        assert_eq!(
            level.rest.mesh().positions()[c],
            mesh.positions()[v as usize]
        );
        assert_eq!(level.coarse_of[v as usize], c as u32);
        assert_eq!(level.near[v as usize], c as u32);
    }
    assert!(level.near.iter().all(|&c| (c as usize) < nc));
    // two levels, not three
    assert!(level.rest.coarse().is_none());
    // a small mesh has none
    let small = generate(&ShapeSpec::default_for(Shape::Bar)).unwrap();
    assert!(small.num_vertices() < MIN_VERTICES);
    assert!(Rest::new(small).unwrap().coarse().is_none());
}

#[test]
fn smaller_meshes_keep_at_least_500_coarse_vertices() {
    let most = crate::deform::ELASTICA_COARSE_RATIO;
    assert_eq!(ratio_at_most(MIN_VERTICES, most), 2);
    assert_eq!(ratio_at_most(1502, most), 3);
    assert_eq!(ratio_at_most(3999, most), 7);
    assert_eq!(ratio_at_most(4000, most), most);
    assert_eq!(ratio_at_most(50_000, most), most);
    assert_eq!(ratio_at_most(50_000, RATIO), RATIO);
    // a 24 × 64 = 1536-vertex tube: ratio 3, about 512 coarse vertices
    let mesh = generate(&ShapeSpec {
        shape: Shape::Cylinder,
        params: ShapeParams {
            nu: Some(24),
            nv: Some(64),
            size: Some(1.0),
            size2: Some(6.0),
            ..Default::default()
        },
    })
    .unwrap();
    let n = mesh.num_vertices();
    let rest = Rest::new(mesh).unwrap();
    let level = rest.coarse().expect("a coarse level from 1000 vertices");
    let nc = level.num_vertices();
    assert!(
        nc >= MIN_COARSE_VERTICES * 9 / 10 && nc <= n / 2,
        "{n} -> {nc} coarse vertices"
    );
}

#[test]
fn restriction_keeps_groups_or_refuses() {
    let mesh = limb();
    let rest = Rest::new(mesh.clone()).unwrap();
    let level = rest.coarse().unwrap();
    let c = limb_constraints(&mesh, swing);
    let r = level.restrict(&c).expect("large groups survive");
    assert!(r.fixed.len() >= MIN_GROUP && r.handles[0].vertices.len() >= MIN_GROUP);
    for (k, &v) in r.fixed.iter().enumerate() {
        let f = level.fine_of[v as usize];
        let i = c.fixed.binary_search(&f).expect("a fixed fine vertex");
        assert_eq!(r.fixed_at[k], c.fixed_at[i]);
    }
    assert_eq!(r.handles[0].target, c.handles[0].target);
    // a handle of two vertices cannot survive
    let v0 = c.handles[0].vertices[0];
    let two = Constraints::new(
        &mesh,
        c.fixed.clone(),
        vec![("pin".into(), vec![v0, v0 + 1], None)],
    )
    .unwrap();
    assert!(level.restrict(&two).is_none());
}

#[test]
fn a_pulled_limb_converges_sooner() {
    // the posing suite's limb edit: a patch at the tip pulled by 0.1
    // diagonal, no rotation (the harmonic rotations give the identity)
    let mesh = limb();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = patch_pull(&mesh, [0.0, 0.1 * mesh.diagonal(), 0.0]);
    let params = Params::elastica();
    let (_, one) = solve(&rest, params, &c, Levels::One);
    let (_, two) = solve(&rest, params, &c, Levels::Two);
    assert!(one.converged && two.converged);
    assert!(two.coarse_iterations > 0, "{two:?}");
    // measured: 26 and 17 (+1 first iteration each)
    assert!(
        two.iterations + 5 <= one.iterations,
        "two levels {} fine iterations, one level {}",
        two.iterations,
        one.iterations
    );
    assert!((two.objective - one.objective).abs() < 1e-2 * one.objective);
}

#[test]
fn a_swung_limb_reaches_the_same_pose() {
    // a 60° swing: to a tight tolerance both starts reach the same pose
    // (at the default tolerance this edit takes MORE fine iterations with
    // the coarse start, 133 vs 108: the tail, not the start, is slow here)
    let mesh = limb();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = limb_constraints(&mesh, swing);
    let tight = Params {
        tol: 1e-6,
        ..Params::elastica()
    };
    let (a, ra) = solve(&rest, tight, &c, Levels::One);
    let (b, rb) = solve(&rest, tight, &c, Levels::Two);
    assert!(ra.converged && rb.converged && rb.coarse_iterations > 0);
    let diag = mesh.diagonal();
    let dist = pose_gap(&a, &b);
    assert!(dist < 1e-3 * diag, "poses {dist} apart, diagonal {diag}");
}

#[test]
fn the_fine_objective_never_grows_through_the_coarse_start_and_corrections() {
    for period in [crate::deform::ELASTICA_CORRECTION_PERIOD, 5] {
        let params = Params::elastica().with_elastic(|e| {
            e.correction_period = period;
            e.corrections = crate::deform::Corrections::WhileGaining;
        });
        objective_never_grows_through_corrections(params);
    }
}

/// The limb swung from rest with `params`: corrections only after every
/// `params.correction_period`-th fine iteration, the objective never
/// growing, and a drag of the solved pose after it.
fn objective_never_grows_through_corrections(params: Params) {
    let period = params.elastic().unwrap().correction_period;
    let mesh = limb();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = limb_constraints(&mesh, swing);
    let factor = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    // the coarse problems' corrections, whose schedule this tests
    d.set_galerkin(None);
    let first = d.step(&factor, &c, 1).unwrap();
    assert!(first.coarse_iterations > 0);
    let mut prev = first.initial_objective;
    assert!(first.objective <= prev * (1.0 + 1e-12));
    prev = first.objective;
    let (reports, converged) = steps_until_converged(&mut d, &factor, &c, prev, 199);
    let mut corrections = Vec::new();
    for (k, r) in (2..).zip(&reports) {
        if r.coarse_iterations > 0 {
            // a correction follows every period-th fine iteration
            assert_eq!(
                k % period,
                0,
                "period {period}: correction after iteration {k}"
            );
            corrections.push(k);
        }
    }
    if converged {
        let k = reports.len() + 1;
        assert!(k > period, "converged in {k}: no correction tried");
    }
    assert_eq!(
        corrections.first(),
        Some(&period),
        "period {period}: corrections after {corrections:?}"
    );
    // a drag of the solved pose: no coarse work in the frame that answers
    // it (its latency), corrections as from rest after that, and the
    // objective still never grows
    let mut dragged = c.clone();
    dragged.handles[0].target.translation[1] += 0.5;
    let first = d.step(&factor, &dragged, 1).unwrap();
    assert!(
        !first.converged && first.coarse_iterations == 0,
        "{first:?}"
    );
    let prev = first.objective;
    assert!(prev <= first.initial_objective * (1.0 + 1e-12));
    let (_, converged) = steps_until_converged(&mut d, &factor, &dragged, prev, 200);
    assert!(converged, "the drag did not converge in 200 iterations");
}

/// Steps `d` one iteration per call, at most `limit` times, until it
/// converges, checking that the objective never grows from `prev` on;
/// the reports, and whether the last one converged.
fn steps_until_converged(
    d: &mut Deformer,
    factor: &Factor,
    c: &Constraints,
    mut prev: Real,
    limit: usize,
) -> (Vec<crate::deform::StepReport>, bool) {
    let mut reports = Vec::new();
    for k in 1..=limit {
        let r = d.step(factor, c, 1).unwrap();
        assert!(
            r.objective <= prev * (1.0 + 1e-12),
            "step {k}: {} > {prev}",
            r.objective
        );
        prev = r.objective;
        let converged = r.converged;
        reports.push(r);
        if converged {
            return (reports, true);
        }
    }
    (reports, false)
}

#[test]
fn identity_and_translation_stay_exact() {
    let mesh = limb();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let params = Params::elastica();
    // identity: the rest pose
    let c = limb_constraints(&mesh, RigidTransform::identity);
    let (d, r) = solve(&rest, params, &c, Levels::Two);
    assert!(r.converged);
    let diag = mesh.diagonal();
    for (p, q) in d.pose().iter().zip(mesh.positions()) {
        assert!(crate::mesh::norm(crate::mesh::sub(*p, *q)) < 1e-9 * diag);
    }
    // every constraint translated by the same vector: the mesh translates
    let shift = [0.3, -0.2, 0.5];
    let mut c = limb_constraints(&mesh, |pivot| RigidTransform {
        rotation: UnitQuaternion::identity(),
        translation: shift,
        pivot,
    });
    for p in &mut c.fixed_at {
        *p = crate::mesh::add(*p, shift);
    }
    let (d, r) = solve(&rest, params, &c, Levels::Two);
    assert!(r.converged);
    for (p, q) in d.pose().iter().zip(mesh.positions()) {
        let want = crate::mesh::add(*q, shift);
        assert!(crate::mesh::norm(crate::mesh::sub(*p, want)) < 1e-9 * diag);
    }
}

/// The lower quarter fixed; a patch of radius 0.08 diagonal about the
/// top rim's vertex of largest x pulled by `shift` (no rotation).
fn patch_pull(mesh: &Mesh, shift: Point) -> Constraints {
    let p = mesh.positions();
    let (lo, hi) = mesh.bounding_box();
    let len = hi[2] - lo[2];
    let tip = (0..p.len())
        .max_by(|&a, &b| (p[a][2] + 1e-3 * p[a][0]).total_cmp(&(p[b][2] + 1e-3 * p[b][0])))
        .unwrap();
    let r = 0.08 * mesh.diagonal();
    let handle: Vec<u32> = (0..p.len() as u32)
        .filter(|&v| crate::mesh::norm(crate::mesh::sub(p[v as usize], p[tip])) <= r)
        .collect();
    let fixed = (0..p.len() as u32)
        .filter(|&v| p[v as usize][2] < lo[2] + 0.25 * len)
        .collect();
    let mut c = Constraints::new(mesh, fixed, vec![("tip".into(), handle, None)]).unwrap();
    c.handles[0].target.translation = shift;
    c
}

/// The limb's rest state, its coarse level and fixed masks for the lower
/// quarter (fine and coarse).
fn limb_level() -> (Arc<Rest>, Arc<CoarseLevel>, Vec<bool>, Vec<bool>) {
    let mesh = limb();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let level = rest
        .coarse()
        .expect("a 4160-vertex tube has a coarse level")
        .clone();
    let (lo, hi) = mesh.bounding_box();
    let cut = lo[2] + 0.25 * (hi[2] - lo[2]);
    let fine_fixed: Vec<bool> = mesh.positions().iter().map(|p| p[2] < cut).collect();
    let coarse_fixed: Vec<bool> = level
        .fine_of
        .iter()
        .map(|&v| fine_fixed[v as usize])
        .collect();
    (rest, level, fine_fixed, coarse_fixed)
}

/// A deterministic pseudo-random vector per index.
fn noise(i: usize, salt: u64) -> Vector3<Real> {
    let mut h = (i as u64 ^ salt).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    let mut next = || {
        h ^= h >> 29;
        h = h.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        (h >> 11) as Real / (1u64 << 53) as Real - 0.5
    };
    Vector3::new(next(), next(), next())
}

#[test]
fn restriction_is_the_transpose_of_prolongation() {
    // <P w_c, f> = <w_c, Pᵀ f> for the same smoothing: the restriction is
    // computed by another loop (Sᵀ = (A + I) D⁻¹), so this checks both
    let (rest, level, fine_fixed, coarse_fixed) = limb_level();
    let n = fine_fixed.len();
    let nc = level.num_vertices();
    let wc: Vec<Vector3<Real>> = (0..nc).map(|c| noise(c, 1)).collect();
    let f: Vec<Point> = (0..n).map(|i| noise(i, 2).into()).collect();
    for passes in [0, 1, 3, 10] {
        let pw = level.prolongate_vectors(&rest, &wc, &fine_fixed, &coarse_fixed, passes);
        let rf = level.restrict_forces(&rest, &f, &fine_fixed, &coarse_fixed, passes);
        let lhs: Real = pw
            .iter()
            .zip(&f)
            .map(|(a, b)| a.dot(&Vector3::from(*b)))
            .sum();
        let rhs: Real = wc
            .iter()
            .zip(&rf)
            .map(|(a, b)| a.dot(&Vector3::from(*b)))
            .sum();
        assert!(
            (lhs - rhs).abs() <= 1e-10 * lhs.abs().max(1.0),
            "{passes} passes: {lhs} vs {rhs}"
        );
        // the masks: nothing reaches a fixed vertex on either level
        assert!(pw
            .iter()
            .zip(&fine_fixed)
            .all(|(v, &x)| !x || v.norm() == 0.0));
        assert!(rf
            .iter()
            .zip(&coarse_fixed)
            .all(|(v, &x)| !x || *v == [0.0; 3]));
    }
}

/// The transfers give the same bits on any number of threads: the limb
/// (4,160 vertices) is above their parallel threshold, and each vertex's
/// value is summed on its own, in the same order, whoever computes it.
#[test]
fn the_transfers_do_not_depend_on_the_threads() {
    let (rest, level, fine_fixed, coarse_fixed) = limb_level();
    assert!(rest.mesh.num_vertices() >= transfer::PARALLEL_MIN);
    let n = fine_fixed.len();
    let nc = level.num_vertices();
    let wc: Vec<Vector3<Real>> = (0..nc).map(|c| noise(c, 3)).collect();
    let f: Vec<Point> = (0..n).map(|i| noise(i, 4).into()).collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            (
                level.prolongate_vectors(&rest, &wc, &fine_fixed, &coarse_fixed, 10),
                level.restrict_forces(&rest, &f, &fine_fixed, &coarse_fixed, 3),
            )
        })
    };
    let (p1, r1) = run(1);
    for threads in [2, 3] {
        let (p, r) = run(threads);
        assert!(p.iter().zip(&p1).all(|(a, b)| a == b), "{threads} threads");
        assert!(r.iter().zip(&r1).all(|(a, b)| a == b), "{threads} threads");
    }
    assert!(p1.iter().any(|v| v.norm() > 0.0) && r1.iter().any(|v| *v != [0.0; 3]));
}

#[test]
fn prolongation_keeps_a_constant_field_away_from_the_fixed_part() {
    // rows of S and P₀ sum to 1: a constant coarse field stays constant
    // where no fixed vertex is within reach of the smoothing
    let (rest, level, _, _) = limb_level();
    let n = level.near.len();
    let nc = level.num_vertices();
    let w = Vector3::new(0.3, -0.2, 0.1);
    let none = vec![false; n];
    let pw = level.prolongate_vectors(&rest, &vec![w; nc], &none, &vec![false; nc], 10);
    for v in &pw {
        assert!((v - w).norm() < 1e-12, "{v:?}");
    }
    // and the restriction of unit forces conserves their sum
    let ones: Vec<Point> = vec![[1.0, 2.0, -1.0]; n];
    let r = level.restrict_forces(&rest, &ones, &none, &vec![false; nc], 3);
    let total = r
        .iter()
        .fold([0.0; 3], |a, b| [a[0] + b[0], a[1] + b[1], a[2] + b[2]]);
    let want = [n as Real, 2.0 * n as Real, -(n as Real)];
    for k in 0..3 {
        assert!((total[k] - want[k]).abs() < 1e-8 * n as Real, "{total:?}");
    }
}

/// `ElasticParams::coarse_ratio` picks the level: the 4160-vertex limb gets about
/// `#V / 8` coarse vertices by default and about `#V / 3` at ratio 3, the
/// rest state keeps both, and a deformer whose ratio changes between two
/// steps (same fine factor) solves with the new level: its pose equals a
/// fresh deformer's at that ratio, and differs from the default ratio's
/// on this swing. A ratio under 2 is refused.
#[test]
fn the_coarse_ratio_parameter_picks_the_level() {
    let mesh = limb();
    let n = mesh.num_vertices();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let coarse8 = rest.coarse_at_most(8).unwrap();
    let coarse3 = rest.coarse_at_most(3).unwrap();
    assert!(coarse8.num_vertices() < n / 6, "{}", coarse8.num_vertices());
    assert!(coarse3.num_vertices() > n / 4, "{}", coarse3.num_vertices());
    assert!(Arc::ptr_eq(&coarse3, &rest.coarse_at_most(3).unwrap()));
    assert!(Arc::ptr_eq(&coarse8, &rest.coarse().unwrap()));
    let c = limb_constraints(&mesh, swing);
    let base = Params {
        tol: 1e-2,
        ..Params::elastica()
    };
    let at3 = base.with_elastic(|e| e.coarse_ratio = 3);
    let factor = Factor::build(&rest, &base, &c).unwrap();
    let mut switched = Deformer::new(rest.clone(), base);
    switched.step(&factor, &c, 3).unwrap();
    switched.set_params(at3).unwrap();
    switched.reset();
    switched.step(&factor, &c, 3).unwrap();
    let mut fresh = Deformer::new(Arc::new(Rest::new(mesh.clone()).unwrap()), at3);
    let fresh_factor = Factor::build(fresh.rest(), &at3, &c).unwrap();
    fresh.step(&fresh_factor, &c, 3).unwrap();
    let mut default = Deformer::new(rest.clone(), base);
    default.step(&factor, &c, 3).unwrap();
    let gap = |a: &Deformer, b: &Deformer| {
        a.pose()
            .iter()
            .zip(b.pose())
            .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
            .fold(0.0, f64::max)
    };
    assert!(gap(&switched, &fresh) < 1e-9, "{}", gap(&switched, &fresh));
    assert!(
        gap(&switched, &default) > 1e-6,
        "{}",
        gap(&switched, &default)
    );
    for bad in [0, 1] {
        let p = Params::elastica().with_elastic(|e| e.coarse_ratio = bad);
        assert!(p.validate().is_err());
    }
}

/// Runs the swung limb one iteration per call until it converges (at most
/// 300), checking that the objective never grows; the number of coarse
/// corrections and of fine iterations.
fn corrections_until_converged(params: Params) -> (usize, usize) {
    let mesh = limb();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = limb_constraints(&mesh, swing);
    let factor = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    // the coarse problems' corrections, whose schedule this tests
    d.set_galerkin(None);
    let first = d.step(&factor, &c, 1).unwrap();
    let (reports, converged) = steps_until_converged(&mut d, &factor, &c, first.objective, 299);
    assert!(converged, "not converged in 300 iterations ({params:?})");
    let corrections = reports.iter().filter(|r| r.coarse_iterations > 0).count();
    (corrections, reports.len() + 1)
}

/// `Corrections::WhileGaining` corrects at least as often as the default
/// rule on the same weights (the characters' `k_L` 0.1, where the fine
/// iteration is slowest), and the objective still never grows.
#[test]
fn corrections_while_gaining_go_on_at_least_as_long() {
    use crate::deform::Corrections;
    let slow = Params::elastica().with_elastic(|e| e.laplacian = 0.1);
    let (faster, its_faster) = corrections_until_converged(slow);
    let (gaining, its_gaining) = corrections_until_converged(
        slow.with_elastic(|e| e.corrections = Corrections::WhileGaining),
    );
    assert!(
        gaining >= faster && gaining >= 1,
        "while gaining {gaining} corrections ({its_gaining} iterations), while faster {faster} ({its_faster})"
    );
}

#[test]
fn the_coarse_start_solved_beside_the_factor_gives_the_same_sequence() {
    // `Deformer::build_factor` runs the coarse start while the fine factor
    // is built; the first step must then be the sequence `Factor::build`
    // plus `step` gives, iteration for iteration
    let mesh = limb();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = patch_pull(&mesh, [0.0, 0.1 * mesh.diagonal(), 0.0]);
    let params = Params::elastica();
    // (the default levels, which the deformers below keep)
    let (plain, rp) = solve(&rest, params, &c, Levels::default());
    let mut ahead = Deformer::new(rest.clone(), params);
    let factor = ahead.build_factor(&c).unwrap();
    let ra = ahead.step(&factor, &c, 2000).unwrap();
    assert!(rp.converged && ra.converged && rp.coarse_iterations > 0);
    assert_eq!(ra.iterations, rp.iterations);
    assert_eq!(ra.coarse_iterations, rp.coarse_iterations);
    let gap = pose_gap(&plain, &ahead);
    assert!(gap < 1e-9 * mesh.diagonal(), "poses {gap} apart");

    // a start solved for one target is not taken for another: the second
    // deformer is asked for twice the pull after building for the first
    let far = patch_pull(&mesh, [0.0, 0.2 * mesh.diagonal(), 0.0]);
    let (plain_far, rf) = solve(&rest, params, &far, Levels::default());
    let mut stale = Deformer::new(rest.clone(), params);
    let factor = stale.build_factor(&c).unwrap();
    let rs = stale.step(&factor, &far, 2000).unwrap();
    assert_eq!(rs.iterations, rf.iterations);
    let gap = pose_gap(&plain_far, &stale);
    assert!(gap < 1e-9 * mesh.diagonal(), "poses {gap} apart");

    // one level: nothing is solved ahead, and no coarse work is done
    let mut one = Deformer::new(rest.clone(), params);
    one.set_levels(Levels::One);
    let factor = one.build_factor(&c).unwrap();
    let r1 = one.step(&factor, &c, 2000).unwrap();
    assert_eq!(r1.coarse_iterations, 0);
}
