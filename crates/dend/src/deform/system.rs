//! Assembly of the stacked least-squares rows of design.md §4.1 and their normal
//! matrix.
//!
//! For the free rows `R` (vertices not fixed, not in a handle), with
//! `W = diag(√A_i)`:
//!
//! ```text
//!   J = [ W R A      ]      internal term, A = the energy's matrix (§3)
//!       [ √λ2 W R L  ]      detail term (paper eq. 16)
//! ```
//!
//! Hard constraints: the unknowns `U` are the free vertices, the constrained
//! columns move to the right-hand side, and `M = J_Uᵀ J_U`. Soft constraints
//! (`λ1 > 0`): every vertex is unknown and `M = Jᵀ J + λ1 Sᵀ S`. `M` depends on
//! the rest mesh, the energy, the λs and the constrained *set* only.

use sprs::{CsMat, TriMat};

use super::params::Params;
use crate::mesh::{Point, Real};
use crate::operators::Operators;
use dend_linalg::sparse::{product_pattern, product_values};

/// The free rows `R` (active, not constrained), the unknowns `U` (`R`, or
/// every active vertex with soft constraints) and vertex → position in `U`
/// (`u32::MAX` if not an unknown): the partition both formulations use.
pub(crate) fn partition(
    n: usize,
    constrained: &[u32],
    active: &[bool],
    soft: bool,
) -> (Vec<u32>, Vec<u32>, Vec<u32>) {
    let mut is_constrained = vec![false; n];
    for &c in constrained {
        is_constrained[c as usize] = true;
    }
    let rows: Vec<u32> = (0..n as u32)
        .filter(|&v| active[v as usize] && !is_constrained[v as usize])
        .collect();
    let unknowns: Vec<u32> = if soft {
        (0..n as u32).filter(|&v| active[v as usize]).collect()
    } else {
        rows.clone()
    };
    let mut col_of = vec![u32::MAX; n];
    for (k, &u) in unknowns.iter().enumerate() {
        col_of[u as usize] = k as u32;
    }
    (rows, unknowns, col_of)
}

/// `m + λ1 SᵀS` on the unknowns: `λ1` added to the diagonal of every
/// constrained vertex that is an unknown (soft constraints).
pub(crate) fn add_soft_diagonal(
    m: &CsMat<Real>,
    constrained: &[u32],
    col_of: &[u32],
    lambda1: Real,
) -> CsMat<Real> {
    let mut diag = TriMat::new((m.rows(), m.cols()));
    for &c in constrained {
        let k = col_of[c as usize];
        if k != u32::MAX {
            diag.add_triplet(k as usize, k as usize, lambda1);
        }
    }
    let d: CsMat<Real> = diag.to_csr();
    m + &d
}

/// The assembled rows and the normal matrix of one constraint set.
#[derive(Debug, Clone)]
pub struct System {
    /// Free rows `R` (vertex indices), sorted.
    pub rows: Vec<u32>,
    /// `√A_i` for each row in `R`.
    pub row_weight: Vec<Real>,
    /// `√λ2`.
    pub sqrt_lambda2: Real,
    /// The unknown vertices `U`, sorted.
    pub unknowns: Vec<u32>,
    /// Vertex → position in `U`, or `u32::MAX`.
    pub col_of: Vec<u32>,
    /// The normal matrix `M`, `|U| × |U|`, CSR, symmetric.
    pub m: CsMat<Real>,
    /// Constrained vertices (fixed ∪ handles), sorted.
    pub constrained: Vec<u32>,
    /// `λ1` (0: hard constraints).
    pub lambda1: Real,
}

/// A constraint set's rows, unknowns, `J_U` and the pattern of `M`: what
/// the numeric product ([`Prepared::values`]) and, at the same time, the
/// factor's symbolic analysis (which needs the pattern only) start from.
pub(crate) struct Prepared {
    rows: Vec<u32>,
    row_weight: Vec<Real>,
    sqrt_lambda2: Real,
    unknowns: Vec<u32>,
    col_of: Vec<u32>,
    j_u: CsMat<Real>,
    jt_u: CsMat<Real>,
    /// `M`'s pattern: CSR row pointers, sorted column indices (with the
    /// whole diagonal under soft constraints, which add `λ1` to it).
    indptr: Vec<usize>,
    indices: Vec<usize>,
    constrained: Vec<u32>,
    lambda1: Real,
}

impl Prepared {
    /// The partition, `J_U` and `M`'s pattern for `constrained` (sorted)
    /// on `ops`, with `a` the energy's matrix.
    pub(crate) fn new(
        ops: &Operators,
        a: &CsMat<Real>,
        params: &Params,
        constrained: &[u32],
        active: &[bool],
    ) -> Prepared {
        let n = ops.num_vertices();
        let soft = params.lambda1 > 0.0;
        let (rows, unknowns, col_of) = partition(n, constrained, active, soft);
        let row_weight: Vec<Real> = rows.iter().map(|&i| ops.area[i as usize].sqrt()).collect();
        let sqrt_lambda2 = params.lambda2.sqrt();
        let nr = rows.len();
        // J_U (the unknown columns of J), built directly in CSR order: every
        // source row is sorted and has no repeated column, and `col_of` is
        // increasing, so no sort or merge is needed. J itself is applied
        // without being stored ([`super::stacked`]).
        let nu = unknowns.len();
        let mut ju_parts = (vec![0usize], Vec::new(), Vec::new());
        for (mat, scale) in [(a, 1.0), (&ops.l, sqrt_lambda2)] {
            for (r, &i) in rows.iter().enumerate() {
                let s = row_weight[r] * scale;
                if s != 0.0 {
                    if let Some(row) = mat.outer_view(i as usize) {
                        for (c, &v) in row.iter() {
                            if col_of[c] != u32::MAX {
                                ju_parts.1.push(col_of[c] as usize);
                                ju_parts.2.push(s * v);
                            }
                        }
                    }
                }
                ju_parts.0.push(ju_parts.1.len());
            }
        }
        let j_u: CsMat<Real> = CsMat::new((2 * nr, nu), ju_parts.0, ju_parts.1, ju_parts.2);
        let jt_u: CsMat<Real> = j_u.transpose_view().to_csr();
        let (indptr, indices) = product_pattern(&jt_u, &j_u, soft);
        Prepared {
            rows,
            row_weight,
            sqrt_lambda2,
            unknowns,
            col_of,
            j_u,
            jt_u,
            indptr,
            indices,
            constrained: constrained.to_vec(),
            lambda1: params.lambda1,
        }
    }

    /// Number of unknowns (the order of `M`).
    pub(crate) fn num_unknowns(&self) -> usize {
        self.unknowns.len()
    }

    /// `M`'s pattern: CSR (= CSC, `M` being symmetric) row pointers and
    /// sorted column indices.
    pub(crate) fn pattern(&self) -> (&[usize], &[usize]) {
        (&self.indptr, &self.indices)
    }

    /// `M`'s values on [`Prepared::pattern`]: `J_Uᵀ J_U`, plus `λ1` on
    /// the constrained unknowns' diagonal under soft constraints.
    pub(crate) fn values(&self) -> Vec<Real> {
        let mut v = product_values(&self.jt_u, &self.j_u, &self.indptr, &self.indices);
        if self.lambda1 > 0.0 {
            for &c in &self.constrained {
                let k = self.col_of[c as usize];
                if k != u32::MAX {
                    let k = k as usize;
                    let row = &self.indices[self.indptr[k]..self.indptr[k + 1]];
                    if let Ok(p) = row.binary_search(&k) {
                        v[self.indptr[k] + p] += self.lambda1;
                    }
                }
            }
        }
        v
    }

    /// The system, with `M`'s `values` from [`Prepared::values`].
    pub(crate) fn into_system(self, values: Vec<Real>) -> System {
        let nu = self.unknowns.len();
        let m = CsMat::new((nu, nu), self.indptr, self.indices, values);
        System {
            rows: self.rows,
            row_weight: self.row_weight,
            sqrt_lambda2: self.sqrt_lambda2,
            unknowns: self.unknowns,
            col_of: self.col_of,
            m,
            constrained: self.constrained,
            lambda1: self.lambda1,
        }
    }
}

impl System {
    /// Assembles `J_U` and `M` for `constrained` (sorted) on `ops`.
    /// Unreferenced vertices are neither rows nor unknowns.
    #[cfg(test)]
    pub(crate) fn assemble(
        ops: &Operators,
        a: &CsMat<Real>,
        params: &Params,
        constrained: &[u32],
        active: &[bool],
    ) -> Result<Self, super::error::DeformError> {
        let prep = Prepared::new(ops, a, params, constrained, active);
        let values = prep.values();
        Ok(prep.into_system(values))
    }

    /// Number of stacked rows `2|R|`.
    pub fn num_rows(&self) -> usize {
        2 * self.rows.len()
    }

    /// `rhs += λ1 (C − Y)` on the constrained unknowns (soft constraints;
    /// nothing with hard ones). `rhs` is column-major `|U| × 3`, `targets`
    /// the normalised `(vertex, C)` pairs.
    pub(crate) fn add_soft_rhs(&self, targets: &[(u32, Point)], y: &[Point], rhs: &mut [Real]) {
        if self.lambda1 <= 0.0 {
            return;
        }
        let nu = self.unknowns.len();
        for &(v, p) in targets {
            let k = self.col_of[v as usize];
            if k == u32::MAX {
                continue;
            }
            let y = y[v as usize];
            for d in 0..3 {
                rhs[d * nu + k as usize] += self.lambda1 * (p[d] - y[d]);
            }
        }
    }

    /// The soft-constraint term `λ1 Σ_c |Y_c − C_c|²` (0 with hard
    /// constraints).
    pub(crate) fn soft_energy(&self, targets: &[(u32, Point)], y: &[Point]) -> Real {
        if self.lambda1 <= 0.0 {
            return 0.0;
        }
        targets
            .iter()
            .map(|&(v, p)| {
                let y = y[v as usize];
                self.lambda1 * (0..3).map(|k| (y[k] - p[k]).powi(2)).sum::<Real>()
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deform::energy::{energy_matrix, Energy};
    use crate::mesh::Mesh;

    fn strip() -> Mesh {
        let mut p = Vec::new();
        for r in 0..4 {
            for c in 0..6 {
                p.push([c as f64, r as f64 * 0.9, 0.1 * ((c * r) % 3) as f64]);
            }
        }
        let mut t = Vec::new();
        for r in 0..3u32 {
            for c in 0..5u32 {
                let v = r * 6 + c;
                t.push([v, v + 1, v + 7]);
                t.push([v, v + 7, v + 6]);
            }
        }
        Mesh::new(p, t).unwrap()
    }

    #[test]
    fn energy_matrices_annihilate_constants_except_the_literal_paper_form() {
        let m = strip();
        let ops = Operators::new(&m);
        for e in [
            Energy::Membrane,
            Energy::ThinPlate,
            Energy::Combined { ks: 1.0, kb: 2.0 },
            Energy::TotalCurvature,
        ] {
            let a = energy_matrix(&ops, e);
            let r: Vec<f64> = a
                .outer_iterator()
                .map(|row| row.iter().map(|(_, v)| v).sum())
                .collect();
            assert!(r.iter().all(|v| v.abs() < 1e-12), "{e:?}: A·1 = {r:?}");
        }
        let a = energy_matrix(&ops, Energy::TotalCurvaturePaper);
        let r: Vec<f64> = a
            .outer_iterator()
            .map(|row| row.iter().map(|(_, v)| v).sum())
            .collect();
        assert!(
            r.iter().any(|v| v.abs() > 1e-6),
            "L² - 2LG should not annihilate 1"
        );
    }

    /// Each energy's one-product form against the sum of products it
    /// stands for, built with sprs's own product, sum and diagonal.
    #[test]
    fn energy_matrices_equal_their_sums_of_products() {
        let m = strip();
        let ops = Operators::new(&m);
        let l = &ops.l;
        let n = m.num_vertices();
        let ll = l * l;
        let mut g = sprs::TriMat::new((n, n));
        for i in 0..n {
            g.add_triplet(i, i, ops.g[i]);
        }
        let g: CsMat<f64> = g.to_csr();
        assert!(ops.g.iter().any(|&v| v > 1e-3), "a strip with curvature");
        let (ks, kb) = (0.7, 1.9);
        let cases = [
            (Energy::ThinPlate, ll.clone()),
            (
                Energy::Combined { ks, kb },
                &l.map(|v| ks * v) + &ll.map(|v| kb * v),
            ),
            (Energy::TotalCurvature, &ll - &(&g * l).map(|v| 2.0 * v)),
            (
                Energy::TotalCurvaturePaper,
                &ll - &(l * &g).map(|v| 2.0 * v),
            ),
        ];
        for (e, want) in cases {
            let got = energy_matrix(&ops, e);
            let scale = want.data().iter().fold(0.0f64, |s, v| s.max(v.abs()));
            for i in 0..n {
                for j in 0..n {
                    let a = got.get(i, j).copied().unwrap_or(0.0);
                    let b = want.get(i, j).copied().unwrap_or(0.0);
                    assert!(
                        (a - b).abs() <= 1e-12 * scale,
                        "{e:?} ({i},{j}): {a} vs {b}"
                    );
                }
            }
            // sprs's sum drops entries that cancel (right angles have a
            // zero cotangent); the product keeps the structural pattern
            assert!(got.nnz() >= want.nnz(), "{e:?}: pattern lost entries");
        }
    }

    #[test]
    fn normal_matrix_is_symmetric_and_matches_j() {
        let m = strip();
        let ops = Operators::new(&m);
        let a = energy_matrix(&ops, Energy::TotalCurvature);
        let active = vec![true; m.num_vertices()];
        for lambda1 in [0.0, 3.0] {
            let params = Params {
                lambda1,
                ..Params::default()
            };
            let sys = System::assemble(&ops, &a, &params, &[0, 6, 5, 11], &active).unwrap();
            for (i, row) in sys.m.outer_iterator().enumerate() {
                for (j, v) in row.iter() {
                    let t = sys.m.get(j, i).copied().unwrap_or(0.0);
                    assert!((v - t).abs() < 1e-12 * (1.0 + v.abs()));
                }
            }
            assert_eq!(sys.num_rows(), 2 * (m.num_vertices() - 4));
            // M = J_Uᵀ J_U (+ λ1 on the constrained unknowns) against sprs's
            // product of the same J_U
            let prep = Prepared::new(&ops, &a, &params, &[0, 5, 6, 11], &active);
            let jtj = &prep.jt_u * &prep.j_u;
            let mut soft_diag = 0;
            for (i, row) in sys.m.outer_iterator().enumerate() {
                for (j, &v) in row.iter() {
                    let mut want = jtj.get(i, j).copied().unwrap_or(0.0);
                    if i == j && [0u32, 5, 6, 11].contains(&sys.unknowns[i]) {
                        want += lambda1;
                        soft_diag += 1;
                    }
                    assert!((v - want).abs() < 1e-12 * (1.0 + want.abs()), "({i},{j})");
                }
            }
            assert_eq!(soft_diag, if lambda1 > 0.0 { 4 } else { 0 });
            assert!(jtj.nnz() <= sys.m.nnz());
            assert_eq!(sys.unknowns.len(), if lambda1 > 0.0 { 24 } else { 20 });
        }
    }
}
