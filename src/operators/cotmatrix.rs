//! The cotangent Laplacian `Lbar` (dend.md §2; Pinkall & Polthier 1993,
//! Meyer et al. 2003 eq. 8).

use sprs::{CsMat, TriMat};

use crate::mesh::{cross, dot, norm, sub, Point, Real};

/// The symmetric cotangent matrix `Lbar`, `#V×#V`, CSR.
///
/// `Lbar_ij = (cot α_ij + cot β_ij) / 2` for every edge `(i, j)` (one term on a
/// boundary edge), `Lbar_ii = -Σ_j Lbar_ij`. Negative semidefinite, rows sum
/// to zero: `Lbar · 1 = 0`. This is libigl's `cotmatrix` exactly (same sign
/// and the same factor ½). `(Lbar X)_i = ½ Σ_j w_ij (X_j - X_i)` with
/// `w_ij = cot α_ij + cot β_ij` (paper eq. 18).
///
/// Cost: O(#F); assembled from 12 triplets per face.
pub fn cotmatrix(positions: &[Point], triangles: &[[u32; 3]]) -> CsMat<Real> {
    let n = positions.len();
    let mut tri = TriMat::with_capacity((n, n), triangles.len() * 12);
    for t in triangles {
        let p = t.map(|i| positions[i as usize]);
        for k in 0..3 {
            // corner k is opposite the edge (k+1, k+2)
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let half_cot = 0.5 * cot(p[k], p[i], p[j]);
            let (vi, vj) = (t[i] as usize, t[j] as usize);
            tri.add_triplet(vi, vj, half_cot);
            tri.add_triplet(vj, vi, half_cot);
            tri.add_triplet(vi, vi, -half_cot);
            tri.add_triplet(vj, vj, -half_cot);
        }
    }
    tri.to_csr()
}

/// Cotangent of the angle at `apex` in the triangle `(apex, a, b)`:
/// `cot θ = (u·v) / |u×v|` with `u = a - apex`, `v = b - apex`.
pub fn cot(apex: Point, a: Point, b: Point) -> Real {
    let (u, v) = (sub(a, apex), sub(b, apex));
    dot(u, v) / norm(cross(u, v))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_triangle_has_cot60_weights() {
        let s = 3f64.sqrt();
        let p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.5, s / 2.0, 0.0]];
        let l = cotmatrix(&p, &[[0, 1, 2]]);
        let c = 0.5 / s; // ½ cot 60°
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { -2.0 * c } else { c };
                let got = *l.get(i, j).unwrap();
                assert!((got - want).abs() < 1e-15, "({i},{j}) {got} vs {want}");
            }
        }
    }

    #[test]
    fn rows_sum_to_zero_and_matrix_is_symmetric() {
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.1, 0.0],
            [0.2, 1.3, 0.4],
            [0.1, 0.2, 1.7],
        ];
        let t = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let l = cotmatrix(&p, &t);
        for (i, row) in l.outer_iterator().enumerate() {
            let s: f64 = row.iter().map(|(_, v)| v).sum();
            assert!(s.abs() < 1e-14);
            for (j, v) in row.iter() {
                assert!((v - l.get(j, i).unwrap()).abs() < 1e-15);
            }
        }
    }
}
