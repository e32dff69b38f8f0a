//! Meshes for tests: small analytic solids, jittered and irregular patches,
//! tubes, and thin wrappers of the library's generators (`dend::mesh::gen`)
//! for the shapes it has (cylinder, torus, flat grid).

use std::f64::consts::PI;

use dend::mesh::gen::{generate, Shape, ShapeParams, ShapeSpec};
use dend::mesh::{Mesh, Point};

/// The library's generator for `shape` with these parameters (panics on
/// invalid parameters: for tests).
fn generated(shape: Shape, params: ShapeParams) -> Mesh {
    generate(&ShapeSpec { shape, params }).expect("valid generator parameters")
}

/// Open cylinder (tube) of radius `r` around the z axis: `rows` rings of
/// `seg` vertices, `dz` apart, from z = 0; every planar quad split along one
/// diagonal (the library's `cylinder`). Outward orientation. Interior
/// vertices have an exactly flat angle sum.
pub fn cylinder(seg: u32, rows: u32, r: f64, dz: f64) -> Mesh {
    generated(
        Shape::Cylinder,
        ShapeParams {
            nu: Some(seg),
            nv: Some(rows),
            size: Some(r),
            size2: Some(dz * f64::from(rows - 1)),
            amplitude: None,
        },
    )
}

/// Torus about the z axis with radii `big > small`, `nu × nv` vertices,
/// outward orientation (the library's `torus`).
pub fn torus(nu: u32, nv: u32, big: f64, small: f64) -> Mesh {
    generated(
        Shape::Torus,
        ShapeParams {
            nu: Some(nu),
            nv: Some(nv),
            size: Some(big),
            size2: Some(small),
            amplitude: None,
        },
    )
}

/// An `n`×`n`-vertex grid of unit spacing in the plane z = 0 (the library's
/// `flag`, `(n-1)` wide), vertex `j·n + i` at `(i, j)`: row 0 is `0..n`.
pub fn unit_grid(n: u32) -> Mesh {
    generated(
        Shape::Flag,
        ShapeParams {
            nu: Some(n),
            nv: Some(n),
            size: Some(f64::from(n - 1)),
            size2: Some(f64::from(n - 1)),
            amplitude: None,
        },
    )
}

/// Builds a mesh, panicking (in tests only) on invalid input.
fn mesh(p: Vec<Point>, t: Vec<[u32; 3]>) -> Mesh {
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
pub fn jittered_grid(n: u32, jitter: f64) -> Mesh {
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

/// An open square tube `w × w × h` along z (bottom at z = 0), `k` vertices
/// per side of the square cross-section ring (4(k-1) per ring), `rings`
/// rings along z. Capped ends are not needed for twist tests.
pub fn square_tube(w: f64, h: f64, k: usize, rings: usize) -> Mesh {
    let per = 4 * (k - 1);
    let mut p = Vec::new();
    for r in 0..rings {
        let z = h * r as f64 / (rings - 1) as f64;
        for s in 0..per {
            let side = s / (k - 1);
            let t = (s % (k - 1)) as f64 / (k - 1) as f64;
            let (x, y) = match side {
                0 => (-0.5 + t, -0.5),
                1 => (0.5, -0.5 + t),
                2 => (0.5 - t, 0.5),
                _ => (-0.5, 0.5 - t),
            };
            p.push([x * w, y * w, z]);
        }
    }
    let mut t = Vec::new();
    for r in 0..rings as u32 - 1 {
        for s in 0..per as u32 {
            let a = r * per as u32 + s;
            let b = r * per as u32 + (s + 1) % per as u32;
            let c = a + per as u32;
            let d = b + per as u32;
            t.push([a, b, d]);
            t.push([a, d, c]);
        }
    }
    mesh(p, t)
}

/// A random-ish irregular open patch with skinny triangles: a jittered grid
/// (deterministic, from `seed`) on a saddle, triangulated with alternating
/// diagonals.
pub fn irregular_saddle(k: usize, seed: u64) -> Mesh {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut rnd = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 33) as f64) / (1u64 << 31) as f64
    };
    let mut p = Vec::new();
    for r in 0..k {
        for c in 0..k {
            let jx = if c == 0 || c == k - 1 {
                0.0
            } else {
                0.8 * (rnd() - 0.5)
            };
            let jy = if r == 0 || r == k - 1 {
                0.0
            } else {
                0.8 * (rnd() - 0.5)
            };
            let (x, y) = (c as f64 + jx, r as f64 + jy);
            let u = (x - k as f64 / 2.0) / k as f64;
            let v = (y - k as f64 / 2.0) / k as f64;
            p.push([x, y, 3.0 * u * v * k as f64 * 0.5]);
        }
    }
    let mut t = Vec::new();
    for r in 0..k as u32 - 1 {
        for c in 0..k as u32 - 1 {
            let v = r * k as u32 + c;
            let kk = k as u32;
            if (r + c) % 2 == 0 {
                t.push([v, v + 1, v + kk + 1]);
                t.push([v, v + kk + 1, v + kk]);
            } else {
                t.push([v, v + 1, v + kk]);
                t.push([v + 1, v + kk + 1, v + kk]);
            }
        }
    }
    mesh(p, t)
}

/// A random Delaunay patch: `n` random points in the unit disc (plus a ring
/// of boundary points), triangulated by Delaunay, lifted onto a saddle. Its
/// hull triangles are skinny, as in design.md §4.5's failing case.
pub fn random_delaunay_patch(n: usize, seed: u64) -> Mesh {
    let mut state = seed ^ 0x9E37_79B9_7F4A_7C15;
    let mut rnd = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut pts = Vec::new();
    while pts.len() < n {
        let (x, y) = (2.0 * rnd() - 1.0, 2.0 * rnd() - 1.0);
        if x * x + y * y < 1.0 {
            pts.push(delaunator::Point { x, y });
        }
    }
    let tri = delaunator::triangulate(&pts);
    let p: Vec<Point> = pts
        .iter()
        .map(|q| [q.x, q.y, 0.6 * (q.x * q.x - q.y * q.y)])
        .collect();
    // delaunator gives clockwise triangles in a y-up frame: flip to CCW
    let t: Vec<[u32; 3]> = tri
        .triangles
        .chunks(3)
        .map(|c| [c[0] as u32, c[2] as u32, c[1] as u32])
        .collect();
    // drop numerically degenerate hull slivers, which Mesh::new rejects
    let t: Vec<[u32; 3]> = t
        .into_iter()
        .filter(|f| Mesh::new(p.clone(), vec![*f]).is_ok())
        .collect();
    Mesh::new(p, t).expect("valid Delaunay patch")
}

/// A closed-side cylindrical tube along z: radius 1, height `h`, `around`
/// vertices per ring, `rings` rings (open at both ends).
pub fn round_tube(around: usize, rings: usize, h: f64) -> Mesh {
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
    round_tube(around, rings, h.max(1.0))
}

/// One 1→4 midpoint subdivision (the old vertices keep their indices and
/// positions; the new ones follow).
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
