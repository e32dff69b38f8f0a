//! The dense update of an ancestor supernode by a descendant's block,
//! `Ls[idx, idx] -= A Aᵀ` (lower triangle): `private-gemm-x86`'s
//! micro-kernels with the scatter fused into their epilogue, or faer's
//! matmul and a separate scatter.

use faer::reborrow::ReborrowMut;
use faer::{MatMut, MatRef, Par};

use crate::Real;

/// `Ls[idx[i], idx[j]] -= (A Aᵀ)[i, j]` for `j < mid`, `i ≥ j`, with `A`
/// the `rows × depth` block of a descendant (column stride `col_stride`):
/// one call of `private-gemm-x86`, whose epilogue scatters the product's
/// lower triangle through `idx` into `Ls`, on `threads` threads.
///
/// # Safety
/// The CPU runs `instr`; `a` is a view into a live slice; every `idx[i]`
/// is below `s_nrows` and every `idx[j]`, `j < mid`, is a column of `Ls`.
#[cfg(target_arch = "x86_64")]
#[allow(clippy::too_many_arguments)]
pub(super) unsafe fn update_x86(
    ls: &mut [Real],
    s_nrows: usize,
    idx: &[usize],
    mid: usize,
    a: MatRef<'_, Real>,
    instr: private_gemm_x86::InstrSet,
    threads: usize,
) {
    // the bounds the kernel writes through, checked in release too: the
    // check is O(rows), the product O(rows · mid · depth)
    assert!(idx.len() == a.nrows() && mid <= a.nrows());
    assert!(a.row_stride() == 1);
    assert!(
        idx.iter().all(|&i| i < s_nrows),
        "update row outside the supernode"
    );
    assert!(
        idx[..mid].iter().all(|&j| (j + 1) * s_nrows <= ls.len()),
        "update column outside the supernode"
    );
    let alpha: Real = -1.0;
    let lhs = a.as_ptr() as *const ();
    let col_stride = a.col_stride();
    // SAFETY: the caller's contract.
    unsafe {
        private_gemm_x86::gemm(
            private_gemm_x86::DType::F64,
            private_gemm_x86::IType::U64,
            instr,
            a.nrows(),
            mid,
            a.ncols(),
            ls.as_mut_ptr() as *mut (),
            1,
            s_nrows as isize,
            idx.as_ptr() as *const (),
            idx.as_ptr() as *const (),
            private_gemm_x86::DstKind::Lower,
            private_gemm_x86::Accum::Add,
            lhs,
            1,
            col_stride,
            false,
            std::ptr::null(),
            0,
            lhs,
            col_stride,
            1,
            false,
            &alpha as *const Real as *const (),
            threads,
        );
    }
}

/// `Ls[idx[i], idx[j]] -= (A Aᵀ)[i, j]` for `j < mid`, `i ≥ j`, with `A`
/// the `rows × depth` block of a descendant: faer's matmul into a dense
/// product, then the scatter (machines without AVX2).
pub(super) fn update_portable(
    ls: &mut [Real],
    s_nrows: usize,
    idx: &[usize],
    mid: usize,
    a: MatRef<'_, Real>,
    product: &mut Vec<Real>,
) {
    let rows = a.nrows();
    product.clear();
    product.resize(rows * mid, 0.0);
    let mut p = MatMut::from_column_major_slice_mut(product, rows, mid);
    faer::linalg::matmul::matmul(
        p.rb_mut(),
        faer::Accum::Replace,
        a,
        a.get(..mid, ..).transpose(),
        1.0,
        Par::Seq,
    );
    for j in 0..mid {
        let col = &mut ls[idx[j] * s_nrows..][..s_nrows];
        for i in j..rows {
            col[idx[i]] -= p[(i, j)];
        }
    }
}
