//! The sparse Cholesky factorisation of a normal matrix `M` (design.md §4.4):
//! fill-reducing ordering and symbolic analysis ([`analyse`], from `M`'s
//! pattern alone), numeric factorisation ([`factorise`]).
//!
//! The ordering is AMD (faer's), or METIS nested dissection on large
//! systems ([`FillOrdering`]); the symbolic factorisation is faer's. The
//! numeric factorisation of a supernodal factor is dend's tree-parallel one
//! ([`super::numeric`]), of a simplicial (small) factor faer's.

use std::borrow::Cow;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Par, Side};

use super::numeric;
use super::ordering::{self, FillOrdering};
use crate::LinalgError;
use crate::Real;

/// The CSR arrays of a symmetric sprs matrix: row pointers from 0, column
/// indices (also its CSC arrays).
pub fn csr_arrays(m: &sprs::CsMat<Real>) -> (Cow<'_, [usize]>, &[usize]) {
    let indptr = m.proper_indptr();
    let base = m.indptr().index(0);
    let end = base + m.nnz();
    (indptr, &m.indices()[base..end])
}

/// Runs `f` on `m` (both triangles, as assembled) with `symbolic`'s
/// fill-reducing permutation: the matrix a supernodal numeric
/// factorisation and its plan read.
fn with_permuted<R>(
    symbolic: &SymbolicCholesky<usize>,
    m: &sprs::CsMat<Real>,
    f: impl FnOnce(numeric::Permuted<'_>) -> R,
) -> R {
    let (col_ptr, row_idx) = csr_arrays(m);
    let base = m.indptr().index(0);
    f(numeric::Permuted {
        col_ptr: &col_ptr,
        row_idx,
        values: &m.data()[base..base + m.nnz()],
        perm: symbolic.perm().map(|p| p.arrays()),
    })
}

/// Fill-reducing ordering and symbolic Cholesky factorisation of the
/// symmetric pattern `(col_ptr, row_idx)` (both triangles, sorted rows).
pub fn analyse(
    col_ptr: &[usize],
    row_idx: &[usize],
    ordering: FillOrdering,
) -> Result<SymbolicCholesky<usize>, LinalgError> {
    let n = col_ptr.len() - 1;
    let pattern = SymbolicSparseColMatRef::new_checked(n, n, col_ptr, None, row_idx);
    let nd = match ordering.resolve(n) {
        FillOrdering::NestedDissection => ordering::nested_dissection(col_ptr, row_idx),
        // faer's AMD (also when METIS fails), called on the sorted pattern
        // directly: faer's symbolic analysis would first sort a copy
        // (camel 19.9 -> 17.5 ms, feline 176 -> 144 ms)
        _ => ordering::amd(pattern),
    };
    let ordering = match &nd {
        Some((fwd, inv)) => {
            SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(fwd, inv, n))
        }
        None => SymmetricOrdering::Amd,
    };
    factorize_symbolic_cholesky(pattern, Side::Lower, ordering, Default::default()).map_err(|_| {
        LinalgError::OutOfMemory {
            what: "symbolic factorisation",
        }
    })
}

/// The numeric factor of `m` (symmetric, both triangles) with `symbolic`'s
/// structure, its values in faer's layout.
///
/// A numerically semi-definite `M` (8th-order stencils on irregular meshes
/// can lose definiteness in rounding) is retried once with a tiny diagonal
/// shift: each iteration solves for the update from the unsquared
/// residual, so the shift only slows convergence slightly and does not
/// change the solution.
pub fn factorise(
    symbolic: &SymbolicCholesky<usize>,
    m: &sprs::CsMat<Real>,
) -> Result<Vec<Real>, LinalgError> {
    factorise_with(symbolic, m, true)
}

/// [`factorise`] without the shifted retry: fails with
/// [`LinalgError::NotPositiveDefinite`] unless `m` is numerically positive
/// definite as it is. For a matrix that may be indefinite (a Newton
/// step's Hessian), whose caller then takes another step.
pub fn factorise_definite(
    symbolic: &SymbolicCholesky<usize>,
    m: &sprs::CsMat<Real>,
) -> Result<Vec<Real>, LinalgError> {
    factorise_with(symbolic, m, false)
}

/// Numeric factorisations of a sequence of matrices with one pattern
/// (the Newton matrix, refactored at every iteration): the supernodal
/// plan, the gather of `M`'s entries into the factor
/// ([`numeric::NumericPlan::for_matrix`]) and the factor's buffer are
/// made once instead of at each factorisation (a fresh zeroed buffer is a
/// page fault per page, 13 MB on the camel's 3258-vertex level).
pub struct Refactor {
    /// `None` for a simplicial factor (faer's, through [`factorise_definite`]).
    plan: Option<numeric::NumericPlan>,
    values: Vec<Real>,
}

impl Refactor {
    /// The plan of `symbolic` for matrices of `m`'s pattern (its values
    /// are not read).
    pub fn new(
        symbolic: &SymbolicCholesky<usize>,
        m: &sprs::CsMat<Real>,
    ) -> Result<Self, LinalgError> {
        let plan = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(sn) => Some(with_permuted(symbolic, m, |a| {
                numeric::NumericPlan::for_matrix(sn, a)
            })),
            SymbolicCholeskyRaw::Simplicial(_) => None,
        };
        let mut values = zeroed(symbolic.len_val())?;
        advise_huge_pages(&mut values);
        Ok(Refactor { plan, values })
    }

    /// [`factorise_definite`] of `m` (of the pattern given to
    /// [`Refactor::new`], with the same `symbolic`), into the kept buffer:
    /// the same values.
    pub fn factorise_definite(
        &mut self,
        symbolic: &SymbolicCholesky<usize>,
        m: &sprs::CsMat<Real>,
    ) -> Result<&[Real], LinalgError> {
        let (Some(plan), SymbolicCholeskyRaw::Supernodal(sn)) = (&self.plan, symbolic.raw()) else {
            self.values = factorise_definite(symbolic, m)?;
            return Ok(&self.values);
        };
        let values = &mut self.values;
        with_permuted(symbolic, m, |a| {
            numeric::factorize(sn, plan, a, values, true)
        })
        .map_err(|e| LinalgError::NotPositiveDefinite { pivot: e.0 })?;
        Ok(&self.values)
    }

    /// The values of the last factorisation (the factor after it
    /// succeeded).
    pub fn values(&self) -> &[Real] {
        &self.values
    }
}

fn factorise_with(
    symbolic: &SymbolicCholesky<usize>,
    m: &sprs::CsMat<Real>,
    retry_shifted: bool,
) -> Result<Vec<Real>, LinalgError> {
    let n = m.rows();
    let (col_ptr, row_idx) = csr_arrays(m);
    let base = m.indptr().index(0);
    let m_values = &m.data()[base..base + m.nnz()];
    // zeroed by the allocator, not written: a fresh mapping's pages are
    // first touched by the factorisation itself, on the pool's threads
    let mut values = zeroed(symbolic.len_val())?;
    advise_huge_pages(&mut values);
    let plan = match symbolic.raw() {
        SymbolicCholeskyRaw::Supernodal(sn) => Some(numeric::NumericPlan::new(sn)),
        SymbolicCholeskyRaw::Simplicial(_) => None,
    };
    let mut mem = match plan {
        Some(_) => None,
        None => {
            let req = symbolic.factorize_numeric_llt_scratch::<Real>(Par::Seq, Default::default());
            Some(
                MemBuffer::try_new(req).map_err(|_| LinalgError::OutOfMemory {
                    what: "factorisation scratch",
                })?,
            )
        }
    };
    let mut shifted: Option<Vec<Real>> = None;
    loop {
        let vals = shifted.as_deref().unwrap_or(m_values);
        let r = match (&plan, symbolic.raw(), mem.as_mut()) {
            (Some(plan), SymbolicCholeskyRaw::Supernodal(sn), _) => {
                let a = numeric::Permuted {
                    col_ptr: &col_ptr,
                    row_idx,
                    values: vals,
                    perm: symbolic.perm().map(|p| p.arrays()),
                };
                numeric::factorize(sn, plan, a, &mut values, true).map_err(|e| e.0)
            }
            (_, _, Some(mem)) => {
                let a = SparseColMatRef::new(
                    SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, row_idx),
                    vals,
                );
                symbolic
                    .factorize_numeric_llt::<Real>(
                        &mut values,
                        a,
                        Side::Lower,
                        LltRegularization::default(),
                        Par::Seq,
                        MemStack::new(mem),
                        Default::default(),
                    )
                    .map(|_| ())
                    .map_err(|LltError::NonPositivePivot { index }| index)
            }
            _ => unreachable!("a simplicial factor has its scratch"),
        };
        match r {
            Ok(()) => return Ok(values),
            Err(index) if shifted.is_some() || !retry_shifted => {
                return Err(LinalgError::NotPositiveDefinite { pivot: index })
            }
            Err(index) => {
                let max_diag = (0..n)
                    .filter_map(|j| m.get(j, j).copied())
                    .fold(0.0, Real::max);
                let shift = 1e-10 * max_diag;
                let mut v = m_values.to_vec();
                for j in 0..n {
                    for p in col_ptr[j]..col_ptr[j + 1] {
                        if row_idx[p] == j {
                            v[p] += shift;
                        }
                    }
                }
                shifted = Some(v);
                tracing::warn!(pivot = index, shift, "normal matrix not numerically positive definite; refactoring with a diagonal shift");
            }
        }
    }
}

/// `len` zeros from the allocator's zeroed allocation (`calloc`: a fresh
/// mapping is not written, its pages are zero when first touched).
fn zeroed(len: usize) -> Result<Vec<Real>, LinalgError> {
    let oom = LinalgError::OutOfMemory {
        what: "Cholesky factor",
    };
    if len == 0 {
        return Ok(Vec::new());
    }
    let layout = std::alloc::Layout::array::<Real>(len).map_err(|_| oom.clone())?;
    // SAFETY: the layout's size is not zero (len > 0).
    let ptr = unsafe { std::alloc::alloc_zeroed(layout) } as *mut Real;
    if ptr.is_null() {
        return Err(oom);
    }
    // SAFETY: `ptr` comes from the global allocator with the layout of
    // `len` reals, all initialised (all-zero bits are 0.0).
    Ok(unsafe { Vec::from_raw_parts(ptr, len, len) })
}

/// Asks the kernel to back `v`'s spare capacity (not touched yet) with
/// transparent huge pages (`madvise(MADV_HUGEPAGE)`; Linux's default THP
/// mode is "madvise"). The factor's values are streamed twice per solve:
/// 2 MiB pages cut the page faults of the first touch 512-fold and the TLB
/// misses of every sweep. Advice only: failure changes nothing.
fn advise_huge_pages(v: &mut Vec<Real>) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let bytes = v.capacity() * std::mem::size_of::<Real>();
        if bytes < 2 * HUGE {
            return;
        }
        let start = v.as_mut_ptr() as usize;
        let page = 4096;
        let begin = start.next_multiple_of(page);
        let end = (start + bytes) & !(page - 1);
        if end > begin {
            // SAFETY: [begin, end) lies inside the allocation of `v`; advice
            // does not change its contents or validity.
            unsafe {
                libc::madvise(begin as *mut libc::c_void, end - begin, libc::MADV_HUGEPAGE);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;

    /// `L − ε·d I` with `L` the graph Laplacian of a `k × k` grid with a
    /// radius-3 stencil and `d` its largest diagonal entry: constants are
    /// an eigenvector of eigenvalue `−ε d`, the other eigenvalues are
    /// positive, so for a small ε it is indefinite by rounding's margin.
    fn shifted_laplacian(k: usize, eps: f64) -> sprs::CsMat<f64> {
        let n = k * k;
        let mut t = sprs::TriMat::new((n, n));
        let mut diag = vec![0.0; n];
        for (c, dc) in diag.iter_mut().enumerate() {
            let (x, y) = ((c % k) as i64, (c / k) as i64);
            for dy in -3i64..=3 {
                for dx in -3i64..=3 {
                    let (u, v) = (x + dx, y + dy);
                    let r = (v * k as i64 + u) as usize;
                    if (dx, dy) != (0, 0)
                        && dx * dx + dy * dy <= 9
                        && (0..k as i64).contains(&u)
                        && (0..k as i64).contains(&v)
                    {
                        let w = 1.0 + ((r + c) % 5) as f64 / 4.0;
                        t.add_triplet(c, r, -w);
                        *dc += w;
                    }
                }
            }
        }
        let d = diag.iter().fold(0.0f64, |a, &b| a.max(b));
        for (i, v) in diag.iter().enumerate() {
            t.add_triplet(i, i, v - eps * d);
        }
        t.to_csr()
    }

    /// The first numeric factorisation meets a non-positive pivot; the
    /// retry with `1e-10 · max diag` on the diagonal, in the same values
    /// buffer, equals faer's factor of the shifted matrix.
    #[test]
    fn an_indefinite_matrix_is_refactored_with_a_diagonal_shift() {
        let m = shifted_laplacian(40, 1e-12);
        let (col_ptr, row_idx) = csr_arrays(&m);
        let sym = analyse(&col_ptr, row_idx, FillOrdering::Amd).unwrap();
        assert!(matches!(sym.raw(), SymbolicCholeskyRaw::Supernodal(_)));
        // unshifted, the factorisation fails
        let plain = faer_factor(&sym, &m, 0.0);
        assert!(plain.is_err(), "the test matrix should not be definite");
        let values = factorise(&sym, &m).unwrap();
        let max_diag = (0..m.rows())
            .filter_map(|j| m.get(j, j).copied())
            .fold(0.0, f64::max);
        let want = faer_factor(&sym, &m, 1e-10 * max_diag).unwrap();
        let scale = want.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        let d = values
            .iter()
            .zip(&want)
            .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        assert!(d <= 1e-9 * scale, "{d:e} of {scale:e}");
        // without the retry, the failure is reported
        assert!(matches!(
            factorise_definite(&sym, &m),
            Err(LinalgError::NotPositiveDefinite { .. })
        ));
    }

    /// Two matrices of one pattern factorised through one [`Refactor`]
    /// give [`factorise_definite`]'s values to the bit, and an indefinite
    /// one its error.
    #[test]
    fn a_refactor_gives_the_values_of_a_fresh_factorisation() {
        let a = shifted_laplacian(30, -0.01);
        let (col_ptr, row_idx) = csr_arrays(&a);
        let sym = analyse(&col_ptr, row_idx, FillOrdering::Amd).unwrap();
        assert!(matches!(sym.raw(), SymbolicCholeskyRaw::Supernodal(_)));
        let mut re = Refactor::new(&sym, &a).unwrap();
        for eps in [-0.01, -0.5, 1e-3, -0.02] {
            let m = shifted_laplacian(30, eps);
            let want = factorise_definite(&sym, &m);
            let got = re.factorise_definite(&sym, &m).map(|v| v.to_vec());
            match (want, got) {
                (Ok(w), Ok(g)) => assert!(w == g, "eps {eps}"),
                (Err(w), Err(g)) => assert_eq!(format!("{w:?}"), format!("{g:?}")),
                (w, g) => panic!("eps {eps}: {:?} against {:?}", w.is_ok(), g.is_ok()),
            }
        }
        assert!(re
            .factorise_definite(&sym, &shifted_laplacian(30, 1e-3))
            .is_err());
    }

    /// faer's own factor of `m + shift I`.
    fn faer_factor(
        sym: &SymbolicCholesky<usize>,
        m: &sprs::CsMat<f64>,
        shift: f64,
    ) -> Result<Vec<f64>, LltError> {
        let n = m.rows();
        let (col_ptr, row_idx) = csr_arrays(m);
        let mut vals = m.data().to_vec();
        for j in 0..n {
            for p in col_ptr[j]..col_ptr[j + 1] {
                if row_idx[p] == j {
                    vals[p] += shift;
                }
            }
        }
        let a = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, row_idx),
            &vals,
        );
        let mut values = vec![0.0; sym.len_val()];
        let mut mem =
            MemBuffer::new(sym.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()));
        sym.factorize_numeric_llt::<f64>(
            &mut values,
            a,
            Side::Lower,
            LltRegularization::default(),
            Par::Seq,
            MemStack::new(&mut mem),
            Default::default(),
        )?;
        Ok(values)
    }
}
