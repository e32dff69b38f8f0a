//! Every generator validates and has its documented counts and topology.

use dend::mesh::gen::{generate, Shape, ShapeSpec};
use dend::mesh::{cross, dot, sub, Mesh};

/// Signed volume `Σ a·(b×c)/6` (positive for outward-oriented closed meshes).
fn signed_volume(m: &Mesh) -> f64 {
    m.triangles()
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| m.positions()[i as usize]);
            dot(a, cross(b, c)) / 6.0
        })
        .sum()
}

fn normal(m: &Mesh, f: usize) -> [f64; 3] {
    let [a, b, c] = m.triangles()[f].map(|i| m.positions()[i as usize]);
    cross(sub(b, a), sub(c, a))
}

/// (shape, V, F, boundary loops, genus)
const TABLE: [(Shape, usize, usize, usize, i64); 9] = [
    (Shape::Bar, 856, 1708, 0, 0),
    (Shape::Cylinder, 1088, 2112, 2, 0),
    (Shape::Flag, 289, 512, 1, 0),
    (Shape::Plane, 2115, 4048, 1, 0),
    (Shape::BumpyPlane, 2115, 4048, 1, 0),
    (Shape::Torus, 576, 1152, 0, 1),
    (Shape::Saddle, 2025, 3872, 1, 0),
    (Shape::WavySheet, 2025, 3872, 1, 0),
    (Shape::Limb, 302, 600, 0, 0),
];

#[test]
fn defaults_match_the_documented_table() {
    for (s, v, f, loops, genus) in TABLE {
        let m = generate(&ShapeSpec::default_for(s)).unwrap();
        assert_eq!(m.num_vertices(), v, "{s:?}");
        assert_eq!(m.num_triangles(), f, "{s:?}");
        assert_eq!(m.topology().boundary_loops().len(), loops, "{s:?}");
        assert_eq!(m.genus(), genus, "{s:?}");
        assert_eq!(m.topology().num_components(), 1, "{s:?}");
        assert!(m.unreferenced_vertices().is_empty(), "{s:?}");
    }
}

#[test]
fn closed_shapes_have_positive_volume_and_open_ones_face_out() {
    let bar = generate(&ShapeSpec::default_for(Shape::Bar)).unwrap();
    assert!(
        (signed_volume(&bar) - 6.0).abs() < 1e-9,
        "bar volume {}",
        signed_volume(&bar)
    );
    let torus = generate(&ShapeSpec::default_for(Shape::Torus)).unwrap();
    // polygonal torus: a bit less than 2π²Rr² = 3.158
    let v = signed_volume(&torus);
    assert!(v > 2.9 && v < 3.16, "torus volume {v}");
    // the limb: a tube of radius 0.3, length 3 with cone caps, a bit
    // less than π 0.3² 3 + 2 · π 0.3³ / 3 = 0.905
    let v = signed_volume(&generate(&ShapeSpec::default_for(Shape::Limb)).unwrap());
    assert!(v > 0.8 && v < 0.905, "limb volume {v}");
    let cyl = generate(&ShapeSpec::default_for(Shape::Cylinder)).unwrap();
    for f in 0..cyl.num_triangles() {
        let c = cyl.triangles()[f].map(|i| cyl.positions()[i as usize]);
        let centre = [
            (c[0][0] + c[1][0] + c[2][0]) / 3.0,
            (c[0][1] + c[1][1] + c[2][1]) / 3.0,
            0.0,
        ];
        assert!(
            dot(normal(&cyl, f), centre) > 0.0,
            "cylinder face {f} points inward"
        );
    }
    for s in [Shape::Flag, Shape::Plane] {
        let m = generate(&ShapeSpec::default_for(s)).unwrap();
        assert!(
            (0..m.num_triangles()).all(|f| normal(&m, f)[2] > 0.0),
            "{s:?}"
        );
    }
}

#[test]
fn long_axis_is_z_with_the_fixed_end_at_zero() {
    for s in [Shape::Bar, Shape::Cylinder] {
        let m = generate(&ShapeSpec::default_for(s)).unwrap();
        let (lo, hi) = m.bounding_box();
        assert_eq!(lo[2], 0.0, "{s:?}");
        assert!((hi[2] - 6.0).abs() < 1e-12, "{s:?}");
        assert!(
            hi[0] - lo[0] <= 2.0 + 1e-12 && hi[1] - lo[1] <= 2.0 + 1e-12,
            "{s:?}"
        );
    }
}

#[test]
fn bumpy_plane_is_a_smooth_height_field_and_plane_is_flat() {
    let plane = generate(&ShapeSpec::default_for(Shape::Plane)).unwrap();
    assert!(plane.positions().iter().all(|p| p[2] == 0.0));
    let bumpy = generate(&ShapeSpec::default_for(Shape::BumpyPlane)).unwrap();
    let zmax = bumpy.positions().iter().map(|p| p[2]).fold(0.0, f64::max);
    assert!(zmax > 0.09 && zmax < 0.12, "bump height {zmax}");
    // same x, y as the plane
    for (a, b) in plane.positions().iter().zip(bumpy.positions()) {
        assert_eq!((a[0], a[1]), (b[0], b[1]));
    }
}

#[test]
fn parameters_change_the_counts() {
    let mut s = ShapeSpec::default_for(Shape::Bar);
    s.params.nu = Some(2);
    s.params.nv = Some(3);
    let m = generate(&s).unwrap();
    assert_eq!(m.num_vertices(), 4 * 2 * 4 + 2);
    assert_eq!(m.genus(), 0);
    let mut s = ShapeSpec::default_for(Shape::Torus);
    s.params.nu = Some(5);
    s.params.nv = Some(3);
    assert_eq!(generate(&s).unwrap().num_vertices(), 15);
    let s: ShapeSpec =
        serde_json::from_str(r#"{"shape": "bumpy-plane", "params": {"nu": 3, "nv": 4}}"#).unwrap();
    assert_eq!(generate(&s).unwrap().num_vertices(), 12);
}
