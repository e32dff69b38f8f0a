//! [`Deformer::turn_rotations`] against its formula, computed here
//! vertex by vertex and triangle by triangle.

use std::sync::Arc;

use nalgebra::{UnitQuaternion, Vector3};

use super::test_util::creature_moved;
use crate::deform::{Deformer, Factor, Params, Rest};
use crate::mesh::gen::{generate, Shape, ShapeSpec};
use crate::mesh::Real;

/// `R_i ← exp(w_i) R_i` where the vertex's rotation is fitted (the others
/// unchanged) and `P_t ← exp(w_{t0}) P_t` for every area target, from a
/// solved pose's rotations and an uneven field of turns, to rounding.
#[test]
fn turning_applies_each_vertexs_exponential_to_its_rotation_and_its_triangles() {
    let mesh = generate(&ShapeSpec::default_for(Shape::Creature)).unwrap();
    let n = mesh.num_vertices();
    let c = creature_moved(&mesh);
    let params = Params::default();
    let rest = Arc::new(Rest::new(mesh).unwrap());
    let f = Factor::build(&rest, &params, &c).unwrap();
    let (el, set) = f.elastic.as_ref().unwrap();
    let mut d = Deformer::new(rest.clone(), params);
    d.step(&f, &c, 3).unwrap();
    let (rot0, proj0) = (d.elastic.rot.clone(), d.elastic.proj.clone());
    let w: Vec<Vector3<Real>> = (0..n)
        .map(|i| {
            let t = i as Real;
            Vector3::new((0.37 * t).sin(), (0.11 * t).cos(), 0.5 * (0.07 * t).sin()) * 0.8
        })
        .collect();
    d.turn_rotations((el, set), &w);
    for i in 0..n {
        let want = if set.fit[i] {
            UnitQuaternion::from_scaled_axis(w[i]) * rot0[i]
        } else {
            rot0[i]
        };
        assert!(
            d.elastic.rot[i].angle_to(&want) < 1e-12,
            "vertex {i} of {n}"
        );
    }
    let first: Vec<usize> = el.area_first_vertices().collect();
    assert_eq!(first.len(), proj0.len());
    for (t, (&v0, p)) in first.iter().zip(&proj0).enumerate() {
        let q = UnitQuaternion::from_scaled_axis(w[v0]);
        let c0 = q * Vector3::new(p[0], p[1], p[2]);
        let c1 = q * Vector3::new(p[3], p[4], p[5]);
        let got = d.elastic.proj[t];
        let want = [c0[0], c0[1], c0[2], c1[0], c1[1], c1[2]];
        for k in 0..6 {
            assert!((got[k] - want[k]).abs() < 1e-12, "triangle {t} of {n}");
        }
    }
}
