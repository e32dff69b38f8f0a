//! Tests of the constraints JSON and its resolution (`spec.rs`).

use super::*;
use crate::deform::VertexSet;

#[test]
fn constraints_json_parses_all_selector_forms() {
    let j = r#"{"fixed": {"box": {"min": [0,0,0], "max": [1,1,1]}},
                "handles": [{"name": "top", "vertices": [3, 4],
                             "translate": [0,0,1], "rotate": {"axis": [0,0,1], "degrees": 90}},
                            {"vertices": {"sphere": {"center": [0,0,0], "radius": 2}},
                             "rotate": {"quaternion": [1,0,0,0]}}]}"#;
    let s: ConstraintsSpec = serde_json::from_str(j).unwrap();
    assert!(matches!(s.fixed, VertexSet::Box { .. }));
    assert_eq!(s.handles.len(), 2);
    assert!(matches!(s.handles[1].vertices, VertexSet::Sphere { .. }));
    let bad = r#"{"fixed": [0], "handles": [], "oops": 1}"#;
    assert!(serde_json::from_str::<ConstraintsSpec>(bad).is_err());
}

/// A posed grid (sheared, bent) to anchor on.
fn posed_grid() -> (Mesh, Vec<Point>) {
    let mesh = crate::deform::factor::tests::grid(8);
    let pose = mesh
        .positions()
        .iter()
        .map(|p| [p[0] + 0.1 * p[1], p[1], p[2] + 0.05 * p[0] * p[0]])
        .collect();
    (mesh, pose)
}

fn spec(j: &str) -> ConstraintsSpec {
    serde_json::from_str(j).unwrap()
}

#[test]
fn resolving_at_a_pose_holds_the_sets_where_the_pose_has_them() {
    let (mesh, pose) = posed_grid();
    let s = spec(
        r#"{"fixed": [0, 1, 2], "handles": [{"name": "h", "vertices": [40, 41],
                     "translate": [0, 0, 1]}]}"#,
    );
    let c = s.resolve_at(&mesh, Some(&pose)).unwrap();
    for (&v, p) in c.fixed.iter().zip(&c.fixed_at) {
        assert_eq!(*p, pose[v as usize]);
    }
    for (v, p) in c.handles[0].target_positions() {
        let q = pose[v as usize];
        assert_eq!(p, [q[0], q[1], q[2] + 1.0]);
    }
    // the default pivot is the posed centroid
    let b = &c.handles[0].base;
    let mid = [
        (b[0][0] + b[1][0]) / 2.0,
        (b[0][1] + b[1][1]) / 2.0,
        (b[0][2] + b[1][2]) / 2.0,
    ];
    assert_eq!(c.handles[0].target.pivot, mid);
    // resolved at rest, the same spec holds them at rest
    let r = s.resolve(&mesh).unwrap();
    assert_eq!(r.fixed_at[2], mesh.positions()[2]);
    assert_ne!(r.fixed_at[2], c.fixed_at[2]);
}

#[test]
fn an_anchored_spec_resolves_to_the_same_constraints_on_the_rest_mesh() {
    let (mesh, pose) = posed_grid();
    let s = spec(
        r#"{"fixed": [0, 1, 2, 3], "handles": [{"name": "h", "vertices": [40, 41, 47],
                     "rotate": {"axis": [0, 0, 1], "degrees": 30}},
                     {"name": "g", "vertices": [20], "pivot": [1, 2, 3]}]}"#,
    );
    let c = s.resolve_at(&mesh, Some(&pose)).unwrap();
    let stored = s.anchored(&mesh, &c);
    assert!(stored.fixed_positions.is_some());
    assert_eq!(stored.handles[1].pivot, Some([1.0, 2.0, 3.0]));
    // through JSON, as a store keeps it
    let json = serde_json::to_string(&stored).unwrap();
    let back: ConstraintsSpec = serde_json::from_str(&json).unwrap();
    assert_eq!(back.resolve(&mesh).unwrap(), c);
    // anchored at rest, nothing is written out
    let r = s.resolve(&mesh).unwrap();
    assert_eq!(s.anchored(&mesh, &r), s);
}

#[test]
fn bad_anchors_are_typed_errors() {
    let (mesh, mut pose) = posed_grid();
    let s = spec(r#"{"fixed": [0, 1], "fixed_positions": [[0, 0, 0]]}"#);
    assert!(matches!(
        s.resolve(&mesh),
        Err(DeformError::PositionsMismatch { .. })
    ));
    let s = spec(r#"{"fixed": [0, 1]}"#);
    assert!(matches!(
        s.resolve_at(&mesh, Some(&pose[1..])),
        Err(DeformError::PositionsMismatch { .. })
    ));
    pose[3][1] = f64::NAN;
    assert!(matches!(
        s.resolve_at(&mesh, Some(&pose)),
        Err(DeformError::NonFinite { .. })
    ));
}
