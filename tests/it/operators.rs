//! Hand-computed and analytic checks of the discrete operators (design.md §2):
//! exact values on regular solids, Gauss–Bonnet on every mesh, flat grids,
//! spheres (with measured convergence orders) and cylinders.

use std::f64::consts::PI;

use dend::mesh::Mesh;
use dend::operators::{angle_defect, cotmatrix, voronoi_areas, Operators};
use dend_testkit::*;

/// `Σ_i K_i A_i = 2π χ` to 1e-9, both from the free `angle_defect` and from
/// `Operators` (where `K_i A_i` is scale-free). On open meshes this holds
/// because of the boundary rule `π - Σθ` (see `angle_defect`).
fn assert_gauss_bonnet(m: &Mesh) {
    let chi = m.euler_characteristic() as f64;
    let d: f64 = angle_defect(m.positions(), m.triangles(), m.topology())
        .iter()
        .sum();
    assert!(
        (d - 2.0 * PI * chi).abs() < 1e-9,
        "Σ defect {d} vs 2π·{chi}"
    );
    let op = Operators::new(m);
    let ka: f64 = (0..m.num_vertices())
        .map(|i| op.gaussian_curvature[i] * op.area[i])
        .sum();
    assert!((ka - 2.0 * PI * chi).abs() < 1e-9, "Σ K A {ka} vs 2π·{chi}");
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1.0)
}

/// Checks `Lbar` of a mesh whose every edge has weight `w` and whose every
/// vertex has degree `deg`: off-diagonals `w` on edges, 0 elsewhere.
fn assert_uniform_lbar(m: &Mesh, w: f64, deg: usize) {
    let l = cotmatrix(m.positions(), m.triangles());
    for i in 0..m.num_vertices() {
        let ring = m.topology().ring(i);
        for j in 0..m.num_vertices() {
            let want = if i == j {
                -w * deg as f64
            } else if ring.contains(&(j as u32)) {
                w
            } else {
                0.0
            };
            let got = l.get(i, j).copied().unwrap_or(0.0);
            assert!(close(got, want, 1e-14), "Lbar({i},{j}) {got} vs {want}");
        }
    }
}

#[test]
fn equilateral_triangle_exact_values() {
    let m = equilateral_triangle();
    let s3 = 3f64.sqrt();
    // every edge is a boundary edge: one term, ½ cot 60° = 1/(2√3)
    assert_uniform_lbar(&m, 0.5 / s3, 2);
    let a = voronoi_areas(m.positions(), m.triangles());
    for ai in a {
        assert!(close(ai, s3 / 12.0, 1e-15));
    }
    // boundary rule: π - π/3 at every corner; Σ = 2π = 2π χ (χ = 1)
    for d in angle_defect(m.positions(), m.triangles(), m.topology()) {
        assert!(close(d, 2.0 * PI / 3.0, 1e-15));
    }
    assert_gauss_bonnet(&m);
}

#[test]
fn regular_tetrahedron_exact_values() {
    // edge 2√2, circumradius √3, four equilateral faces of area 2√3
    let m = tetrahedron();
    let s3 = 3f64.sqrt();
    assert_uniform_lbar(&m, 1.0 / s3, 3); // ½(cot 60° + cot 60°)
    let op = Operators::new(&m);
    let s = op.scale;
    assert!(close(s, 2.0 * 2f64.sqrt(), 1e-15));
    for i in 0..4 {
        let area = op.area[i] * s * s;
        assert!(close(area, 2.0 * s3, 1e-14), "A {area}");
        // defect 2π - 3·π/3 = π
        assert!(close(op.gaussian_curvature[i] * op.area[i], PI, 1e-14));
        assert!(close(
            op.gaussian_curvature[i] / (s * s),
            PI / (2.0 * s3),
            1e-14
        ));
        // (L X)_i = -(4/6) X_i, so H = 1/√3 = 1/R, positive (outward normals)
        assert!(close(op.mean_curvature[i] / s, 1.0 / s3, 1e-14));
        let h = 1.0 / s3;
        let g = (h * h - PI / (2.0 * s3)).max(0.0);
        assert!(close(op.g[i] / (s * s), g, 1e-14));
    }
    assert_gauss_bonnet(&m);
}

#[test]
fn regular_octahedron_exact_values() {
    // vertices ±e_k, edge √2, faces of area √3/2, circumradius 1
    let m = octahedron();
    let s3 = 3f64.sqrt();
    assert_uniform_lbar(&m, 1.0 / s3, 4);
    let op = Operators::new(&m);
    let s = op.scale;
    for i in 0..6 {
        assert!(close(op.area[i] * s * s, 2.0 / s3, 1e-14));
        // defect 2π - 4·π/3 = 2π/3, K = π/√3
        assert!(close(
            op.gaussian_curvature[i] * op.area[i],
            2.0 * PI / 3.0,
            1e-14
        ));
        assert!(close(op.gaussian_curvature[i] / (s * s), PI / s3, 1e-14));
        // (L X)_i = -2 X_i: H = 1 = 1/R exactly
        assert!(close(op.mean_curvature[i] / s, 1.0, 1e-14));
        // H² - K = 1 - π/√3 < 0: clamped to 0
        assert_eq!(op.g[i], 0.0);
    }
    assert_gauss_bonnet(&m);
}

#[test]
fn gauss_bonnet_on_closed_and_open_meshes() {
    assert_gauss_bonnet(&icosphere(3, 0.7)); // χ = 2
    assert_gauss_bonnet(&uv_sphere(9, 20, 3.0)); // χ = 2
    assert_gauss_bonnet(&torus(24, 12, 2.0, 0.6)); // χ = 0
    assert_gauss_bonnet(&jittered_grid(9, 0.25)); // open disc, χ = 1
    assert_gauss_bonnet(&cylinder(16, 7, 1.0, 0.4)); // open annulus, χ = 0
    if let Some(dir) = shared_meshes() {
        for f in [
            "torus_288.off",
            "hand_1502.obj",
            "bumpy_plane_441.off",
            "cylinder_tube_600.off",
        ] {
            assert_gauss_bonnet(&read_mesh(&dir.join(f)));
        }
    }
}

#[test]
fn flat_grid_has_zero_curvature_inside() {
    // planar triangulations (regular or jittered): the cotangent Laplacian
    // reproduces linear functions, so L X = 0 and the angle sum is 2π inside
    for m in [jittered_grid(7, 0.0), jittered_grid(11, 0.28)] {
        let op = Operators::new(&m);
        let mut interior = 0;
        for i in 0..m.num_vertices() {
            if m.topology().is_boundary(i) {
                continue;
            }
            interior += 1;
            assert!(
                op.mean_curvature[i].abs() < 1e-12,
                "H {}",
                op.mean_curvature[i]
            );
            assert!(op.gaussian_curvature[i].abs() < 1e-12);
            assert!(op.g[i].abs() < 1e-12);
        }
        assert!(interior > 0);
        let total: f64 = op.area.iter().sum::<f64>() * op.scale * op.scale;
        assert!(close(total, 1.0, 1e-13), "area of the unit square {total}");
    }
}

/// Max over vertices of `|H r - 1|` and `|K r² - 1|` (mesh units), and the
/// mesh's mean edge length.
fn sphere_errors(m: &Mesh, r: f64) -> (f64, f64, f64) {
    let op = Operators::new(m);
    let s = op.scale;
    let (mut eh, mut ek) = (0.0f64, 0.0f64);
    for i in 0..m.num_vertices() {
        eh = eh.max((op.mean_curvature[i] / s * r - 1.0).abs());
        ek = ek.max((op.gaussian_curvature[i] / (s * s) * r * r - 1.0).abs());
    }
    (s, eh, ek)
}

/// Observed orders `log(e_k / e_{k+1}) / log(h_k / h_{k+1})` of a refinement
/// sequence of `(h, error)` pairs.
fn orders(seq: &[(f64, f64)]) -> Vec<f64> {
    seq.windows(2)
        .map(|w| (w[0].1 / w[1].1).ln() / (w[0].0 / w[1].0).ln())
        .collect()
}

#[test]
fn sphere_curvatures_converge_at_second_order() {
    // Measured (max over all vertices, including the valence-5 ones):
    // icosphere levels 2..6: |Hr-1| 1.4e-4 → 5.4e-7, |Kr²-1| 2.0e-2 → 8.9e-5,
    // both order 2.00 ± 0.03; UV spheres 16..128 rings: orders 1.9–2.0.
    let r = 2.0;
    let ico: Vec<_> = (2..=5)
        .map(|l| sphere_errors(&icosphere(l, r), r))
        .collect();
    let uv: Vec<_> = [16u32, 32, 64]
        .iter()
        .map(|&n| sphere_errors(&uv_sphere(n - 1, 2 * n, r), r))
        .collect();
    for (name, seq) in [("icosphere", &ico), ("uv sphere", &uv)] {
        let h: Vec<_> = seq.iter().map(|e| (e.0, e.1)).collect();
        let k: Vec<_> = seq.iter().map(|e| (e.0, e.2)).collect();
        for (what, o) in [("H", orders(&h)), ("K", orders(&k))] {
            println!("{name}: observed orders of {what}: {o:.3?}");
            for x in o {
                assert!((1.8..=2.2).contains(&x), "{name} {what} order {x}");
            }
        }
        let last = seq.last().unwrap();
        assert!(
            last.1 < 1e-3 && last.2 < 1e-2,
            "{name} finest errors {last:?}"
        );
    }
}

#[test]
fn cylinder_has_k_zero_and_h_half_inverse_radius_inside() {
    // Rings aligned, quads planar: the angle sum is exactly 2π inside, and
    // the cotangent mean-curvature normal of this prism is exactly 1/(2r)
    // (measured |2rH - 1| ≤ 7e-13 up to 128 segments, round-off only).
    for (seg, r, dz) in [
        (8u32, 1.5, 0.3),
        (24, 0.5, 0.2),
        (64, 2.0, 0.05),
        (128, 1.0, 0.7),
    ] {
        let m = cylinder(seg, 6, r, dz);
        let op = Operators::new(&m);
        let s = op.scale;
        let mut interior = 0;
        for i in 0..m.num_vertices() {
            if m.topology().is_boundary(i) {
                continue;
            }
            interior += 1;
            let (h, k) = (op.mean_curvature[i] / s, op.gaussian_curvature[i] / (s * s));
            assert!(
                (2.0 * r * h - 1.0).abs() < 1e-10,
                "seg {seg}: 2rH = {}",
                2.0 * r * h
            );
            assert!(k.abs() * r * r < 1e-12, "seg {seg}: K = {k}");
            // G = H² - K = (1/(2r))²: (k1 - k2)/2 with k1 = 1/r, k2 = 0
            assert!((op.g[i] / (s * s) * 4.0 * r * r - 1.0).abs() < 1e-9);
        }
        assert_eq!(interior, seg as usize * 4);
    }
}
