//! Sparse matrix products and entry scalings for operator assembly.
//!
//! The operators are kept as `sprs` CSR matrices (their assembly and
//! interop), but `sprs`'s generic product was the largest cost of building a
//! constraint set's normal matrix (`L·L` and `J_Uᵀ J_U`: ~25 ms and ~100 ms
//! at 10k vertices). faer's sparse–sparse product (symbolic pass, then a
//! numeric pass on the rayon pool) does the same work on the same arrays:
//! a CSR matrix's arrays are the CSC arrays of its transpose, so
//! `C = A B` in CSR is `Cᵀ = Bᵀ Aᵀ` in CSC.

use std::borrow::Cow;

use faer::sparse::linalg::matmul::sparse_sparse_matmul;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::Par;
use sprs::CsMat;

use crate::mesh::Real;

/// `A B` for CSR matrices (`A.cols() == B.rows()`), as a CSR matrix with
/// sorted indices. Panics only on mismatched shapes (a programming error) or
/// when the product does not fit in memory.
pub fn matmul(a: &CsMat<Real>, b: &CsMat<Real>) -> CsMat<Real> {
    assert_eq!(a.cols(), b.rows(), "sparse product shape mismatch");
    let (a, b) = (as_csr(a), as_csr(b));
    let (ap, bp) = (a.proper_indptr(), b.proper_indptr());
    let at = csc_of_transpose(&a, &ap);
    let bt = csc_of_transpose(&b, &bp);
    // (A B)ᵀ = Bᵀ Aᵀ
    let par = if a.nnz() + b.nnz() > 200_000 {
        Par::rayon(0)
    } else {
        Par::Seq
    };
    let ct = sparse_sparse_matmul(bt, at, 1.0, par).expect("sparse product out of memory");
    let (sym, val) = ct.into_parts();
    let (ncols_ct, nrows_ct, col_ptr, _, row_idx) = sym.into_parts();
    // Cᵀ is (B.cols × A.rows) in CSC = C (A.rows × B.cols) in CSR
    CsMat::new_from_unsorted((nrows_ct, ncols_ct), col_ptr, row_idx, val)
        .map_err(|e| e.3)
        .expect("faer's product is a valid compressed matrix")
}

/// `m` itself when it is CSR with its storage starting at 0 (every matrix
/// the operators build), else a converted copy: the product reads the raw
/// index and value arrays.
fn as_csr(m: &CsMat<Real>) -> Cow<'_, CsMat<Real>> {
    if m.is_csr() && m.indptr().index(0) == 0 {
        Cow::Borrowed(m)
    } else {
        Cow::Owned(m.to_csr())
    }
}

/// `m` with entry `(i, j)` multiplied by `f(i, j)` (same pattern).
pub fn scale_entries(m: &CsMat<Real>, f: impl Fn(usize, usize) -> Real) -> CsMat<Real> {
    let mut out = m.clone();
    for (i, mut row) in out.outer_iterator_mut().enumerate() {
        for (j, v) in row.iter_mut() {
            *v *= f(i, j);
        }
    }
    out
}

/// The CSC view of `Mᵀ` on the arrays of the CSR matrix `m` (`ptr` its
/// indptr starting at 0).
fn csc_of_transpose<'a>(m: &'a CsMat<Real>, ptr: &'a [usize]) -> SparseColMatRef<'a, usize, Real> {
    let sym = SymbolicSparseColMatRef::new_checked(m.cols(), m.rows(), ptr, None, m.indices());
    SparseColMatRef::new(sym, m.data())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use sprs::TriMat;

    fn random(rows: usize, cols: usize, entries: &[(usize, usize, f64)]) -> CsMat<f64> {
        let mut t = TriMat::new((rows, cols));
        for &(r, c, v) in entries {
            t.add_triplet(r % rows, c % cols, v);
        }
        t.to_csr()
    }

    proptest! {
        /// Equals sprs's own product (an independent implementation).
        #[test]
        fn matches_sprs(
            (r, k, c) in (1usize..12, 1usize..12, 1usize..12),
            ea in proptest::collection::vec((0usize..100, 0usize..100, -2.0f64..2.0), 0..40),
            eb in proptest::collection::vec((0usize..100, 0usize..100, -2.0f64..2.0), 0..40),
        ) {
            let a = random(r, k, &ea);
            let b = random(k, c, &eb);
            let ours = matmul(&a, &b);
            let theirs = &a * &b;
            prop_assert_eq!(ours.shape(), (r, c));
            for i in 0..r {
                for j in 0..c {
                    let x = ours.get(i, j).copied().unwrap_or(0.0);
                    let y = theirs.get(i, j).copied().unwrap_or(0.0);
                    prop_assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()), "({},{}): {} vs {}", i, j, x, y);
                }
            }
        }
    }
}
