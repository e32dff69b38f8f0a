//! Fill-reducing orderings for the factor cache.
//!
//! faer's default is approximate minimum degree (AMD). On the normal matrix
//! of a surface mesh (a planar-like graph whose stencil is up to 4 rings
//! wide) nested dissection (George 1973; METIS, Karypis & Kumar 1998)
//! produces less fill and fewer flops as the mesh grows.

use metis_sys::idx_t;

/// Which fill-reducing ordering a factor uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FillOrdering {
    /// [`FillOrdering::NestedDissection`] from
    /// [`NESTED_DISSECTION_MIN_UNKNOWNS`] unknowns on,
    /// [`FillOrdering::Amd`] below.
    #[default]
    Auto,
    /// faer's approximate minimum degree: cheapest to compute.
    Amd,
    /// METIS nested dissection of the matrix graph: the least fill on large
    /// meshes, but its analysis costs more than AMD's.
    NestedDissection,
}

/// Unknowns from which [`FillOrdering::Auto`] picks nested dissection.
/// Measured (eq. (24), total curvature, docs/performance.md): at 40 k
/// unknowns (feline) nested dissection saves 7 % of the factor and its
/// analysis costs 0.7 s more than AMD's; at 107 k (igea) it saves 26 %
/// (69.0 M → 51.3 M nonzeros, 1.10 → 0.82 GB) and the numeric
/// factorisation is 0.9 s faster, paying for its slower analysis.
pub const NESTED_DISSECTION_MIN_UNKNOWNS: usize = 65_536;

impl FillOrdering {
    /// The concrete ordering for a system of `n` unknowns.
    pub fn resolve(self, n: usize) -> FillOrdering {
        match self {
            FillOrdering::Auto if n >= NESTED_DISSECTION_MIN_UNKNOWNS => {
                FillOrdering::NestedDissection
            }
            FillOrdering::Auto => FillOrdering::Amd,
            o => o,
        }
    }
}

/// faer's approximate minimum degree ordering (Amestoy, Davis & Duff
/// 1996) of a symmetric pattern with sorted row indices in every column
/// (both triangles, as every `sprs` matrix has them): what
/// `SymmetricOrdering::Amd` computes, without the sorted copy faer first
/// makes of a pattern it cannot assume sorted. `(fwd, inv)` as for
/// [`nested_dissection`], or `None` on failure (out of memory, unsorted
/// input), where the caller falls back to faer's own.
pub fn amd(
    pattern: faer::sparse::SymbolicSparseColMatRef<'_, usize>,
) -> Option<(Vec<usize>, Vec<usize>)> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::sparse::linalg::amd;
    let n = pattern.ncols();
    let sorted = (0..n).all(|j| {
        pattern
            .row_idx_of_col_raw(j)
            .windows(2)
            .all(|w| w[0] < w[1])
    });
    if !sorted {
        return None;
    }
    let mut mem = MemBuffer::try_new(amd::order_scratch::<usize>(n, pattern.compute_nnz())).ok()?;
    let (mut fwd, mut inv) = (vec![0usize; n], vec![0usize; n]);
    amd::order(
        &mut fwd,
        &mut inv,
        pattern,
        amd::Control::default(),
        MemStack::new(&mut mem),
    )
    .ok()?;
    Some((fwd, inv))
}

/// A nested-dissection ordering of the symmetric sparsity pattern given in
/// compressed columns (`col_ptr`, `row_idx`; both triangles, diagonal
/// allowed). Returns `(fwd, inv)` with `fwd[new] = old` and
/// `inv[old] = new`, or `None` when METIS fails or the graph is too large
/// for its 32-bit indices.
pub fn nested_dissection(col_ptr: &[usize], row_idx: &[usize]) -> Option<(Vec<usize>, Vec<usize>)> {
    let n = col_ptr.len().checked_sub(1)?;
    if n == 0 || row_idx.len() >= idx_t::MAX as usize {
        return None;
    }
    let mut xadj: Vec<idx_t> = Vec::with_capacity(n + 1);
    let mut adjncy: Vec<idx_t> = Vec::with_capacity(row_idx.len());
    xadj.push(0);
    for j in 0..n {
        for &i in &row_idx[col_ptr[j]..col_ptr[j + 1]] {
            if i != j && i < n {
                adjncy.push(i as idx_t);
            }
        }
        xadj.push(adjncy.len() as idx_t);
    }
    let mut nvtxs = n as idx_t;
    let mut options = [0 as idx_t; metis_sys::METIS_NOPTIONS as usize];
    let mut perm = vec![0 as idx_t; n];
    let mut iperm = vec![0 as idx_t; n];
    // SAFETY: every pointer is to a live buffer of the length METIS reads or
    // writes (xadj n+1, adjncy xadj[n], options METIS_NOPTIONS, perm and
    // iperm n); vwgt null is allowed.
    let status = unsafe {
        metis_sys::METIS_SetDefaultOptions(options.as_mut_ptr());
        metis_sys::METIS_NodeND(
            &mut nvtxs,
            xadj.as_mut_ptr(),
            adjncy.as_mut_ptr(),
            std::ptr::null_mut(),
            options.as_mut_ptr(),
            perm.as_mut_ptr(),
            iperm.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return None;
    }
    // METIS: row i of the permuted matrix is row perm[i] of the original.
    let fwd: Vec<usize> = perm.iter().map(|&p| p as usize).collect();
    let inv: Vec<usize> = iperm.iter().map(|&p| p as usize).collect();
    // Defensive: a valid permutation or nothing.
    if fwd.iter().enumerate().any(|(i, &p)| p >= n || inv[p] != i) {
        return None;
    }
    Some((fwd, inv))
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, SymmetricOrdering};
    use faer::sparse::SymbolicSparseColMat;
    use faer::Side;

    /// The 9-point stencil pattern of a `k × k` grid, both triangles and
    /// the diagonal, in compressed columns.
    fn grid_pattern(k: usize) -> (Vec<usize>, Vec<usize>) {
        let (mut col_ptr, mut row_idx) = (vec![0], Vec::new());
        for c in 0..k * k {
            let (x, y) = ((c % k) as i64, (c / k) as i64);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (u, v) = (x + dx, y + dy);
                    if (0..k as i64).contains(&u) && (0..k as i64).contains(&v) {
                        row_idx.push((v * k as i64 + u) as usize);
                    }
                }
            }
            col_ptr.push(row_idx.len());
        }
        (col_ptr, row_idx)
    }

    fn factor_len(
        col_ptr: &[usize],
        row_idx: &[usize],
        ord: SymmetricOrdering<'_, usize>,
    ) -> usize {
        let n = col_ptr.len() - 1;
        let sym = SymbolicSparseColMat::new_checked(n, n, col_ptr.to_vec(), None, row_idx.to_vec());
        factorize_symbolic_cholesky(sym.as_ref(), Side::Lower, ord, Default::default())
            .unwrap()
            .len_val()
    }

    #[test]
    fn nested_dissection_is_a_permutation_with_less_fill_than_amd_on_a_large_grid() {
        // George's result: nested dissection of a k × k grid gives
        // O(k² log k) fill; minimum degree is not as good on large grids
        // (on 120 × 120 the two are within 1 %; the gap grows with k).
        let k = 300;
        let (col_ptr, row_idx) = grid_pattern(k);
        let (fwd, inv) = nested_dissection(&col_ptr, &row_idx).unwrap();
        let mut seen = vec![false; k * k];
        for (i, &p) in fwd.iter().enumerate() {
            assert!(!seen[p] && inv[p] == i);
            seen[p] = true;
        }
        let perm = faer::perm::PermRef::new_checked(&fwd, &inv, k * k);
        let nd = factor_len(&col_ptr, &row_idx, SymmetricOrdering::Custom(perm));
        let amd = factor_len(&col_ptr, &row_idx, SymmetricOrdering::Amd);
        assert!(
            nd < amd,
            "nested dissection {nd} vs AMD {amd} factor entries"
        );
    }

    /// `amd` is faer's AMD ordering itself (the permutation its symbolic
    /// analysis keeps with `SymmetricOrdering::Amd`), a permutation, and
    /// declines unsorted input (which AMD's sorted entry point must not see).
    #[test]
    fn amd_on_the_sorted_pattern_is_faers_own_ordering() {
        let k = 60;
        // a shuffled grid numbering, so that the ordering is not trivial
        let (cp0, ri0) = grid_pattern(k);
        let n = k * k;
        let shuffle: Vec<usize> = (0..n).map(|i| (i * 7919) % n).collect();
        let mut cols: Vec<Vec<usize>> = vec![Vec::new(); n];
        for c in 0..n {
            for &r in &ri0[cp0[c]..cp0[c + 1]] {
                cols[shuffle[c]].push(shuffle[r]);
            }
        }
        let (mut col_ptr, mut row_idx) = (vec![0], Vec::new());
        for mut c in cols {
            c.sort_unstable();
            row_idx.extend(c);
            col_ptr.push(row_idx.len());
        }
        let sym = SymbolicSparseColMat::new_checked(n, n, col_ptr.clone(), None, row_idx.clone());
        let (fwd, inv) = amd(sym.as_ref()).unwrap();
        let faer_own = factorize_symbolic_cholesky(
            sym.as_ref(),
            Side::Lower,
            SymmetricOrdering::Amd,
            Default::default(),
        )
        .unwrap();
        let (f2, _) = faer_own.perm().unwrap().arrays();
        assert_eq!(fwd, f2);
        assert!(fwd.iter().enumerate().all(|(i, &p)| inv[p] == i));
        // one column's rows swapped: unsorted
        let c = (0..n).find(|&c| col_ptr[c + 1] - col_ptr[c] >= 2).unwrap();
        row_idx.swap(col_ptr[c], col_ptr[c] + 1);
        let unsorted = SymbolicSparseColMat::new_unsorted_checked(n, n, col_ptr, None, row_idx);
        assert!(amd(unsorted.as_ref()).is_none());
    }

    #[test]
    fn empty_and_edgeless_graphs() {
        assert!(nested_dissection(&[0], &[]).is_none());
        let (fwd, inv) = nested_dissection(&[0, 1, 2, 3], &[0, 1, 2]).unwrap();
        let mut f = fwd.clone();
        f.sort_unstable();
        assert_eq!(f, vec![0, 1, 2]);
        assert!(fwd.iter().enumerate().all(|(i, &p)| inv[p] == i));
    }

    #[test]
    fn auto_picks_nested_dissection_only_for_large_systems() {
        let t = NESTED_DISSECTION_MIN_UNKNOWNS;
        assert_eq!(FillOrdering::Auto.resolve(t - 1), FillOrdering::Amd);
        assert_eq!(
            FillOrdering::Auto.resolve(t),
            FillOrdering::NestedDissection
        );
        assert_eq!(FillOrdering::Amd.resolve(10 * t), FillOrdering::Amd);
        assert_eq!(
            FillOrdering::NestedDissection.resolve(1),
            FillOrdering::NestedDissection
        );
    }
}
