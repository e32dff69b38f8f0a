//! Invariance of the operators (design.md §2): after a random rotation,
//! translation and uniform scaling by `s` (10^-8 … 10^8) the normalised
//! operators are unchanged, and in mesh units `Lbar` is invariant, areas
//! scale by `s²`, `H` by `1/s`, `K` and `G` by `1/s²`. Also `Lbar · 1 = 0`
//! and `Lbar` symmetric on randomly perturbed meshes.
//!
//! Translations are drawn proportional to `s` (up to 100 mesh sizes): a
//! fixed offset of 10³ on a mesh of size 10⁻⁸ leaves no significant digits.

use dend::mesh::{Mesh, Point};
use dend::operators::{angle_defect, cotmatrix, voronoi_areas, Operators};
use dend_testkit::*;
use proptest::prelude::*;

const TOL: f64 = 1e-9;

/// Rotation matrix from a (not necessarily unit) quaternion.
fn rotation(q: [f64; 4]) -> [[f64; 3]; 3] {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    let [w, x, y, z] = q.map(|c| c / n);
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

fn transform(m: &Mesh, r: [[f64; 3]; 3], t: Point, s: f64) -> Mesh {
    let p = m
        .positions()
        .iter()
        .map(|q| {
            let mut o = [0.0; 3];
            for (k, ok) in o.iter_mut().enumerate() {
                *ok = s * (r[k][0] * q[0] + r[k][1] * q[1] + r[k][2] * q[2]) + t[k];
            }
            o
        })
        .collect();
    m.with_positions(p).unwrap()
}

fn rel(a: f64, b: f64, scale: f64) -> f64 {
    (a - b).abs() / scale
}

/// Maximum scaled discrepancy between the operators of `a` and of `b`,
/// where `b` is `a` moved rigidly and scaled by `s`.
fn discrepancy(a: &Mesh, b: &Mesh, s: f64) -> f64 {
    let (oa, ob) = (Operators::new(a), Operators::new(b));
    let mut e = (ob.scale / (oa.scale * s) - 1.0).abs();
    // normalised Lbar unchanged, entry by entry (relative to the diagonal)
    for (i, (ra, rb)) in oa
        .lbar
        .outer_iterator()
        .zip(ob.lbar.outer_iterator())
        .enumerate()
    {
        let d = oa.lbar.get(i, i).copied().unwrap_or(1.0).abs();
        assert_eq!(ra.indices(), rb.indices());
        for ((_, x), (_, y)) in ra.iter().zip(rb.iter()) {
            e = e.max(rel(*x, *y, d));
        }
    }
    // raw free functions: Lbar invariant, areas ∝ s², defects invariant
    let (la, lb) = (
        cotmatrix(a.positions(), a.triangles()),
        cotmatrix(b.positions(), b.triangles()),
    );
    for (i, (ra, rb)) in la.outer_iterator().zip(lb.outer_iterator()).enumerate() {
        let d = la.get(i, i).copied().unwrap_or(1.0).abs();
        for ((_, x), (_, y)) in ra.iter().zip(rb.iter()) {
            e = e.max(rel(*x, *y, d));
        }
    }
    let (aa, ab) = (
        voronoi_areas(a.positions(), a.triangles()),
        voronoi_areas(b.positions(), b.triangles()),
    );
    let (da, db) = (
        angle_defect(a.positions(), a.triangles(), a.topology()),
        angle_defect(b.positions(), b.triangles(), b.topology()),
    );
    let (sa, sb) = (oa.scale, ob.scale);
    for i in 0..a.num_vertices() {
        e = e.max(rel(ab[i], aa[i] * s * s, aa[i] * s * s));
        e = e.max(rel(db[i], da[i], da[i].abs().max(1.0)));
        e = e.max(rel(ob.area[i], oa.area[i], oa.area[i]));
        // mesh units: H ∝ 1/s, K and G ∝ 1/s² (compared on the curvature
        // scale 1/ℓ̄ of the mesh, as curvatures may vanish)
        let (ha, hb) = (oa.mean_curvature[i] / sa, ob.mean_curvature[i] / sb);
        e = e.max(rel(hb * s, ha, 1.0 / sa));
        let (ka, kb) = (
            oa.gaussian_curvature[i] / (sa * sa),
            ob.gaussian_curvature[i] / (sb * sb),
        );
        e = e.max(rel(kb * s * s, ka, 1.0 / (sa * sa)));
        let (ga, gb) = (oa.g[i] / (sa * sa), ob.g[i] / (sb * sb));
        e = e.max(rel(gb * s * s, ga, 1.0 / (sa * sa)));
    }
    e
}

/// An icosphere with every vertex moved radially by a random factor.
fn bumpy_sphere(bumps: &[f64]) -> Mesh {
    let m = icosphere(2, 1.0);
    let p = m
        .positions()
        .iter()
        .zip(bumps.iter().cycle())
        .map(|(q, b)| [q[0] * (1.0 + b), q[1] * (1.0 + b), q[2] * (1.0 + b)])
        .collect();
    m.with_positions(p).unwrap()
}

/// `Lbar · 1 = 0` and `Lbar = Lbarᵀ` exactly in structure, to 1e-12 in value.
fn assert_lbar_properties(m: &Mesh) {
    let l = cotmatrix(m.positions(), m.triangles());
    for (i, row) in l.outer_iterator().enumerate() {
        let d = l.get(i, i).copied().unwrap().abs();
        let sum: f64 = row.iter().map(|(_, v)| v).sum();
        assert!(sum.abs() <= 1e-12 * d, "row {i} sums to {sum}");
        for (j, v) in row.iter() {
            assert_eq!(Some(v), l.get(j, i), "Lbar({i},{j}) not symmetric");
        }
    }
    let op = Operators::new(m);
    assert_eq!(op.lbar.nnz(), l.nnz());
}

#[test]
fn lbar_annihilates_constants_and_is_symmetric() {
    assert_lbar_properties(&icosphere(3, 2.0));
    assert_lbar_properties(&torus(20, 9, 3.0, 1.0));
    assert_lbar_properties(&jittered_grid(10, 0.28));
    assert_lbar_properties(&cylinder(12, 5, 0.5, 0.3));
    if let Some(dir) = shared_meshes() {
        for f in ["hand_1502.obj", "bumpy_plane_441.off", "bar_722.off"] {
            assert_lbar_properties(&read_mesh(&dir.join(f)));
        }
    }
}

#[test]
fn extreme_scales_are_exact_enough() {
    for m in [
        icosphere(2, 1.0),
        jittered_grid(8, 0.2),
        torus(16, 8, 2.0, 0.5),
    ] {
        for s in [1e8, 1e-8] {
            let r = rotation([0.3, -0.5, 0.2, 0.7]);
            let e = discrepancy(&m, &transform(&m, r, [2.0 * s, -s, 0.5 * s], s), s);
            assert!(e < TOL, "scale {s}: discrepancy {e:e}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn rigid_motion_and_scaling(
        q in prop::array::uniform4(-1.0f64..1.0).prop_filter("non-zero", |q| q.iter().map(|x| x * x).sum::<f64>() > 1e-3),
        t in prop::array::uniform3(-100.0f64..100.0),
        log_s in -8.0f64..8.0,
        bumps in prop::collection::vec(-0.2f64..0.2, 7..31),
        which in 0usize..3,
    ) {
        let m = match which {
            0 => bumpy_sphere(&bumps),
            1 => jittered_grid(7, 0.25),
            _ => torus(12, 7, 2.0, 0.7),
        };
        let s = 10f64.powf(log_s);
        let moved = transform(&m, rotation(q), t.map(|x| x * s), s);
        let e = discrepancy(&m, &moved, s);
        prop_assert!(e < TOL, "discrepancy {:e}", e);
    }

    #[test]
    fn random_bumpy_spheres_keep_lbar_properties_and_gauss_bonnet(
        bumps in prop::collection::vec(-0.3f64..0.3, 5..40),
    ) {
        let m = bumpy_sphere(&bumps);
        assert_lbar_properties(&m);
        let total: f64 = angle_defect(m.positions(), m.triangles(), m.topology()).iter().sum();
        prop_assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-9);
    }
}
