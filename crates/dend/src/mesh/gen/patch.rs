//! Irregular open patches: a saddle and a wavy sheet with obtuse and
//! skinny triangles and a free boundary (what real scans and sculpts have
//! and the paper's shapes do not), the open surfaces the solver's tests
//! and the posing suite check convergence on. They are not
//! paper shapes (no [`super::Shape`] of their own): a jittered grid whose
//! quads are split along a random diagonal, deterministic in a seed.

use super::super::{Mesh, Point, Real};

/// The surface an [`irregular_patch`] lies on, over `(x, y) ∈ [-1, 1]²`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PatchSurface {
    /// `z = 0.5 (x² − y²)`: negative Gaussian curvature everywhere.
    Saddle,
    /// `z = 0.15 sin(2.5 π x) cos(1.5 π y)`: alternating bumps and dips.
    Wavy,
}

impl PatchSurface {
    /// The height over `(x, y)`.
    fn height(self, x: Real, y: Real) -> Real {
        use std::f64::consts::PI;
        match self {
            PatchSurface::Saddle => 0.5 * (x * x - y * y),
            PatchSurface::Wavy => 0.15 * (2.5 * PI * x).sin() * (1.5 * PI * y).cos(),
        }
    }
}

/// An open patch of `n × n` vertices (`n ≥ 3`) on `surface` over
/// `[-1, 1]²`: every vertex of the grid jittered by up to `jitter` cells
/// along x and y (boundary vertices along their side only, so the boundary
/// stays the square's), every quad split along a diagonal drawn at random
/// (the other where the drawn one would make a triangle of under 5 % of a
/// cell). At `jitter` 0.4 about a third of the triangles are obtuse and
/// some have angles under 10°. Same `seed`, same mesh.
pub fn irregular_patch(surface: PatchSurface, n: usize, jitter: Real, seed: u64) -> Mesh {
    assert!(n >= 3, "a patch needs 3 vertices per side");
    let mut state = seed ^ 0x9E37_79B9_7F4A_7C15;
    let mut rnd = move || {
        // xorshift64: deterministic, no dependency
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as Real / (1u64 << 53) as Real
    };
    let h = 2.0 / (n - 1) as Real;
    let mut xy = Vec::with_capacity(n * n);
    for r in 0..n {
        for c in 0..n {
            let jx = if c == 0 || c == n - 1 {
                0.0
            } else {
                jitter * (2.0 * rnd() - 1.0)
            };
            let jy = if r == 0 || r == n - 1 {
                0.0
            } else {
                jitter * (2.0 * rnd() - 1.0)
            };
            xy.push([-1.0 + h * (c as Real + jx), -1.0 + h * (r as Real + jy)]);
        }
    }
    // twice the signed area of (a, b, c) in the plane
    let area2 = |a: u32, b: u32, c: u32| {
        let (p, q, s) = (xy[a as usize], xy[b as usize], xy[c as usize]);
        (q[0] - p[0]) * (s[1] - p[1]) - (q[1] - p[1]) * (s[0] - p[0])
    };
    let min_area2 = 0.05 * h * h;
    let mut tris = Vec::with_capacity(2 * (n - 1) * (n - 1));
    let k = n as u32;
    for r in 0..k - 1 {
        for c in 0..k - 1 {
            let v = r * k + c;
            let (a, b, d, e) = (v, v + 1, v + k + 1, v + k);
            let one = [[a, b, d], [a, d, e]];
            let other = [[a, b, e], [b, d, e]];
            let ok = |t: &[[u32; 3]; 2]| t.iter().all(|t| area2(t[0], t[1], t[2]) > min_area2);
            let first = if rnd() < 0.5 { one } else { other };
            let second = if first == one { other } else { one };
            let pick = if ok(&first) || !ok(&second) {
                first
            } else {
                second
            };
            tris.extend(pick);
        }
    }
    let positions: Vec<Point> = xy
        .iter()
        .map(|&[x, y]| [x, y, surface.height(x, y)])
        .collect();
    Mesh::new(positions, tris).expect("a jittered grid is a valid mesh")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The patches are open (one boundary loop), irregular (obtuse
    /// triangles) and reproducible.
    #[test]
    fn patches_are_open_irregular_and_reproducible() {
        for surface in [PatchSurface::Saddle, PatchSurface::Wavy] {
            let m = irregular_patch(surface, 30, 0.4, 5);
            assert_eq!(m.num_vertices(), 900);
            assert_eq!(m.num_triangles(), 2 * 29 * 29);
            assert_eq!(m.euler_characteristic(), 1, "a disc");
            let p = m.positions();
            let obtuse = m
                .triangles()
                .iter()
                .filter(|t| {
                    (0..3).any(|k| {
                        let o = p[t[k] as usize];
                        let a = p[t[(k + 1) % 3] as usize];
                        let b = p[t[(k + 2) % 3] as usize];
                        let d: Real = (0..3).map(|i| (a[i] - o[i]) * (b[i] - o[i])).sum();
                        d < 0.0
                    })
                })
                .count();
            assert!(
                obtuse * 5 > m.num_triangles(),
                "{surface:?}: {obtuse} obtuse of {}",
                m.num_triangles()
            );
            let again = irregular_patch(surface, 30, 0.4, 5);
            assert_eq!(again.positions(), m.positions());
            assert_eq!(again.triangles(), m.triangles());
            let other = irregular_patch(surface, 30, 0.4, 6);
            assert_ne!(other.positions(), m.positions());
        }
    }
}
