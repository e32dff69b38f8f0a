//! The Newton matrix's pattern and its assembly plan (`solver/newton.rs`):
//! analysed once per constraint set, so that each iteration only computes
//! the elements' blocks and sums them into place.
//!
//! The assembly gathers: each block of `H` lists the element blocks that
//! sum into it (their positions in the elements' buffer, in element
//! order, each to be transposed or not) and the entry of `Q` on its
//! diagonal, so it is summed by whichever thread owns its block row, in
//! the same order for any number of threads: the matrix is the same to
//! the bit. Searching each block's place in its row at every iteration
//! (as a scatter does) cost more than the elements' arithmetic: on the
//! camel's 3258-vertex level (466 k nonzeros) the searched scatter took
//! 11–12 ms of a 28–30 ms Newton iteration.

use dend_linalg::cholesky::Refactor;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::SymbolicSparseColMatRef;
use faer::Side;
use nalgebra::Matrix3;
use rayon::prelude::*;

use super::newton_state::{Gather, NewtonPattern};
use crate::deform::elastic::hessian::blocks::Elements;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::factor::Factor;
use crate::mesh::Real;

/// A source's mark: the element block is added transposed.
const TRANSPOSED: u32 = 1 << 31;

/// Element blocks summed per task of [`Gather::run`], about.
const TASK_SOURCES: usize = 4096;

impl NewtonPattern {
    /// The pattern of `H` for `factor`'s constraint set: `Q_UU`'s entries
    /// and every pair of unknowns in one element's support
    /// ([`ElasticOps::coupling_elements`]), with its assembly plan;
    /// `None` when the symbolic analysis fails (or its buffer cannot be
    /// allocated) or the elements' blocks outnumber the plan's indices.
    pub(super) fn new(
        factor: &Factor,
        el: &ElasticOps,
        set: &ElasticSet,
        ops: &crate::operators::Operators,
    ) -> Option<Self> {
        let sys = &factor.sys;
        let nu = sys.unknowns.len();
        let elements = el.coupling_elements(set, ops, &sys.col_of);
        if elements.num_blocks() >= TRANSPOSED as usize || sys.m.nnz() >= u32::MAX as usize {
            return None;
        }
        let mut rows: Vec<Vec<u32>> = vec![Vec::new(); nu];
        for (r, row) in sys.m.outer_iterator().enumerate() {
            rows[r].extend(row.indices().iter().map(|&c| c as u32));
        }
        let mut unknowns = Vec::new();
        for e in 0..elements.len() {
            unknowns.clear();
            unknowns.extend(elements.unknowns(e));
            for &k in &unknowns {
                rows[k as usize].extend(&unknowns);
            }
        }
        let mut ptr = Vec::with_capacity(nu + 1);
        let mut cols = Vec::new();
        ptr.push(0);
        for row in &mut rows {
            row.sort_unstable();
            row.dedup();
            cols.extend_from_slice(row);
            ptr.push(cols.len());
        }
        drop(rows);
        let gather = Gather::new(factor, &elements, &ptr, &cols);
        // AMD on the block graph, expanded to the coordinates
        let bidx: Vec<usize> = cols.iter().map(|&c| c as usize).collect();
        let block = SymbolicSparseColMatRef::new_checked(nu, nu, &ptr, None, &bidx);
        let (bfwd, _) = dend_linalg::ordering::amd(block)?;
        let fwd: Vec<usize> = bfwd
            .iter()
            .flat_map(|&b| [3 * b, 3 * b + 1, 3 * b + 2])
            .collect();
        let mut inv = vec![0; 3 * nu];
        for (new, &old) in fwd.iter().enumerate() {
            inv[old] = new;
        }
        // the scalar pattern
        let n = 3 * nu;
        let mut indptr = Vec::with_capacity(n + 1);
        let mut indices = Vec::with_capacity(9 * cols.len());
        indptr.push(0);
        for k in 0..nu {
            let row = &cols[ptr[k]..ptr[k + 1]];
            for _ in 0..3 {
                for &c in row {
                    indices.extend([3 * c as usize, 3 * c as usize + 1, 3 * c as usize + 2]);
                }
                indptr.push(indices.len());
            }
        }
        let data = vec![0.0; indices.len()];
        let h = sprs::CsMat::new((n, n), indptr, indices, data);
        let symbolic = {
            let indptr = h.indptr();
            let pattern =
                SymbolicSparseColMatRef::new_checked(n, n, indptr.raw_storage(), None, h.indices());
            let perm = faer::perm::PermRef::new_checked(&fwd, &inv, n);
            // supernodal whatever faer's flop ratio says: each vertex's
            // three coordinates already make a supernode of three columns,
            // and the simplicial factorisation it picked for the 32k tube's
            // 669-vertex coarsest level (107 k nonzeros) took 4.4–5.0 ms
            // per Newton step against 1.2–1.6 ms supernodal
            let params = CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            };
            factorize_symbolic_cholesky(
                pattern,
                Side::Lower,
                SymmetricOrdering::Custom(perm),
                params,
            )
            .ok()?
        };
        let refactor = Refactor::new(&symbolic, &h).ok()?;
        Some(NewtonPattern {
            factor_id: factor.id(),
            ptr,
            h,
            symbolic,
            refactor,
            blocks: vec![Matrix3::zeros(); elements.num_blocks()],
            indefinite: vec![false; elements.len()],
            elements,
            gather,
        })
    }

    /// Writes `H = Q_UU ⊗ I₃ + Σ` the elements' blocks into `h` (its
    /// values are overwritten, not added to).
    pub(super) fn gather(&mut self, q: &sprs::CsMat<Real>) {
        let q = &q.data()[q.indptr().index(0)..];
        let NewtonPattern {
            ptr,
            h,
            blocks,
            gather,
            ..
        } = self;
        gather.run(ptr, blocks, q, h.data_mut());
    }
}

impl Gather {
    /// The plan of the pattern `(ptr, cols)` for `factor`'s `Q_UU` and
    /// the `elements`' blocks.
    fn new(factor: &Factor, elements: &Elements, ptr: &[usize], cols: &[u32]) -> Gather {
        let at = |k: u32, l: u32| -> usize {
            let row = &cols[ptr[k as usize]..ptr[k as usize + 1]];
            ptr[k as usize] + row.binary_search(&l).expect("a block of the pattern")
        };
        // each element block's destinations: (k, l), and (l, k) for a pair
        let mut dest = Vec::with_capacity(elements.num_blocks());
        let mut count = vec![0usize; cols.len() + 1];
        elements.for_each_block(|k, l, _, pair| {
            let d = at(k, l);
            count[d + 1] += 1;
            let t = if pair {
                let t = at(l, k);
                count[t + 1] += 1;
                t
            } else {
                usize::MAX
            };
            dest.push((d, t));
        });
        for d in 0..cols.len() {
            count[d + 1] += count[d];
        }
        let src_ptr = count;
        let mut next = src_ptr.clone();
        let mut src = vec![0u32; src_ptr[cols.len()]];
        // in the buffer's order, which is the elements'
        for (index, &(d, t)) in dest.iter().enumerate() {
            src[next[d]] = index as u32;
            next[d] += 1;
            if t != usize::MAX {
                src[next[t]] = index as u32 | TRANSPOSED;
                next[t] += 1;
            }
        }
        let mut q = vec![u32::MAX; cols.len()];
        let m = &factor.sys.m;
        let base = m.indptr().index(0);
        for r in 0..m.rows() {
            for p in m.indptr().outer_inds_sz(r) {
                let c = m.indices()[p];
                q[at(r as u32, c as u32)] = (p - base) as u32;
            }
        }
        let mut tasks = vec![0];
        let mut load = 0;
        for k in 0..ptr.len() - 1 {
            load += src_ptr[ptr[k + 1]] - src_ptr[ptr[k]] + ptr[k + 1] - ptr[k];
            if load >= TASK_SOURCES {
                tasks.push(k + 1);
                load = 0;
            }
        }
        if tasks.last() != Some(&(ptr.len() - 1)) {
            tasks.push(ptr.len() - 1);
        }
        Gather {
            src_ptr,
            src,
            q,
            tasks,
        }
    }

    /// Sums each block of the pattern `ptr` (block rows' first block) from
    /// `blocks` and `Q_UU`'s values `q` into `data` (`H`'s values, block
    /// row `k`'s three scalar rows at `9 ptr[k]`), block rows in parallel.
    fn run(&self, ptr: &[usize], blocks: &[Matrix3<Real>], q: &[Real], data: &mut [Real]) {
        let mut parts = Vec::with_capacity(self.tasks.len());
        let mut rest = data;
        for w in self.tasks.windows(2) {
            let (head, tail) = rest.split_at_mut(9 * (ptr[w[1]] - ptr[w[0]]));
            parts.push((w[0], w[1], head));
            rest = tail;
        }
        parts.into_par_iter().for_each(|(k0, k1, out)| {
            let origin = 9 * ptr[k0];
            for k in k0..k1 {
                let width = 3 * (ptr[k + 1] - ptr[k]);
                let row = 9 * ptr[k] - origin;
                for p in ptr[k]..ptr[k + 1] {
                    let mut acc = Matrix3::zeros();
                    if self.q[p] != u32::MAX {
                        acc += Matrix3::identity() * q[self.q[p] as usize];
                    }
                    for &s in &self.src[self.src_ptr[p]..self.src_ptr[p + 1]] {
                        let b = &blocks[(s & !TRANSPOSED) as usize];
                        if s & TRANSPOSED == 0 {
                            acc += b;
                        } else {
                            acc += b.transpose();
                        }
                    }
                    let col = row + 3 * (p - ptr[k]);
                    for r in 0..3 {
                        for c in 0..3 {
                            out[col + r * width + c] = acc[(r, c)];
                        }
                    }
                }
            }
        });
    }
}
