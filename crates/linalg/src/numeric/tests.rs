use super::*;
use crate::test_util::faer_values;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMat, Triplet};
use faer::Side;

/// An SPD matrix on a `k × k` grid with a stencil of radius `r` (radius 4:
/// the reach of the 8th-order DEND normal matrix), pseudo-random couplings
/// of both signs, strictly diagonally dominant, both triangles stored.
fn spd(k: usize, radius: i64) -> SparseColMat<usize, f64> {
    let mut t = Vec::new();
    let n = k * k;
    let mut diag = vec![1.0; n];
    for c in 0..n {
        let (x, y) = ((c % k) as i64, (c / k) as i64);
        for dy in -radius..=radius {
            for dx in -radius..=radius {
                let (u, v) = (x + dx, y + dy);
                if dx * dx + dy * dy > radius * radius {
                    continue;
                }
                let r = (v * k as i64 + u) as usize;
                if (0..k as i64).contains(&u) && (0..k as i64).contains(&v) && r < c {
                    let w = ((r * 31 + c * 17) % 97) as f64 / 97.0 - 0.3;
                    t.push(Triplet::new(r, c, w));
                    t.push(Triplet::new(c, r, w));
                    diag[r] += w.abs();
                    diag[c] += w.abs();
                }
            }
        }
    }
    t.extend(diag.iter().enumerate().map(|(i, &d)| Triplet::new(i, i, d)));
    SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
}

fn symbolic(m: &SparseColMat<usize, f64>) -> SymbolicCholesky<usize> {
    let params = CholeskySymbolicParams {
        supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
        ..Default::default()
    };
    factorize_symbolic_cholesky(m.symbolic(), Side::Lower, SymmetricOrdering::Amd, params).unwrap()
}

fn ours(
    sym: &SymbolicCholesky<usize>,
    m: &SparseColMat<usize, f64>,
    parallel: bool,
    kernels: Kernels,
) -> Result<Vec<f64>, NonPositivePivot> {
    let SymbolicCholeskyRaw::Supernodal(sn) = sym.raw() else {
        panic!("not supernodal")
    };
    let plan = NumericPlan::new(sn);
    let mut values = vec![f64::NAN; sn.len_val()];
    let perm = sym.perm().map(|p| p.arrays());
    let a = Permuted {
        col_ptr: m.symbolic().col_ptr(),
        row_idx: m.symbolic().row_idx(),
        values: m.val(),
        perm,
    };
    factorize_impl(sn, &plan, a, &mut values, parallel, kernels).map(|_| values)
}

fn two_threads<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap()
        .install(f)
}

fn max_rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

#[test]
fn values_equal_faers_sequential_parallel_and_every_kernel() {
    // radius 4 on 60 × 60: top supernodes several hundred columns wide,
    // so the wide path (pool inside a supernode) runs too
    for (k, radius) in [(12, 2), (35, 3), (60, 4)] {
        let m = spd(k, radius);
        let sym = symbolic(&m);
        if let SymbolicCholeskyRaw::Supernodal(sn) = sym.raw() {
            if k == 60 {
                assert!(NumericPlan::new(sn).max_width >= WIDE, "no wide supernode");
            }
        }
        let reference = faer_values(&sym, &m).unwrap();
        for parallel in [false, true] {
            for kernels in Kernels::available() {
                let v = two_threads(|| ours(&sym, &m, parallel, kernels)).unwrap();
                let d = max_rel_diff(&v, &reference);
                assert!(
                    d < 1e-12,
                    "k {k} radius {radius} parallel {parallel} {kernels:?}: {d:e}"
                );
            }
        }
    }
}

#[test]
fn the_plan_covers_every_supernode_once_children_first() {
    let m = spd(40, 3);
    let sym = symbolic(&m);
    let SymbolicCholeskyRaw::Supernodal(sn) = sym.raw() else {
        panic!("not supernodal")
    };
    let plan = NumericPlan::new(sn);
    let ns = sn.n_supernodes();
    let mut seen = vec![false; ns];
    for (i, &s) in plan.post.iter().enumerate() {
        assert!(!seen[s]);
        seen[s] = true;
        assert_eq!(plan.pos[s], i);
        for &c in plan.children(s) {
            assert!(plan.pos[c] < i, "child after parent");
            assert!(plan.first[c] >= plan.first[s]);
        }
        // every updating descendant lies in the subtree
        for &d in &plan.upd[plan.upd_ptr[s]..plan.upd_ptr[s + 1]] {
            assert!(plan.first[s] <= plan.pos[d] && plan.pos[d] < i);
        }
    }
    assert!(seen.iter().all(|&b| b));
    let total: f64 = plan.roots.iter().map(|&r| plan.subtree_work[r]).sum();
    assert!((total - plan.total_work).abs() <= 1e-9 * total && total > 0.0);
}

#[test]
fn an_indefinite_matrix_fails_as_faer_does() {
    let mut m = spd(30, 3);
    // make one diagonal entry strongly negative
    let n = m.nrows();
    let target = n / 2;
    let (cp, ri) = (
        m.symbolic().col_ptr().to_vec(),
        m.symbolic().row_idx().to_vec(),
    );
    let vals = m.val_mut();
    for p in cp[target]..cp[target + 1] {
        if ri[p] == target {
            vals[p] = -1e3;
        }
    }
    let sym = symbolic(&m);
    let faer_pivot = faer_values(&sym, &m).unwrap_err();
    for parallel in [false, true] {
        let e = two_threads(|| ours(&sym, &m, parallel, Kernels::detect())).unwrap_err();
        // the one bad pivot is where faer met it
        assert_eq!(e.0, faer_pivot, "parallel {parallel}");
    }
}

/// A strictly diagonally dominant SPD matrix on a random graph of `n`
/// vertices: `edges` as (row, column, weight) taken modulo `n`, and
/// every vertex of a band `i ± reach` coupled too (supernodes of several
/// widths, and a forest when `reach` is 0 and the edges are few).
fn random_spd(n: usize, reach: usize, edges: &[(usize, usize, f64)]) -> SparseColMat<usize, f64> {
    let mut t = Vec::new();
    let mut diag = vec![1.0; n];
    let mut push = |r: usize, c: usize, w: f64, diag: &mut Vec<f64>| {
        t.push(Triplet::new(r, c, w));
        t.push(Triplet::new(c, r, w));
        diag[r] += w.abs();
        diag[c] += w.abs();
    };
    for i in 0..n {
        for j in i + 1..(i + 1 + reach).min(n) {
            push(i, j, 0.25 - ((i * 7 + j * 3) % 11) as f64 / 22.0, &mut diag);
        }
    }
    for &(a, b, w) in edges {
        let (r, c) = (a % n, b % n);
        if r != c {
            push(r, c, w, &mut diag);
        }
    }
    t.extend(diag.iter().enumerate().map(|(i, &d)| Triplet::new(i, i, d)));
    SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]

    /// Irregular elimination trees (random graphs, forests, bands): the
    /// values equal faer's for every kernel, sequential and parallel.
    #[test]
    fn random_patterns_factor_as_faer_does(
        n in 2usize..400,
        reach in 0usize..12,
        edges in proptest::collection::vec((0usize..400, 0usize..400, -1.0f64..1.0), 0..1500),
    ) {
        let m = random_spd(n, reach, &edges);
        let sym = symbolic(&m);
        let reference = faer_values(&sym, &m).unwrap();
        for parallel in [false, true] {
            for kernels in Kernels::available() {
                let v = two_threads(|| ours(&sym, &m, parallel, kernels)).unwrap();
                let d = max_rel_diff(&v, &reference);
                proptest::prop_assert!(d < 1e-12, "parallel {} {:?}: {:e}", parallel, kernels, d);
            }
        }
    }
}

/// A plan made for one matrix pattern ([`NumericPlan::for_matrix`])
/// gathers `M`'s entries by its precomputed list: the values are those of
/// the plain plan to the bit, sequential and parallel, for matrices of
/// that pattern with other values.
#[test]
fn a_plan_for_a_pattern_gives_the_plain_plans_values() {
    let m = spd(35, 3);
    let sym = symbolic(&m);
    let SymbolicCholeskyRaw::Supernodal(sn) = sym.raw() else {
        panic!("not supernodal")
    };
    let perm = sym.perm().map(|p| p.arrays());
    fn permuted<'a>(
        m: &'a SparseColMat<usize, f64>,
        values: &'a [f64],
        perm: Option<(&'a [usize], &'a [usize])>,
    ) -> Permuted<'a> {
        Permuted {
            col_ptr: m.symbolic().col_ptr(),
            row_idx: m.symbolic().row_idx(),
            values,
            perm,
        }
    }
    let for_matrix = NumericPlan::for_matrix(sn, permuted(&m, m.val(), perm));
    let plain = NumericPlan::new(sn);
    for scale in [1.0, 0.5, 3.0] {
        let vals: Vec<f64> = m
            .val()
            .iter()
            .enumerate()
            .map(|(p, v)| v * (scale + (p % 7) as f64 * 1e-3 * (scale - 1.0)))
            .collect();
        for parallel in [false, true] {
            let run = |plan: &NumericPlan| {
                let mut values = vec![f64::NAN; sn.len_val()];
                two_threads(|| {
                    factorize(sn, plan, permuted(&m, &vals, perm), &mut values, parallel)
                        .map(|_| values)
                })
            };
            let (a, b) = (run(&for_matrix), run(&plain));
            assert!(a == b, "scale {scale} parallel {parallel}");
        }
    }
}
