//! Steps from the rest pose. One towards the rest positions (a new
//! session's first constraint set, anchored where the mesh is) is
//! converged after one plain iteration, builds no coarse problem, and
//! leaves the next step as a new deformer's. One whose coarse start is
//! held takes the one-level start and still settles to the minimum.

use std::sync::Arc;

use super::test_util::{creature_moved, max_dist};
use crate::deform::{Deformer, Factor, Levels, Params, Rest};
use crate::mesh::gen::{creature_constraints, generate, Shape, ShapeSpec};

#[test]
fn a_step_towards_the_rest_positions_is_one_plain_iteration_and_changes_nothing_after() {
    let mesh = generate(&ShapeSpec::default_for(Shape::Creature)).unwrap();
    let diag = mesh.diagonal();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let params = Params::default();
    let at_rest = creature_constraints(&mesh).resolve(&mesh).unwrap();
    let moved = creature_moved(&mesh);
    let factor = Factor::build(&rest, &params, &at_rest).unwrap();

    // one iteration, no coarse start: the rest pose, objective 0 to
    // rounding
    let mut d = Deformer::new(rest.clone(), params);
    let r = d.step(&factor, &at_rest, 100).unwrap();
    assert!(r.converged && r.iterations == 1, "{r:?}");
    assert!(r.coarse_iterations == 0 && r.objective <= 1e-9, "{r:?}");
    assert!(d.coarse.is_none(), "a coarse problem was built");
    assert!(max_dist(d.pose(), mesh.positions()) <= 1e-12 * diag);

    // the rest pose is the minimum: the same step from the rest pose set
    // as a pose (which refits and iterates) stays there
    let mut refit = Deformer::new(rest.clone(), params);
    refit.set_pose(mesh.positions().to_vec()).unwrap();
    let r = refit.step(&factor, &at_rest, 100).unwrap();
    assert!(r.converged && r.iterations <= 1, "{r:?}");
    assert!(r.objective <= 1e-9, "{r:?}");
    assert!(max_dist(refit.pose(), mesh.positions()) <= 1e-6 * diag);

    // the next step is the one a new deformer takes (a coarse start from
    // the rest pose): the same iterations, the pose to rounding
    let factor_moved = Factor::build(&rest, &params, &moved).unwrap();
    let after = d.step(&factor_moved, &moved, 1000).unwrap();
    let mut fresh = Deformer::new(rest, params);
    let direct = fresh.step(&factor_moved, &moved, 1000).unwrap();
    assert!(after.converged && after.coarse_iterations > 0, "{after:?}");
    assert_eq!(after.iterations, direct.iterations);
    assert!((after.objective - direct.objective).abs() <= 1e-9 * direct.objective);
    assert!(max_dist(d.pose(), fresh.pose()) <= 1e-9 * diag);
}

/// A held coarse start (`Deformer::hold_coarse_start`, a session's drag
/// while the solver is contended) takes the one-level start: its first
/// iteration is a one-level deformer's, to rounding, with no coarse
/// problem built; once released, the corrections settle it to the
/// minimum a coarse-started solve reaches.
#[test]
fn a_held_coarse_start_propagates_and_settles_to_the_same_minimum() {
    let mesh = generate(&ShapeSpec::default_for(Shape::Creature)).unwrap();
    let diag = mesh.diagonal();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let params = Params::default();
    let moved = creature_moved(&mesh);
    let factor = Factor::build(&rest, &params, &moved).unwrap();

    let mut held = Deformer::new(rest.clone(), params);
    // (a session holds the corrections too while it holds the start)
    held.hold_coarse_start(true);
    held.hold_corrections(true);
    let first = held.step(&factor, &moved, 1).unwrap();
    assert_eq!(first.coarse_iterations, 0, "{first:?}");
    assert!(held.coarse.is_none(), "a coarse problem was built");
    let mut one = Deformer::new(rest.clone(), params);
    one.set_levels(Levels::One);
    let one_first = one.step(&factor, &moved, 1).unwrap();
    assert!(max_dist(held.pose(), one.pose()) <= 1e-12 * diag);
    assert!((first.objective - one_first.objective).abs() <= 1e-12 * one_first.objective);

    held.hold_coarse_start(false);
    held.hold_corrections(false);
    let settled = held.step(&factor, &moved, 1000).unwrap();
    let mut fresh = Deformer::new(rest, params);
    let direct = fresh.step(&factor, &moved, 1000).unwrap();
    assert!(
        settled.converged && direct.converged,
        "{settled:?} {direct:?}"
    );
    assert!(
        settled.coarse_iterations > 0,
        "no correction ran: {settled:?}"
    );
    assert!(
        settled.objective <= direct.objective * (1.0 + 1e-3),
        "{} against {}",
        settled.objective,
        direct.objective
    );
    assert!(max_dist(held.pose(), fresh.pose()) <= 1e-2 * diag);
}
