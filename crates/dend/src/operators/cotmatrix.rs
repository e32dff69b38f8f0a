//! The cotangent Laplacian `Lbar` (design.md §2; Pinkall & Polthier 1993,
//! Meyer et al. 2003 eq. 8).

use rayon::prelude::*;
use sprs::CsMat;

use crate::mesh::{corner_offsets, cross, dot, norm, sub, Point, Real};

/// The symmetric cotangent matrix `Lbar`, `#V×#V`, CSR.
///
/// `Lbar_ij = (cot α_ij + cot β_ij) / 2` for every edge `(i, j)` (one term on a
/// boundary edge), `Lbar_ii = -Σ_j Lbar_ij`. Negative semidefinite, rows sum
/// to zero: `Lbar · 1 = 0`. This is libigl's `cotmatrix` exactly (same sign
/// and the same factor ½). `(Lbar X)_i = ½ Σ_j w_ij (X_j - X_i)` with
/// `w_ij = cot α_ij + cot β_ij` (paper eq. 18).
///
/// The pattern holds the diagonal of every referenced vertex and both
/// `(i, j)` and `(j, i)` of every edge (rows of unreferenced vertices are
/// empty); column indices are sorted within each row.
///
/// Cost: O(#F log d) for maximal valence `d`, no global sort of triplets:
/// each row is assembled on its own from the vertex–face incidence (the two
/// half cotangents of every incident face, sorted and summed within the
/// row), rows in parallel (rayon). Both endpoints of an edge evaluate the
/// same cotangent with the same floating-point operations, so `Lbar` is
/// exactly symmetric.
///
/// # References
/// Pinkall & Polthier 1993; Meyer et al. 2003, eq. 8; DEND paper eq. 18.
pub fn cotmatrix(positions: &[Point], triangles: &[[u32; 3]]) -> CsMat<Real> {
    let n = positions.len();
    // vertex -> incident (face, corner) as CSR
    let start = corner_offsets(n, triangles);
    let mut fill = start.clone();
    let mut corners = vec![(0u32, 0u8); triangles.len() * 3];
    for (f, t) in triangles.iter().enumerate() {
        for (k, &v) in t.iter().enumerate() {
            corners[fill[v as usize]] = (f as u32, k as u8);
            fill[v as usize] += 1;
        }
    }
    drop(fill);
    // Each row: (column, value) pairs from the incident faces, then summed.
    let rows: Vec<Vec<(usize, Real)>> = (0..n)
        .into_par_iter()
        .map(|i| {
            let inc = &corners[start[i]..start[i + 1]];
            if inc.is_empty() {
                return Vec::new();
            }
            let mut e: Vec<(usize, Real)> = Vec::with_capacity(2 * inc.len() + 1);
            let mut diag = 0.0;
            for &(f, k) in inc {
                let t = triangles[f as usize];
                let k = k as usize;
                let (a, b) = ((k + 1) % 3, (k + 2) % 3);
                let p = t.map(|v| positions[v as usize]);
                // edge (i, t[a]) is opposite corner b and vice versa
                let ca = 0.5 * cot(p[b], p[k], p[a]);
                let cb = 0.5 * cot(p[a], p[k], p[b]);
                e.push((t[a] as usize, ca));
                e.push((t[b] as usize, cb));
                diag -= ca + cb;
            }
            e.push((i, diag));
            e.sort_unstable_by_key(|&(j, _)| j);
            let mut out: Vec<(usize, Real)> = Vec::with_capacity(e.len());
            for (j, v) in e {
                match out.last_mut() {
                    Some(last) if last.0 == j => last.1 += v,
                    _ => out.push((j, v)),
                }
            }
            out
        })
        .collect();
    let nnz: usize = rows.iter().map(Vec::len).sum();
    let mut indptr = Vec::with_capacity(n + 1);
    let mut indices = Vec::with_capacity(nnz);
    let mut data = Vec::with_capacity(nnz);
    indptr.push(0);
    for r in rows {
        for (j, v) in r {
            indices.push(j);
            data.push(v);
        }
        indptr.push(indices.len());
    }
    CsMat::new((n, n), indptr, indices, data)
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

    /// The direct row assembly equals a plain triplet assembly (sprs sums
    /// duplicates), including an empty row for an unreferenced vertex.
    #[test]
    fn row_assembly_equals_triplet_assembly() {
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.1, 0.0],
            [0.2, 1.3, 0.4],
            [9.0, 9.0, 9.0], // unreferenced
            [1.1, 1.2, -0.3],
            [-0.7, 0.6, 0.2],
        ];
        let t = [[0, 1, 2], [1, 4, 2], [0, 2, 5]];
        let mut tri = sprs::TriMat::new((6, 6));
        for f in &t {
            let q = f.map(|i| p[i as usize]);
            for k in 0..3 {
                let (i, j) = ((k + 1) % 3, (k + 2) % 3);
                let c = 0.5 * cot(q[k], q[i], q[j]);
                let (vi, vj) = (f[i] as usize, f[j] as usize);
                tri.add_triplet(vi, vj, c);
                tri.add_triplet(vj, vi, c);
                tri.add_triplet(vi, vi, -c);
                tri.add_triplet(vj, vj, -c);
            }
        }
        let want: CsMat<f64> = tri.to_csr();
        let got = cotmatrix(&p, &t);
        assert_eq!(got.indptr().raw_storage(), want.indptr().raw_storage());
        assert_eq!(got.indices(), want.indices());
        assert!(got.outer_iterator().nth(3).unwrap().nnz() == 0);
        for (a, b) in got.data().iter().zip(want.data()) {
            assert!((a - b).abs() < 1e-15, "{a} vs {b}");
        }
    }
}
