//! The two inner kernels of the supernodal sweeps, on `K ≤ 4` columns of a
//! supernode at once (register blocking: each right-hand-side row is read
//! and written once per `K` factor columns, not once per column):
//!
//! - [`update`]: `dst[i] ∓= Σ_c col_c[i] · x_c` (forward sweep: the columns
//!   just solved update the rows below them);
//! - [`dots`]: `Σ_i col_c[i] · src[i]` for each column `c` (backward sweep:
//!   the solved rows below a block of columns, gathered into `src`).
//!
//! Each comes portable (plain `f64` arithmetic, what the compiler makes of
//! it) and, on x86-64, written with AVX2+FMA intrinsics: one `[f64; 4]` row
//! is one `__m256d`, a factor value is broadcast to all four lanes. Left to
//! itself the compiler vectorised the one-column loop over four rows and
//! spent most of its instructions transposing them (measured: 3–5 cycles
//! per factor value, tube:10000).

use super::types::{FactorValue, Lanes};
use crate::Real;

/// Portable [`update`]: `dst[i] += s Σ_c col_c[i] x_c` with `s = +1` if
/// `ADD`, else `-1`.
#[inline(always)]
pub(super) fn update_portable<V: FactorValue, const K: usize, const ADD: bool>(
    cols: [&[V]; K],
    x: [Lanes; K],
    dst: &mut [Lanes],
) {
    for (i, d) in dst.iter_mut().enumerate() {
        let mut acc = [0.0; 4];
        for c in 0..K {
            let l = cols[c][i].get();
            for k in 0..4 {
                acc[k] += l * x[c][k];
            }
        }
        for k in 0..4 {
            if ADD {
                d[k] += acc[k];
            } else {
                d[k] -= acc[k];
            }
        }
    }
}

/// Portable [`dots`].
#[inline(always)]
pub(super) fn dots_portable<V: FactorValue, const K: usize>(
    cols: [&[V]; K],
    src: &[Lanes],
) -> [Lanes; K] {
    let mut acc = [[0.0; 4]; K];
    for (i, s) in src.iter().enumerate() {
        for c in 0..K {
            let l = cols[c][i].get();
            for k in 0..4 {
                acc[c][k] += l * s[k];
            }
        }
    }
    acc
}

/// AVX2+FMA [`update_portable`].
///
/// # Safety
/// The CPU must support AVX2 and FMA; every `cols[c]` must hold at least
/// `dst.len()` values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn update_avx<V: FactorValue, const K: usize, const ADD: bool>(
    cols: [&[V]; K],
    x: [Lanes; K],
    dst: &mut [Lanes],
) {
    use std::arch::x86_64::*;
    let n = dst.len();
    for c in cols {
        assert!(c.len() >= n);
    }
    let mut xv = [_mm256_setzero_pd(); K];
    for c in 0..K {
        xv[c] = _mm256_loadu_pd(x[c].as_ptr());
    }
    let d = dst.as_mut_ptr() as *mut Real;
    for i in 0..n {
        let p = d.add(4 * i);
        let mut acc = _mm256_loadu_pd(p);
        for c in 0..K {
            let l = _mm256_set1_pd(cols[c].get_unchecked(i).get());
            acc = if ADD {
                _mm256_fmadd_pd(l, xv[c], acc)
            } else {
                _mm256_fnmadd_pd(l, xv[c], acc)
            };
        }
        _mm256_storeu_pd(p, acc);
    }
}

/// AVX2+FMA [`dots_portable`]: two interleaved sets of `K` accumulators
/// hide the FMA latency.
///
/// # Safety
/// The CPU must support AVX2 and FMA; every `cols[c]` must hold at least
/// `src.len()` values.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn dots_avx<V: FactorValue, const K: usize>(
    cols: [&[V]; K],
    src: &[Lanes],
) -> [Lanes; K] {
    use std::arch::x86_64::*;
    let n = src.len();
    for c in cols {
        assert!(c.len() >= n);
    }
    let s = src.as_ptr() as *const Real;
    let mut a0 = [_mm256_setzero_pd(); K];
    let mut a1 = [_mm256_setzero_pd(); K];
    let mut i = 0;
    while i + 2 <= n {
        let s0 = _mm256_loadu_pd(s.add(4 * i));
        let s1 = _mm256_loadu_pd(s.add(4 * i + 4));
        for c in 0..K {
            let l0 = _mm256_set1_pd(cols[c].get_unchecked(i).get());
            let l1 = _mm256_set1_pd(cols[c].get_unchecked(i + 1).get());
            a0[c] = _mm256_fmadd_pd(l0, s0, a0[c]);
            a1[c] = _mm256_fmadd_pd(l1, s1, a1[c]);
        }
        i += 2;
    }
    if i < n {
        let s0 = _mm256_loadu_pd(s.add(4 * i));
        for c in 0..K {
            let l0 = _mm256_set1_pd(cols[c].get_unchecked(i).get());
            a0[c] = _mm256_fmadd_pd(l0, s0, a0[c]);
        }
    }
    let mut out = [[0.0; 4]; K];
    for c in 0..K {
        _mm256_storeu_pd(out[c].as_mut_ptr(), _mm256_add_pd(a0[c], a1[c]));
    }
    out
}
