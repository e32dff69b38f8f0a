//! Constraint edits on a posed mesh: a new constraint set resolved at the
//! pose (`ConstraintsSpec::resolve_at`) keeps the pose, where the same set
//! resolved at rest snaps the constrained vertices back.

use std::sync::Arc;

use dend::deform::{ConstraintsSpec, Deformer, Factor, Params, Rest};
use dend::mesh::Point;
use dend_testkit::{handle, max_dist, square_tube, tube_spec};

fn json(j: serde_json::Value) -> ConstraintsSpec {
    serde_json::from_value(j).unwrap()
}

#[test]
fn pinning_more_after_posing_keeps_the_pose() {
    let mesh = square_tube(1.0, 6.0, 4, 25);
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let params = Params::default();
    // pose: the top pulled sideways
    let bend = tube_spec(&mesh, handle(Some([2.0, 0.0, 0.0]), None));
    let c = bend.resolve(&mesh).unwrap();
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest.clone(), params);
    let rep = d.step(&f, &c, 300).unwrap();
    assert!(rep.converged, "{rep:?}");
    let posed: Vec<Point> = d.pose().to_vec();
    // the edit: pin the middle third of the tube as well, with the handle
    // and the bottom as they were
    let middle: Vec<u32> = (0..mesh.num_vertices() as u32)
        .filter(|&v| (2.0..4.0).contains(&mesh.positions()[v as usize][2]))
        .collect();
    let c0 = bend.resolve(&mesh).unwrap();
    let mut fixed = c0.fixed.clone();
    fixed.extend(&middle);
    let edit = json(serde_json::json!({
        "fixed": fixed,
        "handles": [{"name": "top", "vertices": c0.handles[0].vertices}],
    }));
    let at_pose = edit.resolve_at(&mesh, Some(&posed)).unwrap();
    let f2 = Factor::build(&rest, &params, &at_pose).unwrap();
    let rep = d.step(&f2, &at_pose, 300).unwrap();
    assert!(rep.converged, "{rep:?}");
    let diag = {
        let (lo, hi) = mesh.bounding_box();
        (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
    };
    let jump = max_dist(d.pose(), &posed) / diag;
    // the same edit resolved at rest pulls the middle and the top back
    let at_rest = edit.resolve(&mesh).unwrap();
    let mut d_rest = Deformer::new(rest.clone(), params);
    d_rest.set_pose(posed.clone()).unwrap();
    d_rest.step(&f2, &at_rest, 300).unwrap();
    let snap = max_dist(d_rest.pose(), &posed) / diag;
    assert!(
        snap > 0.1,
        "resolved at rest, the edit should move the tube back: {snap}"
    );
    // pinning vertices where they are changes only the rows the newly
    // constrained vertices drop: the pose moves by a small fraction
    eprintln!("pose jump {jump:.2e}, at rest {snap:.3}");
    assert!(
        jump < 0.02 * snap,
        "pose jump {jump} of the diagonal (at rest: {snap})"
    );
}
