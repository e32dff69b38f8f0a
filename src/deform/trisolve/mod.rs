//! Supernodal triangular solves `L Lᵀ x = b` for a few right-hand sides.
//!
//! A DEND iteration solves the factor cache's `M = L Lᵀ` for the three
//! coordinates at once (dend.md §4). faer's general solve calls a packed
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

mod parallel;

pub(crate) use parallel::SolvePlan;

use faer::dyn_stack::{MemStack, StackReq};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::MatMut;

use crate::mesh::Real;

/// Four right-hand-side lanes of one row.
pub(crate) type Lanes = [Real; 4];

/// A stored factor value: `f64`, or `f32` widened on load
/// ([`super::FactorPrecision`]). The arithmetic is `f64` either way.
pub(crate) trait FactorValue: Copy + Send + Sync {
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
pub(crate) struct Supernodal<'a, V> {
    pub sym: &'a SymbolicSupernodalCholesky<usize>,
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
pub(crate) fn scratch(
    sym: &SymbolicSupernodalCholesky<usize>,
    plan: Option<&SolvePlan>,
) -> StackReq {
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
pub(crate) fn solve_in_place<V: FactorValue>(
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

/// `acc - l·v` lane-wise (fused when `FMA`).
#[inline(always)]
fn sub_mul<const FMA: bool>(acc: Lanes, l: Real, v: Lanes) -> Lanes {
    let mut r = acc;
    for k in 0..4 {
        r[k] = if FMA {
            (-l).mul_add(v[k], acc[k])
        } else {
            acc[k] - l * v[k]
        };
    }
    r
}

/// `acc + l·v` lane-wise (fused when `FMA`).
#[inline(always)]
fn add_mul<const FMA: bool>(acc: Lanes, l: Real, v: Lanes) -> Lanes {
    let mut r = acc;
    for k in 0..4 {
        r[k] = if FMA {
            l.mul_add(v[k], acc[k])
        } else {
            acc[k] + l * v[k]
        };
    }
    r
}

fn has_fma() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Forward substitution `L y = b` over `nodes` (in elimination order).
pub(crate) fn forward<V: FactorValue>(
    f: Supernodal<'_, V>,
    nodes: impl Iterator<Item = usize>,
    x: Rows,
    tmp: &mut [Lanes],
    scatter: Scatter<'_>,
) {
    #[cfg(target_arch = "x86_64")]
    if has_fma() {
        // SAFETY: the CPU supports the features the function is compiled for.
        unsafe { forward_fma(f, nodes, x, tmp, scatter) };
        return;
    }
    forward_impl::<V, false>(f, nodes, x, tmp, scatter);
}

/// Back substitution `Lᵀ x = y` over `nodes` (in reverse elimination order).
pub(crate) fn backward<V: FactorValue>(
    f: Supernodal<'_, V>,
    nodes: impl Iterator<Item = usize>,
    x: Rows,
    tmp: &mut [Lanes],
) {
    #[cfg(target_arch = "x86_64")]
    if has_fma() {
        // SAFETY: as in `forward`.
        unsafe { backward_fma(f, nodes, x, tmp) };
        return;
    }
    backward_impl::<V, false>(f, nodes, x, tmp);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn forward_fma<V: FactorValue>(
    f: Supernodal<'_, V>,
    nodes: impl Iterator<Item = usize>,
    x: Rows,
    tmp: &mut [Lanes],
    scatter: Scatter<'_>,
) {
    forward_impl::<V, true>(f, nodes, x, tmp, scatter);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn backward_fma<V: FactorValue>(
    f: Supernodal<'_, V>,
    nodes: impl Iterator<Item = usize>,
    x: Rows,
    tmp: &mut [Lanes],
) {
    backward_impl::<V, true>(f, nodes, x, tmp);
}

#[inline(always)]
fn forward_impl<V: FactorValue, const FMA: bool>(
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
        for j in 0..w {
            let col = &block[j * h..(j + 1) * h];
            let d = col[j].get();
            let xj = xs[j].map(|v| v / d);
            xs[j] = xj;
            for (xi, &l) in xs[j + 1..].iter_mut().zip(&col[j + 1..w]) {
                *xi = sub_mul::<FMA>(*xi, l.get(), xj);
            }
            for (ti, &l) in t.iter_mut().zip(&col[w..]) {
                *ti = add_mul::<FMA>(*ti, l.get(), xj);
            }
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

#[inline(always)]
fn backward_impl<V: FactorValue, const FMA: bool>(
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
        for j in (0..w).rev() {
            let col = &block[j * h..(j + 1) * h];
            // two accumulators over the off-diagonal rows hide the FMA latency
            let (mut a0, mut a1) = (xs[j], [0.0; 4]);
            let off = &col[w..];
            let mut pairs = t.chunks_exact(2).zip(off.chunks_exact(2));
            for (tp, lp) in &mut pairs {
                a0 = sub_mul::<FMA>(a0, lp[0].get(), tp[0]);
                a1 = sub_mul::<FMA>(a1, lp[1].get(), tp[1]);
            }
            if t.len() % 2 == 1 {
                let k = t.len() - 1;
                a0 = sub_mul::<FMA>(a0, off[k].get(), t[k]);
            }
            for (xi, &l) in xs[j + 1..].iter().zip(&col[j + 1..w]) {
                a0 = sub_mul::<FMA>(a0, l.get(), *xi);
            }
            let d = col[j].get();
            xs[j] = [0, 1, 2, 3].map(|k| (a0[k] + a1[k]) / d);
        }
    }
}

#[cfg(test)]
mod tests;
