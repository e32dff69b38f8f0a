//! Tree-parallel numeric supernodal Cholesky `M = L Lᵀ`, written in faer's
//! supernodal layout.
//!
//! faer's supernodal factorisation is left-looking (Ng & Peyton 1993): each
//! supernode gathers its columns of `M`, subtracts the updates
//! `L_d[rows ≥ s] · L_d[rows in s]ᵀ` of the descendants `d` whose pattern
//! reaches it, factors its diagonal block and solves its off-diagonal rows.
//! It visits the supernodes one after the other and parallelises only inside
//! their dense operations, which loses to one thread on a 10k-vertex mesh's
//! factor (docs/performance.md). But a supernode reads the values of its
//! descendants only, so two disjoint subtrees of the supernodal elimination
//! tree can be factorised at the same time: the tree parallelism of sparse
//! direct solvers (Duff & Reid 1983; Liu 1990, "The role of elimination
//! trees in sparse factorization", SIAM J. Matrix Anal. Appl. 11).
//!
//! [`NumericPlan`] (once per symbolic factorisation) holds the supernodal
//! tree, its postorder, each supernode's estimated work and the lists of
//! descendants that update each supernode. [`factorize`] then walks the
//! tree on the rayon pool: a subtree holding less than `1/TASKS` of the work
//! is one task, swept in postorder; above that, the children's subtrees are
//! forked and the supernode itself follows once they have joined. The
//! per-supernode steps are faer's (the same dense kernels: its gather-scatter
//! GEMM on x86-64 with AVX2, its dense Cholesky and triangular solve), so
//! the values are those faer would compute, in the layout its solves and
//! [`super::trisolve`] read.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{cholesky_in_place, cholesky_in_place_scratch, LltError};
use faer::reborrow::{Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::{MatMut, MatRef, Par};

use crate::Real;

mod gather;
mod permuted;
mod update;
use gather::Gather;
pub use permuted::Permuted;
use update::update_portable;
#[cfg(target_arch = "x86_64")]
use update::update_x86;

/// Subtrees with less than `1/TASKS` of the factor's work are one task.
const TASKS: f64 = 64.0;

/// Supernodes at least this wide run their dense Cholesky and triangular
/// solve on the pool (faer's `Par::rayon`), and their larger updates on two
/// threads: the top separators, which no sibling subtree can overlap.
const WIDE: usize = 96;

/// Updates with at least this many multiply-adds run on two threads inside
/// a wide supernode.
const WIDE_UPDATE_FLOPS: usize = 1 << 18;

/// A supernode's "no parent" mark.
const ROOT: usize = usize::MAX;

/// What [`factorize`] needs beyond faer's symbolic structure: analysed once
/// per symbolic factorisation.
#[derive(Debug)]
pub struct NumericPlan {
    /// Children of each supernode in the supernodal elimination tree (CSR).
    child_ptr: Vec<usize>,
    children: Vec<usize>,
    /// Supernodes without a parent.
    roots: Vec<usize>,
    /// The supernodes in postorder; the subtree of `s` is
    /// `post[first[s]..=pos[s]]`.
    post: Vec<usize>,
    first: Vec<usize>,
    pos: Vec<usize>,
    /// Estimated multiply-adds of each subtree (its supernodes' dense steps
    /// and the updates they receive).
    subtree_work: Vec<f64>,
    /// Descendants whose pattern reaches each supernode, ascending (CSR).
    upd_ptr: Vec<usize>,
    upd: Vec<usize>,
    /// Per supernode, the position in each updating descendant's pattern
    /// of its first row in the supernode (parallel to `upd`).
    upd_start: Vec<usize>,
    total_work: f64,
    /// Widest supernode and longest off-diagonal pattern.
    max_width: usize,
    max_pattern: usize,
    /// The gather of one matrix pattern's entries, for
    /// [`NumericPlan::for_matrix`]'s plans.
    gather: Option<Gather>,
}

impl NumericPlan {
    /// The plan of `sym`. `O(n + row indices)`.
    pub fn new(sym: &SymbolicSupernodalCholesky<usize>) -> NumericPlan {
        let ns = sym.n_supernodes();
        let n = sym.nrows();
        let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
        let (cpr, row_idx) = (sym.col_ptr_for_row_idx(), sym.row_idx());
        let mut node_of_col = vec![0usize; n];
        for s in 0..ns {
            node_of_col[begin[s]..end[s]].fill(s);
        }
        let mut parent = vec![ROOT; ns];
        let mut own = vec![0.0f64; ns];
        let mut upd_count = vec![0usize; ns + 1];
        let (mut max_width, mut max_pattern) = (0, 0);
        for d in 0..ns {
            let w = end[d] - begin[d];
            let pattern = &row_idx[cpr[d]..cpr[d + 1]];
            let p = pattern.len();
            max_width = max_width.max(w);
            max_pattern = max_pattern.max(p);
            let (wf, pf) = (w as f64, p as f64);
            // dense Cholesky of the diagonal block, triangular solve below
            own[d] += wf * wf * wf / 3.0 + wf * wf * pf / 2.0;
            if let Some(&r) = pattern.first() {
                parent[d] = node_of_col[r];
            }
            let mut k = 0;
            while k < p {
                let s = node_of_col[pattern[k]];
                let mut mid = 1;
                while k + mid < p && node_of_col[pattern[k + mid]] == s {
                    mid += 1;
                }
                let below = (p - k) as f64;
                own[s] += wf * mid as f64 * (below - mid as f64 / 2.0);
                upd_count[s + 1] += 1;
                k += mid;
            }
        }
        let mut upd_ptr = upd_count;
        for s in 0..ns {
            upd_ptr[s + 1] += upd_ptr[s];
        }
        let mut upd = vec![0usize; upd_ptr[ns]];
        let mut upd_start = vec![0usize; upd_ptr[ns]];
        let mut next = upd_ptr.clone();
        for d in 0..ns {
            let pattern = &row_idx[cpr[d]..cpr[d + 1]];
            let mut k = 0;
            while k < pattern.len() {
                let s = node_of_col[pattern[k]];
                upd[next[s]] = d;
                upd_start[next[s]] = k;
                next[s] += 1;
                while k < pattern.len() && node_of_col[pattern[k]] == s {
                    k += 1;
                }
            }
        }
        let mut child_ptr = vec![0usize; ns + 1];
        for &p in &parent {
            if p != ROOT {
                child_ptr[p + 1] += 1;
            }
        }
        for s in 0..ns {
            child_ptr[s + 1] += child_ptr[s];
        }
        let mut children = vec![0usize; child_ptr[ns]];
        let mut fill = child_ptr.clone();
        for (s, &p) in parent.iter().enumerate() {
            if p != ROOT {
                children[fill[p]] = s;
                fill[p] += 1;
            }
        }
        let roots: Vec<usize> = (0..ns).filter(|&s| parent[s] == ROOT).collect();
        // iterative postorder
        let mut post = Vec::with_capacity(ns);
        let mut first = vec![0usize; ns];
        let mut pos = vec![0usize; ns];
        let mut stack: Vec<(usize, usize)> = Vec::new();
        for &r in &roots {
            stack.push((r, child_ptr[r]));
            first[r] = post.len();
            while let Some(&mut (s, ref mut c)) = stack.last_mut() {
                if *c < child_ptr[s + 1] {
                    let child = children[*c];
                    *c += 1;
                    first[child] = post.len();
                    stack.push((child, child_ptr[child]));
                } else {
                    pos[s] = post.len();
                    post.push(s);
                    stack.pop();
                }
            }
        }
        let mut subtree_work = own;
        for &s in &post {
            if parent[s] != ROOT {
                subtree_work[parent[s]] += subtree_work[s];
            }
        }
        let total_work = roots.iter().map(|&r| subtree_work[r]).sum();
        NumericPlan {
            child_ptr,
            children,
            roots,
            post,
            first,
            pos,
            subtree_work,
            upd_ptr,
            upd,
            upd_start,
            total_work,
            max_width,
            max_pattern,
            gather: None,
        }
    }

    /// The plan of `sym` for a sequence of matrices with `a`'s pattern
    /// (its values are not read): each factorisation then gathers `M`'s
    /// entries by a precomputed list (`numeric/gather.rs`) instead of
    /// permuting and searching each entry's row. [`factorize`] must then be
    /// given matrices of that pattern (it checks their order and number of
    /// entries).
    pub fn for_matrix(sym: &SymbolicSupernodalCholesky<usize>, a: Permuted<'_>) -> NumericPlan {
        let mut plan = NumericPlan::new(sym);
        plan.gather = Gather::new(sym, a);
        plan
    }

    fn children(&self, s: usize) -> &[usize] {
        &self.children[self.child_ptr[s]..self.child_ptr[s + 1]]
    }

    fn subtree(&self, s: usize) -> &[usize] {
        &self.post[self.first[s]..=self.pos[s]]
    }
}

/// Why [`factorize`] stopped: the first non-positive pivot met (a column of
/// the permuted matrix), as faer reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NonPositivePivot(pub usize);

/// The factor's values, shared by the tasks. Each supernode's block is
/// written by one task only (the one that factorises it) and read by its
/// ancestors' tasks after that task has joined them.
struct Values {
    ptr: *mut Real,
    len: usize,
}

// SAFETY: see the struct's comment: the tree schedule makes the accesses
// disjoint or ordered by rayon's joins.
unsafe impl Sync for Values {}
unsafe impl Send for Values {}

/// One task's scratch: the global-to-local row map (all `usize::MAX`
/// between supernodes), the row map of an update, the dense Cholesky's
/// stack, and the product of the portable update path.
struct Scratch {
    global_to_local: Vec<usize>,
    idx: Vec<usize>,
    chol: MemBuffer,
    product: Vec<Real>,
}

struct Ctx<'a> {
    sym: &'a SymbolicSupernodalCholesky<usize>,
    plan: &'a NumericPlan,
    a: Permuted<'a>,
    values: Values,
    cutoff: f64,
    parallel: bool,
    kernels: Kernels,
    /// Smallest failing pivot column + 1 (0: none).
    failed: AtomicUsize,
    pool: Mutex<Vec<Scratch>>,
}

/// Factorises `a` into `values` (`sym.len_val()` long), on the rayon pool
/// when `parallel`.
pub fn factorize(
    sym: &SymbolicSupernodalCholesky<usize>,
    plan: &NumericPlan,
    a: Permuted<'_>,
    values: &mut [Real],
    parallel: bool,
) -> Result<(), NonPositivePivot> {
    factorize_impl(sym, plan, a, values, parallel, Kernels::detect())
}

/// The dense update kernels: `private-gemm-x86`'s AVX-512 or AVX2+FMA
/// micro-kernels with the scatter into the ancestor fused in, or faer's
/// matmul and a separate scatter where neither is present.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kernels {
    Avx512,
    Avx256,
    Portable,
}

impl Kernels {
    /// The widest the CPU runs.
    pub fn detect() -> Self {
        Self::available()[0]
    }

    /// Every kind this CPU can run, widest first (for tests).
    pub fn available() -> Vec<Self> {
        let mut v = Vec::new();
        #[cfg(target_arch = "x86_64")]
        {
            let fma = crate::cpu::has_fma();
            if crate::cpu::has_avx512() {
                v.push(Self::Avx512);
            }
            if fma {
                v.push(Self::Avx256);
            }
        }
        v.push(Self::Portable);
        v
    }
}

/// [`factorize`] with the given update kernels.
pub(crate) fn factorize_impl(
    sym: &SymbolicSupernodalCholesky<usize>,
    plan: &NumericPlan,
    a: Permuted<'_>,
    values: &mut [Real],
    parallel: bool,
    kernels: Kernels,
) -> Result<(), NonPositivePivot> {
    assert_eq!(values.len(), sym.len_val());
    assert_eq!(a.col_ptr.len(), sym.nrows() + 1);
    assert!(
        plan.gather.as_ref().is_none_or(|g| g.fits(&a)),
        "a matrix of another pattern than the plan's"
    );
    let ctx = Ctx {
        sym,
        plan,
        a,
        values: Values {
            ptr: values.as_mut_ptr(),
            len: values.len(),
        },
        cutoff: plan.total_work / TASKS,
        parallel: parallel && rayon::current_num_threads() > 1,
        kernels,
        failed: AtomicUsize::new(0),
        pool: Mutex::new(Vec::new()),
    };
    if ctx.parallel {
        use rayon::prelude::*;
        plan.roots.par_iter().for_each(|&r| run(&ctx, r));
    } else {
        let mut scratch = ctx.take_scratch();
        for &s in &plan.post {
            ctx.factor_node(s, &mut scratch, 1);
        }
    }
    match ctx.failed.load(Ordering::Relaxed) {
        0 => Ok(()),
        k => Err(NonPositivePivot(k - 1)),
    }
}

/// Factorises the subtree of `s`: as one task when small, else its
/// children's subtrees forked, then `s`.
fn run(ctx: &Ctx<'_>, s: usize) {
    let plan = ctx.plan;
    if plan.subtree_work[s] < ctx.cutoff {
        let mut scratch = ctx.take_scratch();
        for &t in plan.subtree(s) {
            ctx.factor_node(t, &mut scratch, 1);
        }
        ctx.put_scratch(scratch);
    } else {
        use rayon::prelude::*;
        plan.children(s).par_iter().for_each(|&c| run(ctx, c));
        let mut scratch = ctx.take_scratch();
        ctx.factor_node(s, &mut scratch, 2);
        ctx.put_scratch(scratch);
    }
}

impl Ctx<'_> {
    fn take_scratch(&self) -> Scratch {
        if let Some(s) = self.pool.lock().ok().and_then(|mut p| p.pop()) {
            return s;
        }
        let req = cholesky_in_place_scratch::<Real>(
            self.plan.max_width,
            Par::rayon(2),
            Default::default(),
        );
        Scratch {
            global_to_local: vec![usize::MAX; self.sym.nrows()],
            idx: Vec::with_capacity(self.plan.max_pattern),
            chol: MemBuffer::new(req),
            product: Vec::new(),
        }
    }

    fn put_scratch(&self, s: Scratch) {
        if let Ok(mut p) = self.pool.lock() {
            p.push(s);
        }
    }

    /// faer's left-looking step for supernode `s` (see the module's doc):
    /// gather, descendants' updates, dense Cholesky, triangular solve.
    /// `threads > 1` lets a wide supernode use the pool.
    fn factor_node(&self, s: usize, scr: &mut Scratch, threads: usize) {
        if self.failed.load(Ordering::Relaxed) != 0 {
            return;
        }
        let sym = self.sym;
        let (cpr, cpv, row_idx) = (
            sym.col_ptr_for_row_idx(),
            sym.col_ptr_for_val(),
            sym.row_idx(),
        );
        let s_start = sym.supernode_begin()[s];
        let s_end = sym.supernode_end()[s];
        let s_ncols = s_end - s_start;
        let s_pattern = &row_idx[cpr[s]..cpr[s + 1]];
        let s_nrows = s_ncols + s_pattern.len();
        let wide = threads > 1 && s_ncols >= WIDE;
        let par = if wide { Par::rayon(2) } else { Par::Seq };
        debug_assert!(cpv[s + 1] <= self.values.len);
        // SAFETY: supernode s's block is written by this call only; no
        // other task reads it before this task has joined its parent's.
        let ls: &mut [Real] = unsafe {
            std::slice::from_raw_parts_mut(self.values.ptr.add(cpv[s]), cpv[s + 1] - cpv[s])
        };
        ls.fill(0.0);
        let g2l = &mut scr.global_to_local;
        for (i, &row) in s_pattern.iter().enumerate() {
            g2l[row] = s_ncols + i;
        }
        // gather the lower triangle of M's permuted columns s_start..s_end
        let a = self.a;
        match self.plan.gather.as_ref() {
            Some(g) => g.add(s, a.values, ls),
            None => {
                for j in s_start..s_end {
                    let old_j = a.perm.map_or(j, |(fwd, _)| fwd[j]);
                    let col = &mut ls[(j - s_start) * s_nrows..][..s_nrows];
                    for p in a.col_ptr[old_j]..a.col_ptr[old_j + 1] {
                        let i = a.perm.map_or(a.row_idx[p], |(_, inv)| inv[a.row_idx[p]]);
                        if i < j {
                            continue;
                        }
                        let local = if i < s_end { i - s_start } else { g2l[i] };
                        col[local] += a.values[p];
                    }
                }
            }
        }
        // descendants' updates
        let plan = self.plan;
        for k in plan.upd_ptr[s]..plan.upd_ptr[s + 1] {
            let d = plan.upd[k];
            let d_start = sym.supernode_begin()[d];
            let d_ncols = sym.supernode_end()[d] - d_start;
            let d_pattern = &row_idx[cpr[d]..cpr[d + 1]];
            let d_nrows = d_ncols + d_pattern.len();
            // SAFETY: d is a finished descendant of s (joined before s).
            let ld: &[Real] = unsafe {
                std::slice::from_raw_parts(self.values.ptr.add(cpv[d]), cpv[d + 1] - cpv[d])
            };
            let start = plan.upd_start[k];
            let below = &d_pattern[start..];
            let mid = below.partition_point(|&r| r < s_end);
            scr.idx.clear();
            scr.idx.extend(below.iter().enumerate().map(|(i, &r)| {
                if i < mid {
                    r - s_start
                } else {
                    g2l[r]
                }
            }));
            let rows = below.len();
            // Ls[idx[i], idx[j]] -= Σ_k Ld[start + i, k] · Ld[start + j, k]
            // for j < mid, i ≥ j
            let threads = if wide && rows * mid * d_ncols >= WIDE_UPDATE_FLOPS {
                2
            } else {
                1
            };
            let off = d_ncols + start;
            let a = MatRef::from_column_major_slice_with_stride(&ld[off..], rows, d_ncols, d_nrows);
            match self.kernels {
                #[cfg(target_arch = "x86_64")]
                Kernels::Avx512 | Kernels::Avx256 => {
                    let instr = if self.kernels == Kernels::Avx512 {
                        private_gemm_x86::InstrSet::Avx512
                    } else {
                        private_gemm_x86::InstrSet::Avx256
                    };
                    // SAFETY: `Kernels::available` checked the instruction
                    // set; `a` is in bounds of Ld and `idx` maps its rows
                    // (and its first `mid` rows as columns) into Ls.
                    unsafe { update_x86(ls, s_nrows, &scr.idx, mid, a, instr, threads) }
                }
                _ => update_portable(ls, s_nrows, &scr.idx, mid, a, &mut scr.product),
            }
        }
        let ls_mat = MatMut::from_column_major_slice_mut(ls, s_nrows, s_ncols);
        let (mut top, bot) = ls_mat.split_at_row_mut(s_ncols);
        if let Err(LltError::NonPositivePivot { index }) = cholesky_in_place(
            top.rb_mut(),
            Default::default(),
            par,
            MemStack::new(&mut scr.chol),
            Default::default(),
        ) {
            let col = s_start + index;
            let _ = self
                .failed
                .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |f| {
                    (f == 0 || col + 1 < f).then_some(col + 1)
                });
        }
        // L_bot = A_bot L_top^{-T}
        faer::linalg::triangular_solve::solve_lower_triangular_in_place(
            top.rb(),
            bot.transpose_mut(),
            par,
        );
        for &row in s_pattern {
            g2l[row] = usize::MAX;
        }
    }
}

#[cfg(test)]
mod tests;
