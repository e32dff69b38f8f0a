//! Simplicial triangular solves `L Lᵀ x = b` for a few right-hand sides:
//! the solve of the small factors (faer makes a factor simplicial when
//! supernodes would not pay off, a few thousand unknowns on meshes).
//!
//! faer's own solve (`LltRef::solve_in_place_with_conj`) keeps the columns
//! of `b` apart: every factor entry updates three (or four) rows that lie
//! `n` values apart, and the permutation is applied column by column. Here
//! the right-hand sides are interleaved four to a row (`[f64; 4]`, as in
//! the supernodal sweeps), so a factor entry updates one row in one 4-lane
//! operation. On a 1502-vertex mesh faer's solve was ~19 % of an elastic
//! iteration.
//!
//! The arithmetic is faer's, operation for operation (per column the
//! diagonal's reciprocal times the row, then the updates in stored order;
//! backwards the dot product over the stored rows in reverse order from
//! zero, then the row minus it times the reciprocal; no fused
//! multiply-adds), so the solution is bit for bit faer's (tested).

use faer::dyn_stack::{MemStack, StackReq};
use faer::sparse::linalg::cholesky::simplicial::SymbolicSimplicialCholesky;
use faer::MatMut;

use super::types::{by_four_columns, Lanes};
use crate::Real;

/// Scratch for [`solve_in_place`]: the permuted right-hand sides.
pub fn scratch(sym: &SymbolicSimplicialCholesky<usize>) -> StackReq {
    StackReq::new::<Lanes>(sym.nrows())
}

/// `M X = B` for a simplicial Cholesky factor (`values` in faer's layout:
/// per column the diagonal first, then the rows below it), four columns of
/// `b` at a time: gathered into the factor's row order through `perm`,
/// solved, scattered back.
pub fn solve_in_place(
    sym: &SymbolicSimplicialCholesky<usize>,
    perm: Option<faer::perm::PermRef<'_, usize>>,
    values: &[Real],
    b: MatMut<'_, Real>,
    stack: &mut MemStack,
) {
    let n = sym.nrows();
    assert_eq!(values.len(), sym.len_val());
    assert_eq!(b.nrows(), n);
    let (col_ptr, row_idx) = (sym.col_ptr(), sym.row_idx());
    let (mut x, _) = stack.make_with::<Lanes>(n, |_| [0.0; 4]);
    by_four_columns(b, perm, &mut x, |x| {
        crate::cpu::with_avx2_fma(|| sweeps(col_ptr, row_idx, values, x))
    });
}

/// `L y = x`, then `Lᵀ x = y`, in place.
#[inline(always)]
fn sweeps(col_ptr: &[usize], row_idx: &[usize], values: &[Real], x: &mut [Lanes]) {
    let n = x.len();
    assert!(col_ptr.len() == n + 1 && col_ptr[n] <= row_idx.len().min(values.len()));
    for j in 0..n {
        let (p0, p1) = (col_ptr[j], col_ptr[j + 1]);
        debug_assert_eq!(row_idx[p0], j, "the diagonal is stored first");
        let r = values[p0].recip();
        let xj = x[j].map(|v| v * r);
        x[j] = xj;
        for (&i, &l) in row_idx[p0 + 1..p1].iter().zip(&values[p0 + 1..p1]) {
            let xi = &mut x[i];
            for c in 0..4 {
                xi[c] -= l * xj[c];
            }
        }
    }
    for j in (0..n).rev() {
        let (p0, p1) = (col_ptr[j], col_ptr[j + 1]);
        let mut acc = [0.0; 4];
        for (&i, &l) in row_idx[p0 + 1..p1].iter().zip(&values[p0 + 1..p1]).rev() {
            let xi = x[i];
            for c in 0..4 {
                acc[c] += l * xi[c];
            }
        }
        let r = values[p0].recip();
        let xj = x[j];
        x[j] = std::array::from_fn(|c| (xj[c] - acc[c]) * r);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::faer_values;
    use faer::dyn_stack::MemBuffer;
    use faer::sparse::linalg::cholesky::simplicial::SimplicialLltRef;
    use faer::sparse::linalg::cholesky::{
        factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholeskyRaw,
        SymmetricOrdering,
    };
    use faer::sparse::linalg::SupernodalThreshold;
    use faer::sparse::{SparseColMat, Triplet};
    use faer::{Conj, Mat, Par, Side};

    /// An SPD matrix on `n` unknowns with pseudo-random couplings of each
    /// unknown to a few others (near and far), strictly diagonally dominant.
    fn spd(n: usize, seed: usize) -> SparseColMat<usize, f64> {
        let mut pairs = std::collections::BTreeSet::new();
        for c in 0..n {
            for step in [1, 2, 7 + seed % 5, n / 3 + 1] {
                let r = (c * 13 + step * (seed + 3)) % n;
                if r != c {
                    pairs.insert((r.min(c), r.max(c)));
                }
            }
        }
        let mut t = Vec::new();
        let mut diag = vec![0.5; n];
        for (r, c) in pairs {
            let w = 0.1 + ((r * 31 + c * 17 + seed) % 97) as f64 / 97.0;
            t.push(Triplet::new(r, c, -w));
            t.push(Triplet::new(c, r, -w));
            diag[r] += w;
            diag[c] += w;
        }
        t.extend(diag.iter().enumerate().map(|(i, &d)| Triplet::new(i, i, d)));
        SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
    }

    /// The solve is faer's simplicial solve bit for bit, for one to six
    /// right-hand sides, with a fill-reducing permutation (faer's
    /// `LltRef`) and without (its `SimplicialLltRef` on the factor's
    /// order), and it solves the system (residual at rounding level).
    #[test]
    fn simplicial_solve_is_faers_bit_for_bit() {
        for (n, seed, ordering) in [
            (1, 0, SymmetricOrdering::Amd),
            (40, 1, SymmetricOrdering::Amd),
            (300, 2, SymmetricOrdering::Amd),
            (257, 3, SymmetricOrdering::Amd),
        ] {
            let m = spd(n, seed);
            let params = CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SIMPLICIAL,
                ..Default::default()
            };
            let sym =
                factorize_symbolic_cholesky(m.symbolic(), Side::Lower, ordering, params).unwrap();
            let SymbolicCholeskyRaw::Simplicial(simp) = sym.raw() else {
                panic!("forced simplicial");
            };
            let values = faer_values(&sym, &m)
                .unwrap_or_else(|pivot| panic!("n {n} seed {seed}: pivot {pivot}"));
            for k in 1..=6 {
                let b = Mat::<f64>::from_fn(n, k, |i, j| {
                    ((i * 37 + j * 11 + seed) % 23) as f64 * 0.3 - 3.1 + j as f64
                });
                let mut want = b.clone();
                let mut mem = MemBuffer::new(sym.solve_in_place_scratch::<f64>(k, Par::Seq));
                LltRef::new(&sym, &values).solve_in_place_with_conj(
                    Conj::No,
                    want.as_mut(),
                    Par::Seq,
                    MemStack::new(&mut mem),
                );
                let mut got = b.clone();
                let mut mem = MemBuffer::new(scratch(simp));
                solve_in_place(
                    simp,
                    sym.perm(),
                    &values,
                    got.as_mut(),
                    MemStack::new(&mut mem),
                );
                for j in 0..k {
                    for i in 0..n {
                        assert_eq!(
                            got[(i, j)].to_bits(),
                            want[(i, j)].to_bits(),
                            "n {n} k {k} ({i}, {j})"
                        );
                    }
                }
                let mut unpermuted = b.clone();
                let mut mem = MemBuffer::new(scratch(simp));
                solve_in_place(
                    simp,
                    None,
                    &values,
                    unpermuted.as_mut(),
                    MemStack::new(&mut mem),
                );
                let mut want = b.clone();
                SimplicialLltRef::new(simp, &values).solve_in_place_with_conj(
                    Conj::No,
                    want.as_mut(),
                    Par::Seq,
                    MemStack::new(&mut []),
                );
                assert_eq!(
                    unpermuted
                        .col_iter()
                        .flat_map(|c| c.iter().map(|v| v.to_bits()).collect::<Vec<_>>())
                        .collect::<Vec<_>>(),
                    want.col_iter()
                        .flat_map(|c| c.iter().map(|v| v.to_bits()).collect::<Vec<_>>())
                        .collect::<Vec<_>>(),
                    "unpermuted, n {n} k {k}"
                );
                let r = &m * &got - &b;
                let scale = b.norm_max().max(1.0);
                assert!(r.norm_max() < 1e-10 * scale, "residual {}", r.norm_max());
            }
        }
    }
}
