//! The discrete operators against libigl's Python binding (the external
//! oracle of design.md §2), through `scripts/oracle/operators.py`.
//!
//! Conventions compared (raw positions, free functions):
//! - `cotmatrix` = `igl.cotmatrix` (same sign, same ½): error relative to
//!   the row's diagonal `|L_ii|` (off-diagonals may cancel to ~0);
//! - `voronoi_areas` = diagonal of `igl.massmatrix(VORONOI)`: relative;
//! - `angle_defect` = `igl.gaussian_curvature` at interior vertices and
//!   `igl.gaussian_curvature - π` at boundary vertices (our boundary rule):
//!   relative to `max(|igl|, 1 rad)` (flat regions have defects ~0);
//! - `|H|` = `|(M⁻¹ L V)_i| / 2` from igl's matrices: relative to
//!   `max(|H|, 1/ℓ̄)` with `ℓ̄` the mean edge length.
//!
//! `Operators` (the normalised copy) is then checked to carry the same
//! values once scaled back: `Lbar` invariant, areas `· s²`, `K A` invariant,
//! `H / s`.

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

use dend::mesh::Mesh;
use dend::operators::{angle_defect, cotmatrix, voronoi_areas, Operators};
use dend_testkit::*;

const TOL: f64 = 1e-9;

struct Oracle {
    l: HashMap<(usize, usize), f64>,
    m: Vec<f64>,
    k: Vec<f64>,
    h: Vec<f64>,
}

fn run_oracle(py: &Path, m: &Mesh) -> Oracle {
    let dir = tempfile::tempdir().unwrap();
    let off = dir.path().join("mesh.off");
    write_mesh(m, &off);
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/oracle/operators.py");
    let out = Command::new(py).arg(&script).arg(&off).output().unwrap();
    assert!(
        out.status.success(),
        "oracle failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    let mut lines = text.lines();
    let mut section = |tag: &str| -> Vec<String> {
        let head = lines.next().unwrap();
        let (t, n) = head.split_once(' ').unwrap();
        assert_eq!(t, tag);
        let n: usize = n.parse().unwrap();
        (0..n).map(|_| lines.next().unwrap().to_string()).collect()
    };
    let l = section("L")
        .iter()
        .map(|s| {
            let w: Vec<&str> = s.split(' ').collect();
            (
                (w[0].parse().unwrap(), w[1].parse().unwrap()),
                w[2].parse().unwrap(),
            )
        })
        .collect();
    let num = |v: Vec<String>| v.iter().map(|s| s.parse().unwrap()).collect();
    let mm = num(section("M"));
    let k = num(section("K"));
    let h = num(section("H"));
    Oracle { l, m: mm, k, h }
}

/// Max relative differences (L, M, K, H) of our operators against igl's.
fn compare(name: &str, py: &Path, m: &Mesh) -> [f64; 4] {
    let o = run_oracle(py, m);
    let n = m.num_vertices();
    let (p, t, topo) = (m.positions(), m.triangles(), m.topology());
    let lbar = cotmatrix(p, t);
    let diag: Vec<f64> = (0..n)
        .map(|i| lbar.get(i, i).copied().unwrap_or(0.0).abs())
        .collect();
    let mut e = [0.0f64; 4];
    let mut ours: HashMap<(usize, usize), f64> = HashMap::new();
    for (i, row) in lbar.outer_iterator().enumerate() {
        for (j, &v) in row.iter() {
            ours.insert((i, j), v);
        }
    }
    for (&(i, j), &v) in ours.iter().chain(o.l.iter()) {
        let a = ours.get(&(i, j)).copied().unwrap_or(0.0);
        let b = o.l.get(&(i, j)).copied().unwrap_or(0.0);
        let _ = v;
        e[0] = e[0].max((a - b).abs() / diag[i]);
    }
    let area = voronoi_areas(p, t);
    let defect = angle_defect(p, t, topo);
    let op = Operators::new(m);
    let hbar = 1.0 / m.mean_edge_length();
    for i in 0..n {
        e[1] = e[1].max((area[i] - o.m[i]).abs() / o.m[i]);
        let k_igl = if topo.is_boundary(i) {
            o.k[i] - std::f64::consts::PI
        } else {
            o.k[i]
        };
        e[2] = e[2].max((defect[i] - k_igl).abs() / k_igl.abs().max(1.0));
        let h = op.mean_curvature[i].abs() / op.scale;
        e[3] = e[3].max((h - o.h[i]).abs() / o.h[i].max(hbar));
        // Operators on the normalised copy, scaled back to mesh units
        let s = op.scale;
        assert!(
            (op.area[i] * s * s - o.m[i]).abs() <= TOL * o.m[i],
            "{name}: A[{i}]"
        );
        let ka = op.gaussian_curvature[i] * op.area[i];
        assert!(
            (ka - k_igl).abs() <= TOL * k_igl.abs().max(1.0),
            "{name}: K A[{i}]"
        );
    }
    for (i, row) in op.lbar.outer_iterator().enumerate() {
        for (j, &v) in row.iter() {
            let b = o.l.get(&(i, j)).copied().unwrap_or(0.0);
            assert!(
                (v - b).abs() <= TOL * diag[i],
                "{name}: Operators Lbar({i},{j})"
            );
        }
    }
    println!(
        "{name} (V={n}): max rel diff  L {:.2e}  M {:.2e}  K {:.2e}  |H| {:.2e}",
        e[0], e[1], e[2], e[3]
    );
    for (what, x) in ["cotmatrix", "massmatrix", "gaussian_curvature", "|H|"]
        .iter()
        .zip(e)
    {
        assert!(
            x <= TOL,
            "{name}: {what} differs from libigl by {x:e} (relative)"
        );
    }
    e
}

#[test]
fn operators_match_libigl_on_generated_meshes() {
    let Some(py) = oracle_python() else { return };
    // off-centre, non-unit sphere; jittered open grid lifted into a paraboloid;
    // a torus (genus 1) and an open cylinder
    let ico = icosphere(2, 1.3);
    let moved: Vec<_> = ico
        .positions()
        .iter()
        .map(|q| [q[0] + 3.0, q[1] - 1.0, q[2] + 0.5])
        .collect();
    compare("icosphere(2)", &py, &ico.with_positions(moved).unwrap());
    let g = jittered_grid(9, 0.25);
    let lifted: Vec<_> = g
        .positions()
        .iter()
        .map(|q| {
            [
                q[0],
                q[1],
                0.7 * (q[0] - 0.4).powi(2) - 0.3 * (q[1] - 0.5).powi(2),
            ]
        })
        .collect();
    compare("saddle grid(9)", &py, &g.with_positions(lifted).unwrap());
    compare("torus(24x12)", &py, &torus(24, 12, 2.0, 0.6));
    compare("cylinder(16x7)", &py, &cylinder(16, 7, 1.0, 0.4));
}

#[test]
fn operators_match_libigl_on_shared_meshes() {
    let Some(dir) = shared_meshes() else { return };
    let Some(py) = oracle_python() else { return };
    for f in [
        "torus_288.off",
        "hand_1502.obj",
        "bumpy_plane_441.off",
        "cylinder_tube_600.off",
        "camel_9770.off",
    ] {
        compare(f, &py, &read_mesh(&dir.join(f)));
    }
}
