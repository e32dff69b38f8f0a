//! Meshes and the standard edit shared by `benches/dend.rs` and
//! `examples/dend_bench.rs` (included there with `#[path]`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use dend::deform::{Constraints, RigidTransform};
use dend::mesh::{Mesh, Point};
use nalgebra::{UnitQuaternion, Vector3};

/// The shared meshes folder: `$DEND_MESHES`, else `<crate>/../shared/meshes`.
pub fn meshes_dir() -> PathBuf {
    std::env::var_os("DEND_MESHES")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes"))
}

/// Reads a shared mesh by file name, or `None` (with a note) when absent.
pub fn shared(name: &str) -> Option<Mesh> {
    let path = meshes_dir().join(name);
    if !path.exists() {
        eprintln!("skipping: {} not found", path.display());
        return None;
    }
    match read_mesh(&path) {
        Ok(m) => Some(m),
        Err(e) => {
            eprintln!("skipping: {}: {e}", path.display());
            None
        }
    }
}

/// A closed-side cylindrical tube along z: radius 1, height `h`, `around`
/// vertices per ring, `rings` rings (open at both ends).
pub fn tube(around: usize, rings: usize, h: f64) -> Mesh {
    let mut p = Vec::with_capacity(around * rings);
    for r in 0..rings {
        let z = h * r as f64 / (rings - 1) as f64;
        for s in 0..around {
            let a = std::f64::consts::TAU * (s as f64 + 0.5 * (r % 2) as f64) / around as f64;
            p.push([a.cos(), a.sin(), z]);
        }
    }
    let mut t = Vec::with_capacity(2 * around * (rings - 1));
    let n = around as u32;
    for r in 0..rings as u32 - 1 {
        for s in 0..n {
            let a = r * n + s;
            let b = r * n + (s + 1) % n;
            let c = (r + 1) * n + s;
            let d = (r + 1) * n + (s + 1) % n;
            t.push([a, b, c]);
            t.push([b, d, c]);
        }
    }
    Mesh::new(p, t).expect("valid tube")
}

/// A tube with about `n` vertices and aspect ratio 4 (height 4 × diameter).
pub fn tube_of_size(n: usize) -> Mesh {
    // rings ≈ around · 8/π for roughly square quads on a height-8 tube.
    let around = ((n as f64 * std::f64::consts::PI / 8.0).sqrt())
        .round()
        .max(8.0) as usize;
    let rings = (n / around).max(3);
    let h = 8.0 * (rings - 1) as f64 / (around as f64 / std::f64::consts::PI);
    tube(around, rings, h.max(1.0))
}

/// One 1→4 midpoint subdivision (positions of old vertices unchanged).
pub fn subdivide(mesh: &Mesh) -> Mesh {
    use std::collections::HashMap;
    let mut p: Vec<Point> = mesh.positions().to_vec();
    let mut mid: HashMap<(u32, u32), u32> = HashMap::new();
    let mut t = Vec::with_capacity(4 * mesh.num_triangles());
    let mut m = |a: u32, b: u32, p: &mut Vec<Point>| {
        let key = (a.min(b), a.max(b));
        *mid.entry(key).or_insert_with(|| {
            let (x, y) = (p[a as usize], p[b as usize]);
            p.push([
                0.5 * (x[0] + y[0]),
                0.5 * (x[1] + y[1]),
                0.5 * (x[2] + y[2]),
            ]);
            (p.len() - 1) as u32
        })
    };
    for &[a, b, c] in mesh.triangles() {
        let ab = m(a, b, &mut p);
        let bc = m(b, c, &mut p);
        let ca = m(c, a, &mut p);
        t.extend_from_slice(&[[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
    }
    Mesh::new(p, t).expect("subdivision of a valid mesh is valid")
}

/// The standard edit: fixed = the lowest 10 % of vertices in z, handle = the
/// highest 10 %, moved by `0.15 · diagonal` along x and rotated 30° about y
/// (about the handle's centroid).
pub fn standard_edit(mesh: &Mesh) -> Constraints {
    let (fixed, handle) = bottom_top(mesh, 0.1);
    let c = centroid(mesh, &handle);
    let d = mesh.diagonal();
    let target = RigidTransform {
        rotation: UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians()),
        translation: [0.15 * d, 0.0, 0.0],
        pivot: c,
    };
    Constraints::new(mesh, fixed, vec![("top".into(), handle, Some(target))])
        .expect("standard edit is valid")
}

/// Vertex indices of the lowest and highest `frac` of vertices in z.
pub fn bottom_top(mesh: &Mesh, frac: f64) -> (Vec<u32>, Vec<u32>) {
    let n = mesh.num_vertices();
    let mut order: Vec<u32> = (0..n as u32).collect();
    let z = |v: &u32| mesh.positions()[*v as usize][2];
    order.sort_by(|a, b| z(a).total_cmp(&z(b)));
    let k = ((n as f64 * frac) as usize).max(1);
    let fixed = order[..k].to_vec();
    let handle = order[n - k..].to_vec();
    (fixed, handle)
}

fn centroid(mesh: &Mesh, vs: &[u32]) -> Point {
    let mut c = [0.0; 3];
    for &v in vs {
        let p = mesh.positions()[v as usize];
        for k in 0..3 {
            c[k] += p[k] / vs.len() as f64;
        }
    }
    c
}

/// Reads OFF / OBJ / PLY / STL through the library's reader.
pub fn read_mesh(path: &Path) -> Result<Mesh, String> {
    dend::mesh::io::read_path(path).map_err(|e| e.to_string())
}
