//! Two-thread sweeps over the supernodal elimination tree.
//!
//! Supernode `s` updates, in the forward sweep, only the rows of its
//! ancestors in the elimination tree (its off-diagonal pattern), and reads,
//! in the backward sweep, only those rows (George & Liu 1981; the tree
//! parallelism of multifrontal solvers). So two groups of subtrees with no
//! ancestor in common can be swept at the same time: the plan splits the
//! tree at its top into the subtrees of a "frontier", assigns them to two
//! threads with balanced work (longest-processing-time greedy), and leaves
//! the supernodes above the frontier (the top separators, a few percent of
//! the factor) to one thread. In the forward sweep the two threads'
//! updates of top rows go to private accumulators, added once both are
//! done; in the backward sweep the top is solved first and is then only
//! read.

use faer::dyn_stack::{MemStack, StackReq};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

use super::sweep::{backward, forward};
use super::types::{FactorValue, Lanes, Rows, Scatter, Supernodal};

/// The split of a factor's supernodes between two threads. Analysed once
/// per factor; every solve reuses it.
#[derive(Debug)]
pub struct SolvePlan {
    /// Each thread's supernodes, in elimination order.
    bins: [Vec<usize>; 2],
    /// Supernodes above the frontier, in elimination order.
    top: Vec<usize>,
    /// Per row (permuted order): 0 for a top row, else the owning thread
    /// (1 or 2).
    owner: Vec<u8>,
    /// Per row, its index among the top rows (`u32::MAX` for others).
    top_index: Vec<u32>,
    /// The top rows.
    top_rows: Vec<usize>,
    /// Top supernodes at least this wide are swept on two threads
    /// themselves ([`super::dense`]).
    dense_min_width: usize,
}

/// Default of [`SolvePlan`]'s `dense_min_width`: four panels.
const DENSE_MIN_WIDTH: usize = 4 * super::dense::PANEL;

/// Factors with fewer values are solved on one thread: their sweeps take
/// well under a millisecond, less than handing work to another thread
/// gains. (2¹⁸ values: ~2 MB in `f64`, a ~3k-vertex mesh.)
const MIN_VALUES: usize = 1 << 18;

/// The larger thread's work may exceed the smaller's by this factor.
const MAX_IMBALANCE: f64 = 1.25;

/// The top (one thread) may hold at most this share of the work.
const MAX_TOP_SHARE: f64 = 0.25;

/// Splits of the frontier tried before the best is kept.
const MAX_SPLITS: usize = 64;

impl SolvePlan {
    /// A plan for `sym`, or `None` when the factor is small or its tree
    /// does not split into two balanced halves below a small top.
    pub fn new(sym: &SymbolicSupernodalCholesky<usize>) -> Option<SolvePlan> {
        Self::with_min_values(sym, MIN_VALUES)
    }

    /// [`SolvePlan::new`] with another size threshold.
    pub fn with_min_values(
        sym: &SymbolicSupernodalCholesky<usize>,
        min_values: usize,
    ) -> Option<SolvePlan> {
        let ns = sym.n_supernodes();
        let n = sym.nrows();
        if sym.len_val() < min_values || ns < 3 {
            return None;
        }
        let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
        let (cpr, cpv, row_idx) = (
            sym.col_ptr_for_row_idx(),
            sym.col_ptr_for_val(),
            sym.row_idx(),
        );
        let mut node_of_col = vec![0usize; n];
        for s in 0..ns {
            node_of_col[begin[s]..end[s]].fill(s);
        }
        // parent: the supernode of the first off-diagonal row
        const ROOT: usize = usize::MAX;
        let mut parent = vec![ROOT; ns];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); ns];
        let mut work: Vec<f64> = (0..ns).map(|s| (cpv[s + 1] - cpv[s]) as f64).collect();
        for s in 0..ns {
            if let Some(&r) = row_idx[cpr[s]..cpr[s + 1]].iter().min() {
                let p = node_of_col[r];
                if p <= s {
                    return None; // not in elimination order: do not guess
                }
                parent[s] = p;
                children[p].push(s);
            }
        }
        let own: Vec<f64> = work.clone();
        for s in 0..ns {
            if parent[s] != ROOT {
                work[parent[s]] += work[s];
            }
        }
        let total: f64 = own.iter().sum();
        let mut frontier: Vec<usize> = (0..ns).filter(|&s| parent[s] == ROOT).collect();
        // Split the heaviest subtree of the frontier (its root joins the
        // top) step by step, and keep the split whose estimated two-thread
        // time, the top's work plus the larger thread's, is least.
        let mut top = Vec::new();
        let mut top_work = 0.0;
        // (estimated time, frontier assignment, top length)
        type Split = (f64, Vec<(usize, u8)>, usize);
        let mut best: Option<Split> = None;
        for _ in 0..MAX_SPLITS {
            frontier.sort_unstable_by(|&a, &b| work[b].total_cmp(&work[a]));
            let mut load = [0.0f64; 2];
            let mut assign = Vec::with_capacity(frontier.len());
            for &s in &frontier {
                let b = usize::from(load[1] < load[0]);
                load[b] += work[s];
                assign.push((s, b as u8 + 1));
            }
            let (lo, hi) = (load[0].min(load[1]), load[0].max(load[1]));
            let cost = top_work + hi;
            if lo > 0.0 && hi <= MAX_IMBALANCE * lo && best.as_ref().is_none_or(|b| cost < b.0) {
                best = Some((cost, assign, top.len()));
            }
            let h = frontier.remove(0);
            if children[h].is_empty() || top_work + own[h] > MAX_TOP_SHARE * total {
                break;
            }
            top_work += own[h];
            top.push(h);
            frontier.extend(children[h].iter().copied());
        }
        let (_, assignment, ntop) = best?;
        top.truncate(ntop);
        let mut in_top = vec![false; ns];
        for &s in &top {
            in_top[s] = true;
        }
        let mut node_owner = vec![0u8; ns];
        for &(s, b) in &assignment {
            node_owner[s] = b;
        }
        for s in (0..ns).rev() {
            if node_owner[s] == 0 && parent[s] != ROOT && !in_top[s] {
                node_owner[s] = node_owner[parent[s]];
            }
        }
        top.sort_unstable();
        let bins = [1u8, 2].map(|b| (0..ns).filter(|&s| node_owner[s] == b).collect());
        let owner: Vec<u8> = (0..n).map(|c| node_owner[node_of_col[c]]).collect();
        let top_rows: Vec<usize> = (0..n).filter(|&c| owner[c] == 0).collect();
        let mut top_index = vec![u32::MAX; n];
        for (i, &r) in top_rows.iter().enumerate() {
            top_index[r] = i as u32;
        }
        Some(SolvePlan {
            bins,
            top,
            owner,
            top_index,
            top_rows,
            dense_min_width: DENSE_MIN_WIDTH,
        })
    }

    /// The same plan with the top's supernodes from `width` columns on
    /// swept on two threads each (tests use small widths).
    #[cfg(test)]
    pub fn with_dense_min_width(mut self, width: usize) -> Self {
        self.dense_min_width = width;
        self
    }

    /// Widths of the top supernodes swept on two threads each.
    #[cfg(test)]
    pub fn dense_widths(&self, sym: &SymbolicSupernodalCholesky<usize>) -> Vec<usize> {
        self.top
            .iter()
            .map(|&s| sym.supernode_end()[s] - sym.supernode_begin()[s])
            .filter(|&w| w >= self.dense_min_width)
            .collect()
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        (self.bins[0].len() + self.bins[1].len() + self.top.len() + self.top_rows.len()) * 8
            + self.owner.len() * 5
    }

    /// Scratch of [`SolvePlan::solve`] beyond the first thread's buffer of
    /// `rows` rows.
    pub(super) fn scratch(&self, rows: usize) -> StackReq {
        StackReq::all_of(&[
            StackReq::new::<Lanes>(rows),
            StackReq::new::<Lanes>(self.top_rows.len()),
            StackReq::new::<Lanes>(self.top_rows.len()),
        ])
    }

    /// Both sweeps on `x` (permuted order), two threads where the plan
    /// allows; `tmp0` is the first thread's gather/scatter buffer.
    pub(super) fn solve<V: FactorValue>(
        &self,
        f: Supernodal<'_, V>,
        x: &mut [Lanes],
        tmp0: &mut [Lanes],
        stack: &mut MemStack,
    ) {
        let ntop = self.top_rows.len();
        let (mut tmp1, stack) = stack.make_with::<Lanes>(tmp0.len(), |_| [0.0; 4]);
        let (mut d1, stack) = stack.make_with::<Lanes>(ntop, |_| [0.0; 4]);
        let (mut d2, _) = stack.make_with::<Lanes>(ntop, |_| [0.0; 4]);
        let tmp1: &mut [Lanes] = &mut tmp1;
        let (d1, d2): (&mut [Lanes], &mut [Lanes]) = (&mut d1, &mut d2);
        // Every access to x below goes through `rows`: the two threads own
        // disjoint supernodes, and write other rows only into d1 / d2.
        let rows = Rows::new(x);
        let (owner, top_index) = (&self.owner[..], &self.top_index[..]);
        let [b1, b2] = &self.bins;
        let sweep = |me: u8, nodes: &[usize], tmp: &mut [Lanes], delta: &mut [Lanes]| {
            let scatter = Scatter::Split {
                me,
                owner,
                top_index,
                delta,
            };
            forward(f, nodes.iter().copied(), rows, tmp, scatter)
        };
        rayon::join(|| sweep(1, b1, tmp0, d1), || sweep(2, b2, tmp1, d2));
        for (i, &r) in self.top_rows.iter().enumerate() {
            let d = [0, 1, 2, 3].map(|k| d1[i][k] + d2[i][k]);
            // SAFETY: both threads have joined.
            unsafe { rows.sub(r, d) };
        }
        // the top on a worker thread of the pool, so that the wide nodes'
        // joins are cheap
        let sym = f.sym;
        let wide =
            |s: usize| sym.supernode_end()[s] - sym.supernode_begin()[s] >= self.dense_min_width;
        let top = &self.top;
        let tmp0: &mut [Lanes] = tmp0;
        rayon::scope(|_| {
            for &s in top {
                if wide(s) {
                    super::dense::forward_node(f, s, rows, tmp0);
                } else {
                    forward(f, std::iter::once(s), rows, tmp0, Scatter::Direct);
                }
            }
            for &s in top.iter().rev() {
                if wide(s) {
                    super::dense::backward_node(f, s, rows, tmp0);
                } else {
                    backward(f, std::iter::once(s), rows, tmp0);
                }
            }
        });
        rayon::join(
            || backward(f, b1.iter().rev().copied(), rows, tmp0),
            || backward(f, b2.iter().rev().copied(), rows, tmp1),
        );
    }
}
