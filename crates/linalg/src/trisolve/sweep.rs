//! The forward and back substitutions over a range of supernodes, and the
//! column-block kernels they are made of (the AVX2+FMA kernels when
//! [`has_fma`] says so).

use super::types::{FactorValue, Lanes, Rows, Scatter, Supernodal};
use crate::cpu::has_fma;

/// Forward substitution `L y = b` over `nodes` (in elimination order).
pub(crate) fn forward<V: FactorValue>(
    f: Supernodal<'_, V>,
    nodes: impl Iterator<Item = usize>,
    x: Rows,
    tmp: &mut [Lanes],
    scatter: Scatter<'_>,
) {
    if has_fma() {
        forward_impl::<V, true>(f, nodes, x, tmp, scatter);
    } else {
        forward_impl::<V, false>(f, nodes, x, tmp, scatter);
    }
}

/// Back substitution `Lᵀ x = y` over `nodes` (in reverse elimination order).
pub(crate) fn backward<V: FactorValue>(
    f: Supernodal<'_, V>,
    nodes: impl Iterator<Item = usize>,
    x: Rows,
    tmp: &mut [Lanes],
) {
    if has_fma() {
        backward_impl::<V, true>(f, nodes, x, tmp);
    } else {
        backward_impl::<V, false>(f, nodes, x, tmp);
    }
}

/// `dst ∓= Σ_c L[r0.., j0 + c] x[c]` for the `k ≤ 4` columns `j0..j0 + k`
/// of a supernode's column-major `block` of height `h`, rows
/// `r0..r0 + dst.len()` (`+=` if `ADD`). `SIMD`: the AVX2+FMA kernel, only
/// when [`has_fma`] said so.
#[inline(always)]
pub(super) fn update_block<V: FactorValue, const SIMD: bool, const ADD: bool>(
    block: &[V],
    h: usize,
    (j0, k): (usize, usize),
    r0: usize,
    x: &[Lanes],
    dst: &mut [Lanes],
) {
    #[inline(always)]
    fn run<V: FactorValue, const K: usize, const SIMD: bool, const ADD: bool>(
        block: &[V],
        h: usize,
        j0: usize,
        r0: usize,
        x: &[Lanes],
        dst: &mut [Lanes],
    ) {
        let n = dst.len();
        let cols: [&[V]; K] =
            std::array::from_fn(|c| &block[(j0 + c) * h + r0..(j0 + c) * h + r0 + n]);
        let x: [Lanes; K] = std::array::from_fn(|c| x[c]);
        #[cfg(target_arch = "x86_64")]
        if SIMD {
            // SAFETY: SIMD is set only on CPUs with AVX2 and FMA; every
            // column slice holds `dst.len()` values.
            unsafe { super::kernels::update_avx::<V, K, ADD>(cols, x, dst) };
            return;
        }
        super::kernels::update_portable::<V, K, ADD>(cols, x, dst)
    }
    if dst.is_empty() {
        return;
    }
    match k {
        1 => run::<V, 1, SIMD, ADD>(block, h, j0, r0, x, dst),
        2 => run::<V, 2, SIMD, ADD>(block, h, j0, r0, x, dst),
        3 => run::<V, 3, SIMD, ADD>(block, h, j0, r0, x, dst),
        _ => run::<V, 4, SIMD, ADD>(block, h, j0, r0, x, dst),
    }
}

/// `Σ_i L[r0 + i, j0 + c] src[i]` for the `k ≤ 4` columns `j0..j0 + k`
/// (lanes of columns `≥ k` are zero); arguments as in [`update_block`].
#[inline(always)]
pub(super) fn dots_block<V: FactorValue, const SIMD: bool>(
    block: &[V],
    h: usize,
    (j0, k): (usize, usize),
    r0: usize,
    src: &[Lanes],
) -> [Lanes; 4] {
    #[inline(always)]
    fn run<V: FactorValue, const K: usize, const SIMD: bool>(
        block: &[V],
        h: usize,
        j0: usize,
        r0: usize,
        src: &[Lanes],
    ) -> [Lanes; 4] {
        let n = src.len();
        let cols: [&[V]; K] =
            std::array::from_fn(|c| &block[(j0 + c) * h + r0..(j0 + c) * h + r0 + n]);
        #[cfg(target_arch = "x86_64")]
        let d = if SIMD {
            // SAFETY: as in `update_block`.
            unsafe { super::kernels::dots_avx::<V, K>(cols, src) }
        } else {
            super::kernels::dots_portable::<V, K>(cols, src)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let d = super::kernels::dots_portable::<V, K>(cols, src);
        std::array::from_fn(|c| if c < K { d[c] } else { [0.0; 4] })
    }
    if src.is_empty() {
        return [[0.0; 4]; 4];
    }
    match k {
        1 => run::<V, 1, SIMD>(block, h, j0, r0, src),
        2 => run::<V, 2, SIMD>(block, h, j0, r0, src),
        3 => run::<V, 3, SIMD>(block, h, j0, r0, src),
        _ => run::<V, 4, SIMD>(block, h, j0, r0, src),
    }
}

/// The triangle of the column block `(j0, k)` (`k ≤ 4`) of a supernode's
/// column-major `block` of height `h`, forward: `x[j] /= L[j, j]` and the
/// block's later rows updated, for `j` in `j0..j0 + k` (rows of `xs` are
/// the supernode's).
#[inline(always)]
pub(crate) fn triangle_forward<V: FactorValue>(
    block: &[V],
    h: usize,
    (j0, k): (usize, usize),
    xs: &mut [Lanes],
) {
    for j in j0..j0 + k {
        let col = &block[j * h..j * h + j0 + k];
        let d = col[j].get();
        let xj = xs[j].map(|v| v / d);
        xs[j] = xj;
        for i in j + 1..j0 + k {
            let l = col[i].get();
            for (xi, v) in xs[i].iter_mut().zip(xj) {
                *xi -= l * v;
            }
        }
    }
}

/// [`triangle_forward`]'s transpose: the block's rows solved last to first
/// against the block's later rows (the rows below the block already
/// subtracted).
#[inline(always)]
pub(crate) fn triangle_backward<V: FactorValue>(
    block: &[V],
    h: usize,
    (j0, k): (usize, usize),
    xs: &mut [Lanes],
) {
    for j in (j0..j0 + k).rev() {
        let col = &block[j * h..j * h + j0 + k];
        let mut a = xs[j];
        for i in j + 1..j0 + k {
            let l = col[i].get();
            for (ak, v) in a.iter_mut().zip(xs[i]) {
                *ak -= l * v;
            }
        }
        let d = col[j].get();
        xs[j] = a.map(|v| v / d);
    }
}

/// Column blocks of a supernode of width `w`: `(j0, k)`, `k ≤ 4` columns
/// from `j0`.
pub(super) fn column_blocks(w: usize) -> impl DoubleEndedIterator<Item = (usize, usize)> {
    (0..w.div_ceil(4)).map(move |b| (4 * b, (w - 4 * b).min(4)))
}

/// The forward sweep over `nodes`: per block of four columns, the block's
/// own triangle, then one pass over the rows below it (the rest of the
/// diagonal block, then the off-diagonal rows into `tmp`, scattered at the
/// end of the supernode).
#[inline(always)]
pub(super) fn forward_impl<V: FactorValue, const SIMD: bool>(
    f: Supernodal<'_, V>,
    nodes: impl Iterator<Item = usize>,
    x: Rows,
    tmp: &mut [Lanes],
    mut scatter: Scatter<'_>,
) {
    for s in nodes {
        let (c0, w, pattern, block) = f.node(s);
        let h = w + pattern.len();
        let t = &mut tmp[..pattern.len()];
        t.fill([0.0; 4]);
        // SAFETY: supernode s's rows belong to the calling thread (`Rows`).
        let xs = unsafe { x.slice(c0, w) };
        for (j0, k) in column_blocks(w) {
            triangle_forward(block, h, (j0, k), xs);
            let (head, below) = xs.split_at_mut(j0 + k);
            let solved = &head[j0..];
            update_block::<V, SIMD, false>(block, h, (j0, k), j0 + k, solved, below);
            update_block::<V, SIMD, true>(block, h, (j0, k), w, solved, t);
        }
        match &mut scatter {
            // SAFETY: a single thread owns every row.
            Scatter::Direct => {
                for (ti, &r) in t.iter().zip(pattern) {
                    unsafe { x.sub(r, *ti) };
                }
            }
            Scatter::Split {
                me,
                owner,
                top_index,
                delta,
            } => {
                for (ti, &r) in t.iter().zip(pattern) {
                    if owner[r] == *me {
                        // SAFETY: row r is this thread's.
                        unsafe { x.sub(r, *ti) };
                    } else {
                        let d = &mut delta[top_index[r] as usize];
                        for k in 0..4 {
                            d[k] += ti[k];
                        }
                    }
                }
            }
        }
    }
}

/// The backward sweep over `nodes`: the off-diagonal rows gathered into
/// `tmp`, then per block of four columns, last block first, one pass over
/// the solved rows below it and the block's own triangle.
#[inline(always)]
pub(super) fn backward_impl<V: FactorValue, const SIMD: bool>(
    f: Supernodal<'_, V>,
    nodes: impl Iterator<Item = usize>,
    x: Rows,
    tmp: &mut [Lanes],
) {
    for s in nodes {
        let (c0, w, pattern, block) = f.node(s);
        let h = w + pattern.len();
        let t = &mut tmp[..pattern.len()];
        for (ti, &r) in t.iter_mut().zip(pattern) {
            // SAFETY: ancestors' rows are final and nobody writes them now.
            *ti = unsafe { x.get(r) };
        }
        // SAFETY: supernode s's rows belong to the calling thread.
        let xs = unsafe { x.slice(c0, w) };
        for (j0, k) in column_blocks(w).rev() {
            let (head, below) = xs.split_at_mut(j0 + k);
            let off = dots_block::<V, SIMD>(block, h, (j0, k), w, t);
            let diag = dots_block::<V, SIMD>(block, h, (j0, k), j0 + k, below);
            for c in 0..k {
                for q in 0..4 {
                    head[j0 + c][q] -= off[c][q] + diag[c][q];
                }
            }
            triangle_backward(block, h, (j0, k), head);
        }
    }
}
