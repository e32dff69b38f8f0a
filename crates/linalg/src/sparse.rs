//! Sparse matrix products and entry scalings for operator assembly.
//!
//! The operators are kept as `sprs` CSR matrices (their assembly and
//! interop), but `sprs`'s generic product was the largest cost of building a
//! constraint set's normal matrix (`L·L` and `J_Uᵀ J_U`: ~25 ms and ~100 ms
//! at 10k vertices), and faer's (a symbolic pass, then a numeric pass) still
//! took ~10 ms for `J_Uᵀ J_U`. [`matmul`] is Gustavson's row-by-row product
//! (Gustavson 1978, "Two fast algorithms for sparse matrices: multiplication
//! and permuted transposition"): one pass per row of `A` with a dense
//! accumulator and a marker per column of `B`, the row's pattern sorted at
//! the end; blocks of rows on the rayon pool, each with its own accumulator.

use std::borrow::Cow;

use rayon::prelude::*;
use sprs::CsMat;

use crate::Real;

/// Row count from which a one-column [`mul_columns`] runs on the rayon pool.
const PARALLEL_MIN_ROWS: usize = 4096;

/// `out = M X` for CSR `m` and the `K` columns of the column-major `x`
/// (`x.len() = K · m.cols()`, `out.len() = K · m.rows()`): the matrix is
/// read once for all `K` columns, each row's sums taken in its stored
/// order. One column (CG's `M p`) runs on the rayon pool from
/// [`PARALLEL_MIN_ROWS`] rows; several columns (the solver's `M X` of the
/// three coordinates) on the calling thread.
///
/// Rows are summed two at a time, their terms interleaved ([`row_pair`]):
/// a row's sums are chains of dependent additions, and two rows give the
/// processor twice the independent work (each row still sums its terms in
/// stored order, so the product is the same to the last bit). With the
/// `x` reads unchecked, a camel-sized 2-ring product (9770 rows, 188 k
/// entries, 3 columns) took 275–285 µs instead of 395–410 µs (best of 200,
/// loaded host).
pub fn mul_columns<const K: usize>(m: &CsMat<Real>, x: &[Real], out: &mut [Real]) {
    let (rows, cols) = (m.rows(), m.cols());
    assert!(m.is_csr(), "mul_columns: M must be CSR");
    assert_eq!(x.len(), K * cols, "mul_columns: x has K · cols entries");
    assert_eq!(out.len(), K * rows, "mul_columns: out has K · rows entries");
    let (indptr, indices, data) = (m.indptr(), m.indices(), m.data());
    let xs: [&[Real]; K] = std::array::from_fn(|c| &x[c * cols..(c + 1) * cols]);
    let row = |i: usize| {
        let span = indptr.index(i)..indptr.index(i + 1);
        (&indices[span.clone()], &data[span])
    };
    // rows `2p` and `2p + 1` (the last alone when `rows` is odd)
    let pair = |p: usize| {
        let i = 2 * p;
        if i + 1 < rows {
            row_pair(xs, row(i), row(i + 1))
        } else {
            let (a, _) = row_pair(xs, row(i), (&[], &[]));
            (a, [0.0; K])
        }
    };
    let pairs = rows.div_ceil(2);
    if K == 1 && rows >= PARALLEL_MIN_ROWS {
        out.par_chunks_mut(2).enumerate().for_each(|(p, o)| {
            let (a, b) = pair(p);
            o[0] = a[0];
            if let Some(o1) = o.get_mut(1) {
                *o1 = b[0];
            }
        });
    } else {
        for p in 0..pairs {
            let (a, b) = pair(p);
            for c in 0..K {
                out[c * rows + 2 * p] = a[c];
                if 2 * p + 1 < rows {
                    out[c * rows + 2 * p + 1] = b[c];
                }
            }
        }
    }
}

/// Two rows `(indices, values)` of a CSR matrix times the `K` columns
/// `xs` (each of the matrix's column count): per row and column the sum
/// of its terms in stored order from 0, the two rows' terms interleaved.
#[inline(always)]
fn row_pair<const K: usize>(
    xs: [&[Real]; K],
    (ia, va): (&[usize], &[Real]),
    (ib, vb): (&[usize], &[Real]),
) -> ([Real; K], [Real; K]) {
    let cols = xs.first().map_or(0, |x| x.len());
    debug_assert!(xs.iter().all(|x| x.len() == cols));
    debug_assert!(ia.iter().chain(ib).all(|&j| j < cols));
    // x_c[j]: j is a column index of a CsMat, < cols (sprs checks every
    // index when a matrix is built; only its unsafe constructors skip
    // that), and every xs[c] has cols entries
    let at = |c: usize, j: usize| -> Real {
        // SAFETY: j < cols = xs[c].len() (above).
        unsafe { *xs[c].get_unchecked(j) }
    };
    let (mut a, mut b) = ([0.0; K], [0.0; K]);
    let common = ia.len().min(ib.len()).min(va.len()).min(vb.len());
    let (ia0, va0, ib0, vb0) = (&ia[..common], &va[..common], &ib[..common], &vb[..common]);
    for p in 0..common {
        let (ja, wa, jb, wb) = (ia0[p], va0[p], ib0[p], vb0[p]);
        for c in 0..K {
            a[c] += wa * at(c, ja);
            b[c] += wb * at(c, jb);
        }
    }
    for (&j, &w) in ia[common..].iter().zip(&va[common..]) {
        for (c, acc) in a.iter_mut().enumerate() {
            *acc += w * at(c, j);
        }
    }
    for (&j, &w) in ib[common..].iter().zip(&vb[common..]) {
        for (c, acc) in b.iter_mut().enumerate() {
            *acc += w * at(c, j);
        }
    }
    (a, b)
}

/// Rows of `A` per parallel block of [`matmul`].
const ROW_BLOCK: usize = 1024;

/// Products with fewer multiply-adds than this run on one thread.
const PARALLEL_MIN_FLOPS: usize = 200_000;

/// `block(r0, r1)` over rows `0..rows`: in blocks of [`ROW_BLOCK`] rows on
/// the rayon pool when the product has `flops` ≥ [`PARALLEL_MIN_FLOPS`],
/// else as one block; results in row order.
fn map_row_blocks<R: Send>(
    rows: usize,
    flops: usize,
    block: impl Fn(usize, usize) -> R + Sync,
) -> Vec<R> {
    if flops >= PARALLEL_MIN_FLOPS && rows > ROW_BLOCK {
        (0..rows.div_ceil(ROW_BLOCK))
            .into_par_iter()
            .map(|c| block(c * ROW_BLOCK, ((c + 1) * ROW_BLOCK).min(rows)))
            .collect()
    } else {
        vec![block(0, rows)]
    }
}

/// `A B` for CSR matrices (`A.cols() == B.rows()`), as a CSR matrix with
/// sorted indices and no explicit zeros removed (the pattern is structural).
/// Panics only on mismatched shapes (a programming error) or when the
/// product does not fit in memory.
pub fn matmul(a: &CsMat<Real>, b: &CsMat<Real>) -> CsMat<Real> {
    assert_eq!(a.cols(), b.rows(), "sparse product shape mismatch");
    let (a, b) = (as_csr(a), as_csr(b));
    let (ap, bp) = (a.proper_indptr(), b.proper_indptr());
    let (rows, cols) = (a.rows(), b.cols());
    let flops: usize = a.indices().iter().map(|&k| bp[k + 1] - bp[k]).sum();
    // one block: (row lengths, indices, values)
    let block = |r0: usize, r1: usize| {
        let mut mark = vec![usize::MAX; cols];
        let mut acc = vec![0.0; cols];
        let mut lens = Vec::with_capacity(r1 - r0);
        let mut idx = Vec::new();
        let mut val = Vec::new();
        for i in r0..r1 {
            let start = idx.len();
            for p in ap[i]..ap[i + 1] {
                let (k, aik) = (a.indices()[p], a.data()[p]);
                for q in bp[k]..bp[k + 1] {
                    let (j, bkj) = (b.indices()[q], b.data()[q]);
                    if mark[j] != i {
                        mark[j] = i;
                        acc[j] = aik * bkj;
                        idx.push(j);
                    } else {
                        acc[j] += aik * bkj;
                    }
                }
            }
            idx[start..].sort_unstable();
            val.extend(idx[start..].iter().map(|&j| acc[j]));
            lens.push(idx.len() - start);
        }
        (lens, idx, val)
    };
    let blocks = map_row_blocks(rows, flops, block);
    let nnz: usize = blocks.iter().map(|b| b.1.len()).sum();
    let mut indptr = Vec::with_capacity(rows + 1);
    let (mut indices, mut data) = (Vec::with_capacity(nnz), Vec::with_capacity(nnz));
    indptr.push(0);
    for (lens, idx, val) in blocks {
        for l in lens {
            indptr.push(indptr.last().copied().unwrap_or(0) + l);
        }
        indices.extend_from_slice(&idx);
        data.extend_from_slice(&val);
    }
    CsMat::new((rows, cols), indptr, indices, data)
}

/// The pattern of `A B` for CSR matrices: row pointers and, per row, the
/// sorted column indices; with `diagonal`, every `(i, i)` is in it too (a
/// square product that gets a diagonal term added). The symbolic half of
/// Gustavson's product: [`product_values`] then fills it without the
/// marker's branch, and the pattern alone is enough to order and analyse
/// the factor of `A B` meanwhile.
pub fn product_pattern(
    a: &CsMat<Real>,
    b: &CsMat<Real>,
    diagonal: bool,
) -> (Vec<usize>, Vec<usize>) {
    assert_eq!(a.cols(), b.rows(), "sparse product shape mismatch");
    assert!(
        !diagonal || a.rows() == b.cols(),
        "a diagonal needs a square product"
    );
    let (a, b) = (as_csr(a), as_csr(b));
    let (ap, bp) = (a.proper_indptr(), b.proper_indptr());
    let (rows, cols) = (a.rows(), b.cols());
    let (ai, bi) = (a.indices(), b.indices());
    let flops: usize = ai.iter().map(|&k| bp[k + 1] - bp[k]).sum();
    let block = |r0: usize, r1: usize| {
        let mut mark = vec![usize::MAX; cols];
        let mut lens = Vec::with_capacity(r1 - r0);
        let mut idx = Vec::new();
        for i in r0..r1 {
            let start = idx.len();
            if diagonal {
                mark[i] = i;
                idx.push(i);
            }
            for &k in &ai[ap[i]..ap[i + 1]] {
                for &j in &bi[bp[k]..bp[k + 1]] {
                    if mark[j] != i {
                        mark[j] = i;
                        idx.push(j);
                    }
                }
            }
            idx[start..].sort_unstable();
            lens.push(idx.len() - start);
        }
        (lens, idx)
    };
    let blocks = map_row_blocks(rows, flops, block);
    let nnz: usize = blocks.iter().map(|b| b.1.len()).sum();
    let mut indptr = Vec::with_capacity(rows + 1);
    let mut indices = Vec::with_capacity(nnz);
    indptr.push(0);
    for (lens, idx) in blocks {
        for l in lens {
            indptr.push(indptr.last().copied().unwrap_or(0) + l);
        }
        indices.extend_from_slice(&idx);
    }
    (indptr, indices)
}

/// The values of `A B` on a pattern holding the product's
/// ([`product_pattern`]): entry `p` of row `i` is `(A B)[i, indices[p]]`,
/// 0 where the pattern is wider than the product. One dense accumulator per
/// block of rows, cleared through the pattern after each row.
pub fn product_values(
    a: &CsMat<Real>,
    b: &CsMat<Real>,
    indptr: &[usize],
    indices: &[usize],
) -> Vec<Real> {
    assert_eq!(a.cols(), b.rows(), "sparse product shape mismatch");
    assert_eq!(indptr.len(), a.rows() + 1, "pattern rows");
    let (a, b) = (as_csr(a), as_csr(b));
    let (ap, bp) = (a.proper_indptr(), b.proper_indptr());
    let (rows, cols) = (a.rows(), b.cols());
    let (ai, av, bi, bv) = (a.indices(), a.data(), b.indices(), b.data());
    let flops: usize = ai.iter().map(|&k| bp[k + 1] - bp[k]).sum();
    let mut data = vec![0.0; indptr[rows]];
    // rows r0..r1 into `out` (their slice of `data`)
    let block = |r0: usize, r1: usize, out: &mut [Real]| {
        let mut acc = vec![0.0; cols];
        let base = indptr[r0];
        for i in r0..r1 {
            for p in ap[i]..ap[i + 1] {
                let (k, aik) = (ai[p], av[p]);
                for q in bp[k]..bp[k + 1] {
                    acc[bi[q]] += aik * bv[q];
                }
            }
            for p in indptr[i]..indptr[i + 1] {
                let j = indices[p];
                out[p - base] = acc[j];
                acc[j] = 0.0;
            }
        }
    };
    if flops >= PARALLEL_MIN_FLOPS && rows > ROW_BLOCK {
        let mut chunks = Vec::with_capacity(rows.div_ceil(ROW_BLOCK));
        let mut rest: &mut [Real] = &mut data;
        for c in 0..rows.div_ceil(ROW_BLOCK) {
            let (r0, r1) = (c * ROW_BLOCK, ((c + 1) * ROW_BLOCK).min(rows));
            let (head, tail) = rest.split_at_mut(indptr[r1] - indptr[r0]);
            chunks.push((r0, r1, head));
            rest = tail;
        }
        chunks
            .into_par_iter()
            .for_each(|(r0, r1, out)| block(r0, r1, out));
    } else {
        block(0, rows, &mut data);
    }
    data
}

/// `m` itself when it is CSR with its storage starting at 0 (every matrix
/// the operators build), else a converted copy: the product reads the raw
/// index and value arrays.
fn as_csr(m: &CsMat<Real>) -> Cow<'_, CsMat<Real>> {
    if m.is_csr() && m.indptr().index(0) == 0 {
        Cow::Borrowed(m)
    } else {
        Cow::Owned(m.to_csr())
    }
}

/// `m` with entry `(i, j)` multiplied by `f(i, j)` (same pattern).
pub fn scale_entries(m: &CsMat<Real>, f: impl Fn(usize, usize) -> Real) -> CsMat<Real> {
    let mut out = m.clone();
    for (i, mut row) in out.outer_iterator_mut().enumerate() {
        for (j, v) in row.iter_mut() {
            *v *= f(i, j);
        }
    }
    out
}

/// `c M + diag(d)` for a square CSR matrix `M` (sorted rows): every entry
/// scaled by `c` and `d(i)` added to the diagonal, which is inserted
/// where `M` has none.
pub fn scale_and_shift_diagonal(
    m: &CsMat<Real>,
    c: Real,
    d: impl Fn(usize) -> Real,
) -> CsMat<Real> {
    assert_eq!(m.rows(), m.cols(), "a diagonal shift needs a square matrix");
    let m = as_csr(m);
    let n = m.rows();
    let mut indptr = Vec::with_capacity(n + 1);
    let mut indices = Vec::with_capacity(m.nnz() + n);
    let mut data = Vec::with_capacity(m.nnz() + n);
    indptr.push(0);
    for (i, row) in m.outer_iterator().enumerate() {
        let (idx, val) = (row.indices(), row.data());
        // the entries left of the diagonal, the diagonal, the rest
        let k = idx.partition_point(|&j| j < i);
        let on_diagonal = idx.get(k) == Some(&i);
        indices.extend_from_slice(&idx[..k]);
        data.extend(val[..k].iter().map(|&v| c * v));
        indices.push(i);
        data.push(if on_diagonal { c * val[k] + d(i) } else { d(i) });
        let rest = k + usize::from(on_diagonal);
        indices.extend_from_slice(&idx[rest..]);
        data.extend(val[rest..].iter().map(|&v| c * v));
        indptr.push(indices.len());
    }
    CsMat::new((n, n), indptr, indices, data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use sprs::TriMat;

    /// A reproducible stream of pseudo-random `usize`s (Knuth's MMIX linear
    /// congruential generator, high bits) for the tests' random matrices.
    fn lcg(seed: u64) -> impl FnMut() -> usize {
        let mut state = seed;
        move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as usize
        }
    }

    fn random(rows: usize, cols: usize, entries: &[(usize, usize, f64)]) -> CsMat<f64> {
        let mut t = TriMat::new((rows, cols));
        for &(r, c, v) in entries {
            t.add_triplet(r % rows, c % cols, v);
        }
        t.to_csr()
    }

    /// The diagonal scaled and shifted where present, inserted in order
    /// where absent (rows 1 and 3 have none; row 3 is empty).
    #[test]
    fn scale_and_shift_diagonal_inserts_missing_diagonals() {
        let m = random(
            4,
            4,
            &[
                (0, 0, 1.0),
                (0, 2, 2.0),
                (1, 0, 3.0),
                (1, 3, 4.0),
                (2, 2, 5.0),
                (2, 1, 6.0),
            ],
        );
        let s = scale_and_shift_diagonal(&m, 2.0, |i| 10.0 * (i + 1) as f64);
        let dense = |a: &CsMat<f64>| -> Vec<Vec<f64>> {
            (0..4)
                .map(|i| {
                    (0..4)
                        .map(|j| a.get(i, j).copied().unwrap_or(0.0))
                        .collect()
                })
                .collect()
        };
        let (dm, ds) = (dense(&m), dense(&s));
        for i in 0..4 {
            for j in 0..4 {
                let want = 2.0 * dm[i][j] + if i == j { 10.0 * (i + 1) as f64 } else { 0.0 };
                assert_eq!(ds[i][j], want, "({i},{j})");
            }
        }
        assert_eq!(s.nnz(), m.nnz() + 2);
        for row in s.outer_iterator() {
            assert!(row.indices().windows(2).all(|w| w[0] < w[1]), "sorted rows");
        }
    }

    /// A product large enough for the parallel blocks (several row blocks,
    /// over `PARALLEL_MIN_FLOPS`) against sprs's product, entry by entry,
    /// with sorted indices.
    #[test]
    fn parallel_blocks_match_sprs() {
        let (r, k, c) = (3 * ROW_BLOCK + 17, 900, 800);
        let mut next = lcg(12345u64);
        let ea: Vec<_> = (0..40 * r)
            .map(|_| (next() % r, next() % k, (next() % 1000) as f64 / 500.0 - 1.0))
            .collect();
        let eb: Vec<_> = (0..20 * k)
            .map(|_| (next() % k, next() % c, (next() % 1000) as f64 / 500.0 - 1.0))
            .collect();
        let (a, b) = (random(r, k, &ea), random(k, c, &eb));
        let ours = matmul(&a, &b);
        let theirs = &a * &b;
        assert!(a.nnz() * 20 > PARALLEL_MIN_FLOPS);
        assert_eq!(ours.shape(), theirs.shape());
        for (i, row) in ours.outer_iterator().enumerate() {
            assert!(
                row.indices().windows(2).all(|w| w[0] < w[1]),
                "row {i} unsorted"
            );
            let other = theirs.outer_view(i).unwrap();
            for (j, &v) in row.iter() {
                let t = other.get(j).copied().unwrap_or(0.0);
                assert!(
                    (v - t).abs() <= 1e-12 * (1.0 + t.abs()),
                    "({i},{j}): {v} vs {t}"
                );
            }
            for (j, &t) in other.iter() {
                let v = row.get(j).copied().unwrap_or(0.0);
                assert!(
                    (v - t).abs() <= 1e-12 * (1.0 + t.abs()),
                    "({i},{j}): {v} vs {t}"
                );
            }
        }
    }

    /// `M X` column by column against a dense reference (each row's terms
    /// summed in stored order: bit for bit), for one column on the rayon
    /// pool (rows ≥ PARALLEL_MIN_ROWS) and for three on one thread, on an
    /// odd row count (a last row without a partner); each column of the
    /// three-column product is bit-identical to the one-column product of
    /// that column.
    #[test]
    fn mul_columns_matches_dense_products() {
        let (rows, cols) = (PARALLEL_MIN_ROWS + 33, 700);
        let mut next = lcg(99u64);
        let entries: Vec<_> = (0..8 * rows)
            .map(|_| {
                (
                    next() % rows,
                    next() % cols,
                    (next() % 1000) as f64 / 250.0 - 2.0,
                )
            })
            .collect();
        let m = random(rows, cols, &entries);
        let x: Vec<f64> = (0..3 * cols)
            .map(|i| ((i * 37) % 101) as f64 - 50.0)
            .collect();
        let mut three = vec![f64::NAN; 3 * rows];
        mul_columns::<3>(&m, &x, &mut three);
        for c in 0..3 {
            let col = &x[c * cols..(c + 1) * cols];
            let mut one = vec![f64::NAN; rows];
            mul_columns::<1>(&m, col, &mut one);
            assert_eq!(one, three[c * rows..(c + 1) * rows], "column {c}");
            let mut dense = vec![0.0; rows];
            for (v, (i, j)) in m.iter() {
                dense[i] += v * col[j];
            }
            // (the reference sums each row's terms in stored order too)
            for (i, (a, b)) in one.iter().zip(&dense).enumerate() {
                assert_eq!(a.to_bits(), b.to_bits(), "({i}, {c}): {a} vs {b}");
            }
        }
    }

    /// The two-pass product (pattern, then values on it) equals the one-pass
    /// product, in the parallel blocks too, and a forced diagonal is there.
    #[test]
    fn pattern_then_values_equal_the_product() {
        let (r, k) = (3 * ROW_BLOCK + 5, 700);
        let mut next = lcg(99u64);
        let e: Vec<_> = (0..30 * r)
            .map(|_| (next() % r, next() % k, (next() % 1000) as f64 / 500.0 - 1.0))
            .collect();
        let j = random(r, k, &e);
        let jt = j.transpose_view().to_csr();
        let m = matmul(&jt, &j);
        for diagonal in [false, true] {
            let (ip, ix) = product_pattern(&jt, &j, diagonal);
            let v = product_values(&jt, &j, &ip, &ix);
            for i in 0..k {
                let row = &ix[ip[i]..ip[i + 1]];
                assert!(row.windows(2).all(|w| w[0] < w[1]), "row {i} unsorted");
                assert_eq!(row.contains(&i), diagonal || m.get(i, i).is_some());
                let mut n = 0;
                for (p, &c) in row.iter().enumerate() {
                    let want = m.get(i, c).copied().unwrap_or(0.0);
                    n += usize::from(m.get(i, c).is_some());
                    let got = v[ip[i] + p];
                    assert!(
                        (got - want).abs() <= 1e-12 * (1.0 + want.abs()),
                        "({i},{c})"
                    );
                }
                assert_eq!(n, m.outer_view(i).map_or(0, |r| r.nnz()), "row {i} pattern");
            }
        }
    }

    proptest! {
        /// Equals sprs's own product (an independent implementation).
        #[test]
        fn matches_sprs(
            (r, k, c) in (1usize..12, 1usize..12, 1usize..12),
            ea in proptest::collection::vec((0usize..100, 0usize..100, -2.0f64..2.0), 0..40),
            eb in proptest::collection::vec((0usize..100, 0usize..100, -2.0f64..2.0), 0..40),
        ) {
            let a = random(r, k, &ea);
            let b = random(k, c, &eb);
            let ours = matmul(&a, &b);
            let theirs = &a * &b;
            prop_assert_eq!(ours.shape(), (r, c));
            for i in 0..r {
                for j in 0..c {
                    let x = ours.get(i, j).copied().unwrap_or(0.0);
                    let y = theirs.get(i, j).copied().unwrap_or(0.0);
                    prop_assert!((x - y).abs() <= 1e-12 * (1.0 + y.abs()), "({},{}): {} vs {}", i, j, x, y);
                }
            }
        }
    }
}
