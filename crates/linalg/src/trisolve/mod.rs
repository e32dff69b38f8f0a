//! Supernodal triangular solves `L Lᵀ x = b` for a few right-hand sides.
//!
//! A DEND iteration solves the factor cache's `M = L Lᵀ` for the three
//! coordinates at once (design.md §4.4). faer's general solve calls a packed
//! GEMM per supernode, which pays off for wide right-hand sides; with three
//! columns it spends its time packing the factor and in per-call overhead
//! (measured on tube:10000: 11.8 ms per solve for 2.65 M factor nonzeros,
//! ~3.6 GB/s). This module runs the same two sweeps (the supernodal layout
//! of Ng & Peyton 1993, as faer stores it) with the right-hand sides
//! interleaved four to a row (`[f64; 4]`, the fourth lane padding or a
//! fourth column), so every factor entry is read once per sweep and used in
//! one 4-lane multiply-add: the sweeps are bound by memory bandwidth, not by
//! call overhead.
//!
//! Both sweeps can run on two threads ([`parallel::SolvePlan`]): two
//! disjoint groups of subtrees of the supernodal elimination tree are
//! independent, only their common ancestors are solved by one thread.
//!
//! The kernels are compiled twice: for the baseline target and with
//! AVX2+FMA, chosen at run time.

mod dense;
mod kernels;
mod parallel;

pub use parallel::SolvePlan;

use faer::dyn_stack::{MemStack, StackReq};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::MatMut;

use crate::Real;

/// Four right-hand-side lanes of one row.
pub(crate) type Lanes = [Real; 4];

/// A stored factor value: `f64`, or `f32` widened on load
/// (`dend::deform::FactorPrecision`). The arithmetic is `f64` either way.
pub trait FactorValue: Copy + Send + Sync {
    /// The value widened to `f64`.
    fn get(self) -> Real;
}

impl FactorValue for f64 {
    #[inline(always)]
    fn get(self) -> Real {
        self
    }
}

impl FactorValue for f32 {
    #[inline(always)]
    fn get(self) -> Real {
        self as Real
    }
}

/// A supernodal factor: faer's symbolic structure and the values (per
/// supernode a column-major block, the diagonal block on top of the
/// off-diagonal rows).
#[derive(Clone, Copy)]
pub struct Supernodal<'a, V> {
    /// faer's supernodal structure.
    pub sym: &'a SymbolicSupernodalCholesky<usize>,
    /// The values, supernode after supernode.
    pub values: &'a [V],
}

impl<V: FactorValue> Supernodal<'_, V> {
    /// Columns `begin..begin + width`, off-diagonal row pattern and value
    /// block of supernode `s`.
    #[inline(always)]
    fn node(&self, s: usize) -> (usize, usize, &[usize], &[V]) {
        let sym = self.sym;
        let begin = sym.supernode_begin()[s];
        let width = sym.supernode_end()[s] - begin;
        let cpr = sym.col_ptr_for_row_idx();
        let cpv = sym.col_ptr_for_val();
        (
            begin,
            width,
            &sym.row_idx()[cpr[s]..cpr[s + 1]],
            &self.values[cpv[s]..cpv[s + 1]],
        )
    }
}

/// Scratch for [`solve_in_place`] (the permuted right-hand sides and the
/// gather/scatter buffers of one or two threads).
pub fn scratch(sym: &SymbolicSupernodalCholesky<usize>, plan: Option<&SolvePlan>) -> StackReq {
    let rows = scratch_rows(sym);
    StackReq::all_of(&[
        StackReq::new::<Lanes>(sym.nrows()),
        StackReq::new::<Lanes>(rows),
        plan.map_or(StackReq::EMPTY, |p| p.scratch(rows)),
    ])
}

/// `M X = B` for a supernodal factor, four columns of `b` at a time:
/// gathered into the factor's row order, solved (on two threads when a
/// `plan` is given), scattered back.
pub fn solve_in_place<V: FactorValue>(
    sn: &SymbolicSupernodalCholesky<usize>,
    perm: Option<faer::perm::PermRef<'_, usize>>,
    values: &[V],
    plan: Option<&SolvePlan>,
    mut b: MatMut<'_, Real>,
    stack: &mut MemStack,
) {
    let n = sn.nrows();
    assert_eq!(values.len(), sn.len_val());
    assert_eq!(b.nrows(), n);
    let factor = Supernodal { sym: sn, values };
    let rows = scratch_rows(sn);
    let (mut x, stack) = stack.make_with::<Lanes>(n, |_| [0.0; 4]);
    let (mut tmp, stack) = stack.make_with::<Lanes>(rows, |_| [0.0; 4]);
    let (fwd, inv) = match perm {
        Some(p) => {
            let (f, i) = p.arrays();
            (Some(f), Some(i))
        }
        None => (None, None),
    };
    for c0 in (0..b.ncols()).step_by(4) {
        let k = (b.ncols() - c0).min(4);
        for (i, xi) in x.iter_mut().enumerate() {
            let src = fwd.map_or(i, |f| f[i]);
            *xi = [0.0; 4];
            for l in 0..k {
                xi[l] = b[(src, c0 + l)];
            }
        }
        match plan {
            Some(p) => p.solve(factor, &mut x, &mut tmp, stack),
            None => {
                let shared = Rows::new(&mut x);
                let all = 0..sn.n_supernodes();
                forward(factor, all.clone(), shared, &mut tmp, Scatter::Direct);
                backward(factor, all.rev(), shared, &mut tmp);
            }
        }
        for i in 0..n {
            let xi = x[inv.map_or(i, |v| v[i])];
            for l in 0..k {
                b[(i, c0 + l)] = xi[l];
            }
        }
    }
}

/// Length of the gather/scatter buffer of one thread: the longest
/// off-diagonal pattern of a supernode.
pub(crate) fn scratch_rows(sym: &SymbolicSupernodalCholesky<usize>) -> usize {
    let cpr = sym.col_ptr_for_row_idx();
    (0..sym.n_supernodes())
        .map(|s| cpr[s + 1] - cpr[s])
        .max()
        .unwrap_or(0)
}

/// The solution rows, shared by the threads of a parallel sweep.
///
/// Each thread writes only the rows of its own supernodes (its subtrees of
/// the elimination tree) and reads only those and rows no thread writes in
/// that phase; [`parallel`] establishes this and the sequential sweeps are
/// trivially exclusive.
#[derive(Clone, Copy)]
pub(crate) struct Rows {
    ptr: *mut Lanes,
    len: usize,
}

// SAFETY: `Rows` is a view of a `&mut [Lanes]` that outlives every use;
// concurrent uses touch disjoint rows (type docs).
unsafe impl Send for Rows {}
unsafe impl Sync for Rows {}

impl Rows {
    pub(crate) fn new(x: &mut [Lanes]) -> Self {
        Rows {
            ptr: x.as_mut_ptr(),
            len: x.len(),
        }
    }

    /// Rows `start..start + len`.
    ///
    /// # Safety
    /// No other live reference or thread may access these rows.
    #[inline(always)]
    #[allow(clippy::mut_from_ref)]
    unsafe fn slice(&self, start: usize, len: usize) -> &mut [Lanes] {
        assert!(start + len <= self.len);
        std::slice::from_raw_parts_mut(self.ptr.add(start), len)
    }

    /// Row `r`.
    ///
    /// # Safety
    /// No other thread may write row `r` concurrently.
    #[inline(always)]
    unsafe fn get(&self, r: usize) -> Lanes {
        assert!(r < self.len);
        *self.ptr.add(r)
    }

    /// `x[r] -= v`.
    ///
    /// # Safety
    /// No other thread may access row `r` concurrently.
    #[inline(always)]
    unsafe fn sub(&self, r: usize, v: Lanes) {
        assert!(r < self.len);
        let xr = &mut *self.ptr.add(r);
        for k in 0..4 {
            xr[k] -= v[k];
        }
    }
}

/// Where a forward sweep sends a supernode's update of rows outside it.
pub(crate) enum Scatter<'a> {
    /// Straight into the solution (a single thread owns every row).
    Direct,
    /// Rows of thread `me` directly; rows of the shared ancestors into the
    /// thread's own accumulator `delta`, indexed by `top_index`.
    Split {
        me: u8,
        owner: &'a [u8],
        top_index: &'a [u32],
        delta: &'a mut [Lanes],
    },
}

pub use crate::cpu::has_fma;

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
fn update_block<V: FactorValue, const SIMD: bool, const ADD: bool>(
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
            unsafe { kernels::update_avx::<V, K, ADD>(cols, x, dst) };
            return;
        }
        kernels::update_portable::<V, K, ADD>(cols, x, dst)
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
fn dots_block<V: FactorValue, const SIMD: bool>(
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
            unsafe { kernels::dots_avx::<V, K>(cols, src) }
        } else {
            kernels::dots_portable::<V, K>(cols, src)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let d = kernels::dots_portable::<V, K>(cols, src);
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
fn column_blocks(w: usize) -> impl DoubleEndedIterator<Item = (usize, usize)> {
    (0..w.div_ceil(4)).map(move |b| (4 * b, (w - 4 * b).min(4)))
}

/// The forward sweep over `nodes`: per block of four columns, the block's
/// own triangle, then one pass over the rows below it (the rest of the
/// diagonal block, then the off-diagonal rows into `tmp`, scattered at the
/// end of the supernode).
#[inline(always)]
fn forward_impl<V: FactorValue, const SIMD: bool>(
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
fn backward_impl<V: FactorValue, const SIMD: bool>(
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

#[cfg(test)]
mod tests;
