//! Angle-defect Gaussian curvature, signed mean curvature and `G = H² - K`
//! (design.md §2; paper eqs. 17 and 19).

use std::f64::consts::PI;

use sprs::CsMat;

use crate::mesh::{cross, dot, norm, sub, Point, Real, Topology};

/// The integrated angle defect of every vertex, `#V`.
///
/// Interior vertex: `2π - Σ θ_j` (the incident corner angles, paper eq. 19).
/// Boundary vertex: `π - Σ θ_j` (the geodesic-curvature form), so that the
/// discrete Gauss–Bonnet theorem `Σ_i defect_i = 2π χ` holds on open meshes
/// too. Unreferenced vertices get 0. libigl's `gaussian_curvature` returns
/// `2π - Σ θ_j` everywhere: equal at interior vertices, `π` more on the boundary.
pub fn angle_defect(positions: &[Point], triangles: &[[u32; 3]], topo: &Topology) -> Vec<Real> {
    let mut angle_sum = vec![0.0; positions.len()];
    for t in triangles {
        let p = t.map(|i| positions[i as usize]);
        for k in 0..3 {
            let u = sub(p[(k + 1) % 3], p[k]);
            let v = sub(p[(k + 2) % 3], p[k]);
            angle_sum[t[k] as usize] += norm(cross(u, v)).atan2(dot(u, v));
        }
    }
    (0..positions.len())
        .map(|i| {
            if topo.ring(i).is_empty() {
                0.0
            } else if topo.is_boundary(i) {
                PI - angle_sum[i]
            } else {
                2.0 * PI - angle_sum[i]
            }
        })
        .collect()
}

/// Area-weighted vertex normals (unit; zero for unreferenced vertices).
pub fn vertex_normals(positions: &[Point], triangles: &[[u32; 3]]) -> Vec<Point> {
    let mut n = vec![[0.0; 3]; positions.len()];
    for t in triangles {
        let p = t.map(|i| positions[i as usize]);
        let c = cross(sub(p[1], p[0]), sub(p[2], p[0]));
        for &v in t {
            for k in 0..3 {
                n[v as usize][k] += c[k];
            }
        }
    }
    for v in &mut n {
        let l = norm(*v);
        if l > 0.0 {
            *v = [v[0] / l, v[1] / l, v[2] / l];
        }
    }
    n
}

/// The mean-curvature normal `(L X)_i` for `L = D Lbar`, `#V×3`:
/// `(1 / 2A_i) Σ_j w_ij (X_j - X_i)` (paper eq. 17), with `|(L X)_i| = 2|H_i|`.
pub fn laplacian_coordinates(l: &CsMat<Real>, positions: &[Point]) -> Vec<Point> {
    l.outer_iterator()
        .map(|row| {
            let mut s = [0.0; 3];
            for (j, w) in row.iter() {
                for k in 0..3 {
                    s[k] += w * positions[j][k];
                }
            }
            s
        })
        .collect()
}

/// Signed mean curvature `H_i = |(L X)_i| / 2`, `#V`, `H = (k1 + k2)/2`.
///
/// Sign convention: **positive where the surface bends away from its normal**,
/// e.g. `H = +1/r` on a sphere of radius `r` with outward normals (there
/// `(L X)_i` points inwards, against the normal). The sign is taken from the
/// area-weighted vertex normal; where that is zero, or where `(L X)_i` is
/// numerically tangential (`|(L X)_i · n_i| ≤ 1e-9 |(L X)_i|`, e.g. on the
/// boundary of a flat region, where `(L X)_i` is the in-plane boundary
/// term), `H ≥ 0`: the sign of round-off would otherwise flip under rigid
/// motions.
pub fn mean_curvature(laplacian: &[Point], normals: &[Point]) -> Vec<Real> {
    laplacian
        .iter()
        .zip(normals)
        .map(|(&lx, &n)| {
            let h = norm(lx) / 2.0;
            if dot(lx, n) > 1e-9 * norm(lx) {
                -h
            } else {
                h
            }
        })
        .collect()
}

/// `G_i = max(H_i² - K_i, 0)`, `#V`: `H² - K = ((k1 - k2)/2)² ≥ 0` smoothly;
/// the clamp keeps it so in the discrete setting (paper, after eq. 12).
pub fn g_coefficient(h: &[Real], k: &[Real]) -> Vec<Real> {
    h.iter()
        .zip(k)
        .map(|(&h, &k)| (h * h - k).max(0.0))
        .collect()
}
