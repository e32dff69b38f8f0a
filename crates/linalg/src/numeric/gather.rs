//! Where each entry of `M`'s lower triangle (permuted) lands in the
//! factor's values ([`Gather`]): made once for a sequence of
//! factorisations of matrices with one pattern, it replaces the per-entry
//! permutation look-ups and row searches of each supernode's gather by one
//! indexed add per entry, in the same order (so the same values).

use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;

use super::permuted::Permuted;

/// The entries of `M` each supernode gathers: `(p, offset)`, `M`'s value
/// `p` added at `offset` in the supernode's block (column-major, its
/// columns' rows then its pattern's), in the order the supernode's
/// columns and `M`'s columns list them.
#[derive(Debug)]
pub(super) struct Gather {
    ptr: Vec<usize>,
    entries: Vec<(u32, u32)>,
    /// `M`'s order and number of entries, to check a matrix against.
    n: usize,
    nnz: usize,
}

impl Gather {
    /// The gather of `a`'s pattern (its values are not read) into `sym`'s
    /// supernodes; `None` when an index does not fit 32 bits.
    pub(super) fn new(sym: &SymbolicSupernodalCholesky<usize>, a: Permuted<'_>) -> Option<Gather> {
        let n = sym.nrows();
        let nnz = a.col_ptr[n];
        if nnz > u32::MAX as usize || sym.len_val() > u32::MAX as usize {
            return None;
        }
        let (cpr, row_idx) = (sym.col_ptr_for_row_idx(), sym.row_idx());
        let mut local = vec![usize::MAX; n];
        let mut ptr = Vec::with_capacity(sym.n_supernodes() + 1);
        ptr.push(0);
        let mut entries = Vec::with_capacity(nnz / 2 + n);
        for s in 0..sym.n_supernodes() {
            let (s_start, s_end) = (sym.supernode_begin()[s], sym.supernode_end()[s]);
            let s_ncols = s_end - s_start;
            let s_pattern = &row_idx[cpr[s]..cpr[s + 1]];
            let s_nrows = s_ncols + s_pattern.len();
            for (i, &row) in s_pattern.iter().enumerate() {
                local[row] = s_ncols + i;
            }
            for j in s_start..s_end {
                let old_j = a.perm.map_or(j, |(fwd, _)| fwd[j]);
                for p in a.col_ptr[old_j]..a.col_ptr[old_j + 1] {
                    let i = a.perm.map_or(a.row_idx[p], |(_, inv)| inv[a.row_idx[p]]);
                    if i < j {
                        continue;
                    }
                    let row = if i < s_end { i - s_start } else { local[i] };
                    debug_assert!(row < s_nrows, "an entry outside the factor's pattern");
                    entries.push((p as u32, ((j - s_start) * s_nrows + row) as u32));
                }
            }
            for &row in s_pattern {
                local[row] = usize::MAX;
            }
            ptr.push(entries.len());
        }
        Some(Gather {
            ptr,
            entries,
            n,
            nnz,
        })
    }

    /// Whether `a` has the order and number of entries of the pattern the
    /// gather was made for.
    pub(super) fn fits(&self, a: &Permuted<'_>) -> bool {
        a.col_ptr.len() == self.n + 1 && a.col_ptr[self.n] == self.nnz
    }

    /// Adds supernode `s`'s entries of `values` into its block `ls`.
    pub(super) fn add(&self, s: usize, values: &[f64], ls: &mut [f64]) {
        for &(p, offset) in &self.entries[self.ptr[s]..self.ptr[s + 1]] {
            ls[offset as usize] += values[p as usize];
        }
    }
}
