//! Meshes and measurements shared by the solver tests.
#![allow(dead_code)]

pub mod gltf_validator;

use std::sync::Arc;

use dend::deform::{
    BoxSel, ConstraintsSpec, Deformer, Factor, Formulation, HandleSpec, Params, Rest, RotationSpec,
    StepReport, VertexSet,
};
use dend::mesh::{Mesh, Point};

/// An open square tube `w × w × h` along z (bottom at z = 0), `k` vertices
/// per side of the square cross-section ring (4(k-1) per ring), `rings`
/// rings along z. Capped ends are not needed for twist tests.
pub fn tube(w: f64, h: f64, k: usize, rings: usize) -> Mesh {
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
    Mesh::new(p, t).unwrap()
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
    Mesh::new(p, t).unwrap()
}

/// Largest distance between corresponding points.
pub fn max_dist(a: &[Point], b: &[Point]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

/// Where the shared meshes live (`DEND_MESHES`, default
/// `../shared/meshes` beside the repository), or `None` after recording
/// that the caller skips ([`record_skip`]).
pub fn shared_meshes() -> Option<std::path::PathBuf> {
    let dir = std::env::var("DEND_MESHES")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|_| {
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/meshes")
        });
    if dir.is_dir() {
        Some(dir)
    } else {
        record_skip(&format!("shared meshes not found at {}", dir.display()));
        None
    }
}

/// Prints a skip and appends it, with the test's name, to the file named
/// by `DEND_SKIP_LOG` (scripts/test.sh prints that file as the run's skip
/// summary: cargo hides a passing test's output).
pub fn record_skip(why: &str) {
    let test = std::thread::current().name().unwrap_or("?").to_owned();
    eprintln!("skipping {test}: {why}");
    if let Ok(path) = std::env::var("DEND_SKIP_LOG") {
        use std::io::Write;
        if let Ok(mut f) = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
        {
            let _ = writeln!(f, "{test}: {why}");
        }
    }
}

/// A random Delaunay patch: `n` random points in the unit disc (plus a ring
/// of boundary points), triangulated by Delaunay, lifted onto a saddle. Its
/// hull triangles are skinny, as in dend.md §8.4's failing case.
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

/// Eq. (24) least squares (the default before the elastic formulation):
/// the energies' properties below are this formulation's; the elastic
/// default's are in tests/elastic.rs.
pub fn ls() -> Params {
    Params {
        formulation: Formulation::LeastSquares,
        ..Params::default()
    }
}

/// Solves `spec` on `mesh` from rest with up to `iters` iterations.
pub fn solve(
    mesh: &Mesh,
    params: Params,
    spec: &ConstraintsSpec,
    iters: usize,
) -> (Vec<[f64; 3]>, StepReport) {
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = spec.resolve(mesh).unwrap();
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    let rep = d.step(&f, &c, iters).unwrap();
    (d.pose().to_vec(), rep)
}

pub fn tube_spec(mesh: &Mesh, handle: HandleSpec) -> ConstraintsSpec {
    let (lo, hi) = mesh.bounding_box();
    let _ = lo;
    ConstraintsSpec {
        fixed_positions: None,
        fixed: VertexSet::Box {
            bbox: BoxSel {
                min: [-9.0, -9.0, -0.01],
                max: [9.0, 9.0, 0.01 * hi[2] + 0.3],
            },
        },
        handles: vec![HandleSpec {
            vertices: VertexSet::Box {
                bbox: BoxSel {
                    min: [-9.0, -9.0, hi[2] * 0.99 - 0.3],
                    max: [9.0, 9.0, hi[2] + 1.0],
                },
            },
            ..handle
        }],
    }
}

pub fn handle(translate: Option<[f64; 3]>, rotate: Option<RotationSpec>) -> HandleSpec {
    HandleSpec {
        name: Some("top".into()),
        vertices: VertexSet::Indices(vec![]),
        translate,
        rotate,
        pivot: None,
        positions: None,
    }
}
