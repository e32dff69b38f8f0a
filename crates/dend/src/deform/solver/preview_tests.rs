//! Coarse previews on generated meshes: a rigid motion of every
//! constraint is reproduced exactly, the constraints are met, the shown
//! pose switches as documented, and the fine solve that starts from a
//! preview reaches the one-shot solve's objective.

use std::sync::Arc;

use nalgebra::{UnitQuaternion, Vector3};

use crate::deform::solver::test_util::max_dist;
use crate::deform::{Constraints, Deformer, Factor, Params, Rest, RigidTransform};
use crate::mesh::gen::{generate, Shape, ShapeSpec};
use crate::mesh::{Mesh, Point};

/// The creature at 4 levels (over `PREVIEW_MIN_VERTICES` vertices).
fn creature() -> Mesh {
    let mut s = ShapeSpec::default_for(Shape::Creature);
    s.params.nu = Some(4);
    generate(&s).expect("creature")
}

/// The creature ([`creature`]), its rest operators, its [`ends`] with
/// `both_handles` and their factor under the default parameters.
fn creature_ends(both_handles: bool) -> (Mesh, Arc<Rest>, Constraints, Factor) {
    let mesh = creature();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = ends(&mesh, both_handles);
    let factor = Factor::build(&rest, &Params::default(), &c).unwrap();
    (mesh, rest, c, factor)
}

/// The lowest 10 % along the longest axis and the highest 10 %: both
/// handles when `both_handles`, else fixed and handle.
fn ends(mesh: &Mesh, both_handles: bool) -> Constraints {
    let (lo, hi) = mesh.bounding_box();
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap();
    let extent = hi[axis] - lo[axis];
    let at = |v: u32| mesh.positions()[v as usize][axis];
    let n = mesh.num_vertices() as u32;
    let low: Vec<u32> = (0..n)
        .filter(|&v| at(v) < lo[axis] + 0.1 * extent)
        .collect();
    let high: Vec<u32> = (0..n)
        .filter(|&v| at(v) > hi[axis] - 0.1 * extent)
        .collect();
    if both_handles {
        Constraints::new(
            mesh,
            vec![],
            vec![("a".into(), low, None), ("b".into(), high, None)],
        )
        .unwrap()
    } else {
        Constraints::new(mesh, low, vec![("b".into(), high, None)]).unwrap()
    }
}

/// The handle of `c` at a fraction `s` of its gesture: moved by 0.15 and
/// 0.1 of the mesh's `diag` along x and y and turned 0.8 rad about z, all
/// times `s`, about its rest centroid.
fn swing(c: &Constraints, diag: f64, s: f64) -> RigidTransform {
    RigidTransform {
        rotation: UnitQuaternion::from_scaled_axis(Vector3::z() * (0.8 * s)),
        translation: [0.15 * diag * s, 0.1 * diag * s, 0.0],
        pivot: c.handles[0].rest_centroid,
    }
}

#[test]
fn a_rigid_motion_of_every_constraint_previews_as_that_motion() {
    let (mesh, rest, mut c, factor) = creature_ends(true);
    assert!(mesh.num_vertices() >= super::PREVIEW_MIN_VERTICES);
    let params = Params::default();
    // both handles turn 50° about one pivot and move: a rigid motion
    let pivot = c.handles[0].rest_centroid;
    let motion = RigidTransform {
        rotation: UnitQuaternion::from_scaled_axis(Vector3::new(0.3, -0.5, 0.7).normalize() * 0.87),
        translation: [0.2, -0.4, 0.1].map(|t| t * mesh.diagonal()),
        pivot,
    };
    for h in &mut c.handles {
        h.target = motion;
    }
    let mut d = Deformer::new(rest.clone(), params);
    let report = d
        .preview(&factor, &c, 20)
        .unwrap()
        .expect("a preview level");
    assert!(report.coarse_vertices < mesh.num_vertices() / 2);
    assert!(d.shows_preview());
    let expected: Vec<Point> = mesh.positions().iter().map(|&p| motion.apply(p)).collect();
    let gap = max_dist(d.shown_pose(), &expected) / mesh.diagonal();
    assert!(
        gap < 1e-6,
        "the preview is {gap:.2e} of the diagonal off the rigid motion"
    );
    // the fine pose did not move
    assert_eq!(d.pose(), mesh.positions());
}

#[test]
fn previews_meet_the_constraints_and_the_fine_solve_refines_from_them() {
    let (mesh, rest, mut c, factor) = creature_ends(false);
    let params = Params::default();
    let diag = mesh.diagonal();
    // the fine drag loop: one iteration per drag, corrections held as a
    // session holds them while a person drags
    let mut fine = Deformer::new(rest.clone(), params);
    fine.hold_corrections(true);
    for k in 1..=10 {
        c.handles[0].target = swing(&c, diag, k as f64 / 10.0);
        fine.step(&factor, &c, 1).unwrap();
    }
    let mut d = Deformer::new(rest.clone(), params);
    for k in 1..=10 {
        c.handles[0].target = swing(&c, diag, k as f64 / 10.0);
        let r = d.preview(&factor, &c, super::PREVIEW_ITERATIONS).unwrap();
        assert!(r.is_some(), "drag {k}: no preview");
        let shown = d.shown_pose();
        assert!(shown.iter().flatten().all(|v| v.is_finite()));
        for (&v, &at) in c.fixed.iter().zip(&c.fixed_at) {
            assert_eq!(shown[v as usize], at, "fixed vertex {v} moved");
        }
        for (v, at) in c.handles[0].target_positions() {
            assert_eq!(shown[v as usize], at, "handle vertex {v} off its target");
        }
    }
    let previewed = d.shown_pose().to_vec();
    let mut d2 = Deformer::new(rest.clone(), params);
    d2.preview(&factor, &c, 300).unwrap();
    let converged_preview = d2.shown_pose().to_vec();
    // the fine solve starts from the preview and reaches the one-shot's objective
    let settle = d.step(&factor, &c, params.max_iters).unwrap();
    assert!(!d.shows_preview());
    assert!(settle.converged, "{settle:?}");
    assert!(
        settle.initial_objective.is_finite(),
        "the settle starts from the preview: {settle:?}"
    );
    let mut one = Deformer::new(rest.clone(), params);
    let r1 = one.step(&factor, &c, params.max_iters).unwrap();
    assert!(
        settle.objective <= 1.01 * r1.objective,
        "settled {} against the one-shot's {}",
        settle.objective,
        r1.objective
    );
    // the previews are a better picture of where the drag goes than the
    // fine frames they replace (measured 0.063 against 0.110 of the
    // diagonal), and a converged preview is within the level's detail
    // (0.021)
    let off = |p: &[Point]| max_dist(p, d.pose()) / diag;
    let (preview_off, fine_off) = (off(&previewed), off(fine.pose()));
    let converged_off = off(&converged_preview);
    assert!(
        preview_off <= fine_off,
        "after 10 drags the preview is {preview_off:.3} of the diagonal from the settled pose, \
         the fine drag loop {fine_off:.3}"
    );
    assert!(
        converged_off < 0.05,
        "a converged preview is {converged_off:.3} of the diagonal from the settled pose"
    );
}

#[test]
fn small_meshes_and_the_paper_formulation_have_no_preview() {
    let mut s = ShapeSpec::default_for(Shape::Creature);
    s.params.nu = Some(2);
    let small = generate(&s).unwrap();
    let rest = Arc::new(Rest::new(small.clone()).unwrap());
    let c = ends(&small, false);
    let params = Params::default();
    let factor = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    assert!(!d.can_preview());
    assert_eq!(d.preview(&factor, &c, 3).unwrap(), None);
    assert!(!d.shows_preview());
}

/// The coarse problems built ahead of a constraint set's first solve
/// (`solver/prepared.rs`) are the ones a deformer builds on use: a gesture
/// of previews and the settle after it, with its corrections, give the
/// same shown poses and the same settled pose, bit for bit, and the same
/// reports.
#[test]
fn levels_built_ahead_solve_as_the_levels_built_on_use() {
    let (mesh, rest, mut c, factor) = creature_ends(false);
    let params = Params::default();
    let diag = mesh.diagonal();
    let mut on_use = Deformer::new(rest.clone(), params);
    let mut ahead = Deformer::new(rest.clone(), params);
    let prepared = ahead.level_plan().build(&c);
    assert!(!prepared.is_empty());
    assert!(ahead.install_levels(prepared, &factor));
    for k in 1..=6 {
        c.handles[0].target = swing(&c, diag, k as f64 / 6.0);
        let a = on_use
            .preview(&factor, &c, super::PREVIEW_ITERATIONS)
            .unwrap();
        let b = ahead
            .preview(&factor, &c, super::PREVIEW_ITERATIONS)
            .unwrap();
        assert_eq!(a.map(|r| r.iterations), b.map(|r| r.iterations), "drag {k}");
        assert_eq!(on_use.shown_pose(), ahead.shown_pose(), "drag {k}");
    }
    let a = on_use.step(&factor, &c, params.max_iters).unwrap();
    let b = ahead.step(&factor, &c, params.max_iters).unwrap();
    assert!(a.converged && a.coarse_iterations > 0, "{a:?}");
    assert_eq!(
        (a.iterations, a.coarse_iterations, a.objective.to_bits()),
        (b.iterations, b.coarse_iterations, b.objective.to_bits())
    );
    assert_eq!(on_use.pose(), ahead.pose());
    // the settle from the previews' pose is a sequence from a pose: it
    // corrects on their coarser hierarchy, not on the start's
    assert!(!ahead.elastic.on_hierarchy);
}

/// Levels built for one constrained set are not taken for another set's
/// factor (a set with half the handle's vertices), and a deformer without
/// them builds its own on use; a set with the same constrained vertices
/// (both ends handles instead of one fixed: the same factor) takes them.
#[test]
fn levels_built_for_another_set_are_refused() {
    let mesh = creature();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let params = Params::default();
    let one = ends(&mesh, false);
    let handle = &one.handles[0].vertices;
    let half = Constraints::new(
        &mesh,
        one.fixed.clone(),
        vec![("b".into(), handle[..handle.len() / 2].to_vec(), None)],
    )
    .unwrap();
    let factor = Factor::build(&rest, &params, &half).unwrap();
    let mut d = Deformer::new(rest.clone(), params);
    assert!(!d.install_levels(d.level_plan().build(&one), &factor));
    assert!(d.preview(&factor, &half, 3).unwrap().is_some());
    let both = ends(&mesh, true);
    let factor = Factor::build(&rest, &params, &both).unwrap();
    assert!(d.install_levels(d.level_plan().build(&one), &factor));
}
