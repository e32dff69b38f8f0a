//! The drag loop in the core, as a session runs it: a handle
//! dragged along a turning arc in many target changes, one iteration after
//! each (a frame per drag), then the settle in one-iteration steps (a frame
//! each) until converged or `max_iters`. The settled pose must converge
//! and reach the objective of the one-shot solve of the final target from
//! rest (within 1 %, or below it: the energy is not convex, and a path may
//! end in another minimum).
//!
//! On the camel the settle used to crawl: its first coarse correction did
//! not converge within its cap, was skipped, and ended the corrections
//! (100 iterations without converging; `examples/drag_sim.rs` prints the
//! figures of any mesh).

use std::sync::Arc;

use dend::deform::{Constraints, Deformer, Factor, Params, Rest, RigidTransform, StepReport};
use dend::mesh::gen::{generate, Shape, ShapeSpec};
use dend::mesh::{Mesh, Point};
use nalgebra::{UnitQuaternion, Vector3};

/// The load test's edit: the lowest 10 % along the longest axis fixed,
/// the highest 10 % the handle.
fn edit(mesh: &Mesh) -> (Constraints, usize, f64) {
    let (lo, hi) = mesh.bounding_box();
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap();
    let extent = hi[axis] - lo[axis];
    let n = mesh.num_vertices() as u32;
    let at = |v: u32| mesh.positions()[v as usize][axis];
    let fixed = (0..n)
        .filter(|&v| at(v) < lo[axis] + 0.1 * extent)
        .collect();
    let handle = (0..n)
        .filter(|&v| at(v) > hi[axis] - 0.1 * extent)
        .collect();
    let c = Constraints::new(mesh, fixed, vec![("h".into(), handle, None)]).unwrap();
    (c, axis, extent)
}

/// The target after a fraction `s` of the path: 0.3 of the extent across
/// the long axis, bowed out and back along an arc, turning 60° about the
/// long axis.
fn target_at(s: f64, axis: usize, extent: f64, pivot: Point) -> RigidTransform {
    let mut t = [0.0; 3];
    t[(axis + 1) % 3] = 0.3 * extent * s;
    t[(axis + 2) % 3] = 0.15 * extent * (std::f64::consts::PI * s).sin();
    let mut a = Vector3::zeros();
    a[axis] = 60f64.to_radians() * s;
    RigidTransform {
        rotation: UnitQuaternion::from_scaled_axis(a),
        translation: t,
        pivot,
    }
}

/// (one-shot report, settle report, settle iterations) for `drags` drags.
fn drag_and_settle(mesh: &Mesh, drags: usize) -> (StepReport, StepReport, usize) {
    let params = Params::default();
    let (mut c, axis, extent) = edit(mesh);
    let pivot = c.handles[0].rest_centroid;
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let factor = Factor::build(&rest, &params, &c).unwrap();
    c.handles[0].target = target_at(1.0, axis, extent, pivot);
    let one = Deformer::new(rest.clone(), params)
        .step(&factor, &c, params.max_iters)
        .unwrap();
    let mut d = Deformer::new(rest, params);
    for k in 1..=drags {
        c.handles[0].target = target_at(k as f64 / drags as f64, axis, extent, pivot);
        let r = d.step(&factor, &c, 1).unwrap();
        assert!(r.objective.is_finite());
    }
    let mut its = 0;
    loop {
        let r = d.step(&factor, &c, 1).unwrap();
        its += r.iterations;
        if r.converged || r.diverged || its >= params.max_iters {
            return (one, r, its);
        }
    }
}

fn check(what: &str, mesh: &Mesh, drags: usize) {
    let (one, settled, its) = drag_and_settle(mesh, drags);
    eprintln!(
        "{what}, {drags} drags: one-shot {} iterations, objective {:.6}; settle {its} iterations, \
         converged {}, objective {:.6} ({:.4}x)",
        one.iterations,
        one.objective,
        settled.converged,
        settled.objective,
        settled.objective / one.objective
    );
    assert!(one.converged, "{what}: the one-shot solve converged");
    assert!(
        settled.converged && !settled.diverged,
        "{what}, {drags} drags: the settle did not converge in {its} iterations"
    );
    assert!(
        settled.objective <= 1.01 * one.objective,
        "{what}, {drags} drags: settled objective {} against the one-shot {}",
        settled.objective,
        one.objective
    );
}

#[test]
fn a_dragged_creature_settles_as_low_as_a_one_shot_solve() {
    let mut spec = ShapeSpec::default_for(Shape::Creature);
    spec.params.nu = Some(3);
    let mesh = generate(&spec).unwrap();
    for drags in [10, 60] {
        check("creature (3 levels)", &mesh, drags);
    }
}

#[test]
fn a_dragged_camel_settles_as_low_as_a_one_shot_solve() {
    let Some(mesh) = dend_testkit::shared_mesh("camel_9770.off") else {
        return;
    };
    for drags in [10, 60] {
        check("camel", &mesh, drags);
    }
}

/// Held corrections (a session holds them while a person drags) run no
/// coarse work at all, and the first step after the hold ends runs the
/// correction that was due; the same steps unheld run corrections.
#[test]
fn held_corrections_wait_for_the_end_of_the_gesture() {
    let mut spec = ShapeSpec::default_for(Shape::Creature);
    spec.params.nu = Some(3);
    let mesh = generate(&spec).unwrap();
    let params = Params::default();
    let (c, axis, extent) = edit(&mesh);
    let pivot = c.handles[0].rest_centroid;
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let factor = Factor::build(&rest, &params, &c).unwrap();
    // (coarse iterations in 12 one-iteration steps at the final target,
    // coarse iterations of the step after them)
    let run = |hold: bool| -> (usize, usize) {
        let mut d = Deformer::new(rest.clone(), params);
        let mut c = c.clone();
        for k in 1..=10 {
            c.handles[0].target = target_at(k as f64 / 10.0, axis, extent, pivot);
            d.step(&factor, &c, 1).unwrap();
        }
        d.hold_corrections(hold);
        let during: usize = (0..12)
            .map(|_| d.step(&factor, &c, 1).unwrap().coarse_iterations)
            .sum();
        d.hold_corrections(false);
        let after = d.step(&factor, &c, 1).unwrap().coarse_iterations;
        (during, after)
    };
    let (held, first_after) = run(true);
    let (free, _) = run(false);
    eprintln!("coarse iterations: held {held} then {first_after}; unheld {free}");
    assert_eq!(held, 0, "a held step ran coarse work");
    assert!(
        free > 0,
        "the unheld steps ran no correction: the test shows nothing"
    );
    assert!(first_after > 0, "the step after the hold ran no correction");
}
