//! Test helpers shared by the integration tests: small analytic meshes,
//! a minimal OFF/OBJ reader and OFF writer (test-only; the library readers
//! live in `dend::mesh::io`), and the locations of the shared meshes and of
//! the Python oracle.
#![allow(dead_code)]

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use dend::mesh::{Mesh, Point};

/// Builds a mesh, panicking (in tests only) on invalid input.
pub fn mesh(p: Vec<Point>, t: Vec<[u32; 3]>) -> Mesh {
    Mesh::new(p, t).expect("test mesh is valid")
}

/// Unit-edge equilateral triangle in the plane z = 0.
pub fn equilateral_triangle() -> Mesh {
    let s = 3f64.sqrt();
    mesh(
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, s / 2.0, 0.0]],
        vec![[0, 1, 2]],
    )
}

/// Regular tetrahedron with edge length `2√2` (vertices at alternate cube
/// corners), outward orientation.
pub fn tetrahedron() -> Mesh {
    mesh(
        vec![
            [1.0, 1.0, 1.0],
            [1.0, -1.0, -1.0],
            [-1.0, 1.0, -1.0],
            [-1.0, -1.0, 1.0],
        ],
        vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]],
    )
}

/// Regular octahedron with vertices `±e_k` (edge length `√2`), outward.
pub fn octahedron() -> Mesh {
    let p = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let t = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    mesh(p, t)
}

/// Icosahedron subdivided `level` times (each triangle into four, new
/// vertices projected onto the sphere) of radius `r`, outward orientation.
pub fn icosphere(level: u32, r: f64) -> Mesh {
    let g = (1.0 + 5f64.sqrt()) / 2.0;
    let mut p: Vec<Point> = vec![
        [-1.0, g, 0.0],
        [1.0, g, 0.0],
        [-1.0, -g, 0.0],
        [1.0, -g, 0.0],
        [0.0, -1.0, g],
        [0.0, 1.0, g],
        [0.0, -1.0, -g],
        [0.0, 1.0, -g],
        [g, 0.0, -1.0],
        [g, 0.0, 1.0],
        [-g, 0.0, -1.0],
        [-g, 0.0, 1.0],
    ];
    let mut t: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let unit = |q: Point| {
        let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
        [q[0] / n, q[1] / n, q[2] / n]
    };
    for q in &mut p {
        *q = unit(*q);
    }
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut nt = Vec::with_capacity(t.len() * 4);
        for f in &t {
            let mut m = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (f[k], f[(k + 1) % 3]);
                let key = (a.min(b), a.max(b));
                m[k] = *mid.entry(key).or_insert_with(|| {
                    let (pa, pb) = (p[a as usize], p[b as usize]);
                    p.push(unit([pa[0] + pb[0], pa[1] + pb[1], pa[2] + pb[2]]));
                    (p.len() - 1) as u32
                });
            }
            nt.push([f[0], m[0], m[2]]);
            nt.push([f[1], m[1], m[0]]);
            nt.push([f[2], m[2], m[1]]);
            nt.push([m[0], m[1], m[2]]);
        }
        t = nt;
    }
    for q in &mut p {
        *q = [q[0] * r, q[1] * r, q[2] * r];
    }
    mesh(p, t)
}

/// Latitude–longitude sphere of radius `r`: `rings` latitude rings (plus two
/// poles) of `seg` vertices each, outward orientation.
pub fn uv_sphere(rings: u32, seg: u32, r: f64) -> Mesh {
    let mut p = vec![[0.0, 0.0, r]];
    for i in 1..=rings {
        let th = PI * i as f64 / (rings + 1) as f64;
        for j in 0..seg {
            let ph = 2.0 * PI * j as f64 / seg as f64;
            p.push([
                r * th.sin() * ph.cos(),
                r * th.sin() * ph.sin(),
                r * th.cos(),
            ]);
        }
    }
    p.push([0.0, 0.0, -r]);
    let south = (p.len() - 1) as u32;
    let v = |i: u32, j: u32| 1 + (i - 1) * seg + (j % seg);
    let mut t = Vec::new();
    for j in 0..seg {
        t.push([0, v(1, j), v(1, j + 1)]);
        t.push([south, v(rings, j + 1), v(rings, j)]);
    }
    for i in 1..rings {
        for j in 0..seg {
            let (a, b, c, d) = (v(i, j), v(i, j + 1), v(i + 1, j), v(i + 1, j + 1));
            t.push([a, c, d]);
            t.push([a, d, b]);
        }
    }
    mesh(p, t)
}

/// Flat `n×n`-vertex grid on `[0,1]²` (z = 0), each square split along one
/// diagonal; `jitter` in `[0, 0.3)` moves interior vertices in the plane
/// pseudo-randomly (deterministic) by up to `jitter` cells.
pub fn grid(n: u32, jitter: f64) -> Mesh {
    let h = 1.0 / (n - 1) as f64;
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut rnd = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let mut p = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let inner = i > 0 && j > 0 && i < n - 1 && j < n - 1;
            let (dx, dy) = if inner {
                (jitter * h * rnd(), jitter * h * rnd())
            } else {
                (0.0, 0.0)
            };
            p.push([j as f64 * h + dx, i as f64 * h + dy, 0.0]);
        }
    }
    let mut t = Vec::new();
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let a = i * n + j;
            let (b, c, d) = (a + 1, a + n, a + n + 1);
            if (i + j) % 2 == 0 {
                t.push([a, b, d]);
                t.push([a, d, c]);
            } else {
                t.push([a, b, c]);
                t.push([b, d, c]);
            }
        }
    }
    mesh(p, t)
}

/// Open cylinder (tube) of radius `r` around the z axis: `rows` rings of
/// `seg` vertices, `dz` apart; every planar quad split along one diagonal.
/// Outward orientation. Interior vertices have an exactly flat angle sum.
pub fn cylinder(seg: u32, rows: u32, r: f64, dz: f64) -> Mesh {
    let mut p = Vec::new();
    for i in 0..rows {
        for j in 0..seg {
            let ph = 2.0 * PI * j as f64 / seg as f64;
            p.push([r * ph.cos(), r * ph.sin(), i as f64 * dz]);
        }
    }
    let v = |i: u32, j: u32| i * seg + j % seg;
    let mut t = Vec::new();
    for i in 0..rows - 1 {
        for j in 0..seg {
            let (a, b, c, d) = (v(i, j), v(i, j + 1), v(i + 1, j), v(i + 1, j + 1));
            t.push([a, b, d]);
            t.push([a, d, c]);
        }
    }
    mesh(p, t)
}

/// Torus with radii `big > small`, `nu × nv` vertices, outward orientation.
pub fn torus(nu: u32, nv: u32, big: f64, small: f64) -> Mesh {
    let mut p = Vec::new();
    for i in 0..nu {
        let u = 2.0 * PI * i as f64 / nu as f64;
        for j in 0..nv {
            let w = 2.0 * PI * j as f64 / nv as f64;
            let rr = big + small * w.cos();
            p.push([rr * u.cos(), rr * u.sin(), small * w.sin()]);
        }
    }
    let v = |i: u32, j: u32| (i % nu) * nv + j % nv;
    let mut t = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (v(i, j), v(i + 1, j), v(i, j + 1), v(i + 1, j + 1));
            t.push([a, b, d]);
            t.push([a, d, c]);
        }
    }
    mesh(p, t)
}

/// Folder of the shared test meshes (`DEND_MESHES`, default
/// `<crate>/../shared/meshes`), or `None` (with a printed skip) if absent.
pub fn meshes_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("DEND_MESHES")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes"));
    if dir.is_dir() {
        Some(dir)
    } else {
        let test = std::thread::current().name().unwrap_or("?").to_owned();
        println!("skipping {test}: {} not found", dir.display());
        if let Ok(path) = std::env::var("DEND_SKIP_LOG") {
            use std::io::Write;
            if let Ok(mut f) = std::fs::OpenOptions::new()
                .create(true)
                .append(true)
                .open(path)
            {
                let _ = writeln!(f, "{test}: shared meshes not found at {}", dir.display());
            }
        }
        None
    }
}

/// Minimal reader of triangle OFF and OBJ files (polygons fan-triangulated).
pub fn read_mesh(path: &Path) -> Mesh {
    let text = std::fs::read_to_string(path).expect("readable mesh");
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    let (p, t) = if ext.eq_ignore_ascii_case("obj") {
        parse_obj(&text)
    } else {
        parse_off(&text)
    };
    mesh(p, t)
}

fn fan(poly: &[u32], t: &mut Vec<[u32; 3]>) {
    for k in 1..poly.len() - 1 {
        t.push([poly[0], poly[k], poly[k + 1]]);
    }
}

fn parse_off(text: &str) -> (Vec<Point>, Vec<[u32; 3]>) {
    let mut tok = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or(""))
        .flat_map(str::split_whitespace);
    assert_eq!(tok.next(), Some("OFF"));
    let mut num = || tok.next().expect("token").parse::<f64>().expect("number");
    let (nv, nf, _) = (num() as usize, num() as usize, num());
    let p = (0..nv).map(|_| [num(), num(), num()]).collect();
    let mut t = Vec::new();
    for _ in 0..nf {
        let k = num() as usize;
        let poly: Vec<u32> = (0..k).map(|_| num() as u32).collect();
        fan(&poly, &mut t);
    }
    (p, t)
}

fn parse_obj(text: &str) -> (Vec<Point>, Vec<[u32; 3]>) {
    let (mut p, mut t) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut w = line.split_whitespace();
        match w.next() {
            Some("v") => {
                let c: Vec<f64> = w.take(3).map(|x| x.parse().expect("number")).collect();
                p.push([c[0], c[1], c[2]]);
            }
            Some("f") => {
                let poly: Vec<u32> = w
                    .map(|x| {
                        let i: i64 = x.split('/').next().unwrap().parse().expect("index");
                        (if i < 0 { p.len() as i64 + i } else { i - 1 }) as u32
                    })
                    .collect();
                fan(&poly, &mut t);
            }
            _ => {}
        }
    }
    (p, t)
}

/// Writes `mesh` as OFF with round-trip-exact coordinates.
pub fn write_off(mesh: &Mesh, path: &Path) {
    use std::fmt::Write;
    let mut s = format!("OFF\n{} {} 0\n", mesh.num_vertices(), mesh.num_triangles());
    for q in mesh.positions() {
        writeln!(s, "{:e} {:e} {:e}", q[0], q[1], q[2]).unwrap();
    }
    for f in mesh.triangles() {
        writeln!(s, "3 {} {} {}", f[0], f[1], f[2]).unwrap();
    }
    std::fs::write(path, s).expect("writable temp file");
}

/// The oracle's Python: `DEND_PYTHON`, else `<crate>/.venv/bin/python`, if it
/// can `import igl, numpy, scipy`. Otherwise `None` after a printed skip, or a
/// panic under `CI=true` (a missing oracle must fail CI).
pub fn oracle_python() -> Option<PathBuf> {
    let py = std::env::var_os("DEND_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python"));
    let ok = std::process::Command::new(&py)
        .args(["-c", "import igl, numpy, scipy"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if ok {
        return Some(py);
    }
    let msg = format!(
        "python oracle {} (igl, numpy, scipy) not usable",
        py.display()
    );
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{msg}; under CI=true the oracle is required");
    }
    println!("skipping: {msg}");
    None
}
