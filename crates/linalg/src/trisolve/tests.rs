use super::sweep::{backward_impl, forward_impl};
use super::*;
use crate::test_util::faer_values;
use faer::dyn_stack::MemBuffer;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky,
    SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Conj, Mat, Par, Side};

/// An SPD matrix on a `k × k` grid with a 2-ring stencil (the shape of
/// the DEND normal matrix), pseudo-random positive couplings, strictly
/// diagonally dominant.
fn spd(k: usize) -> SparseColMat<usize, f64> {
    let mut t = Vec::new();
    let n = k * k;
    let mut diag = vec![1.0; n];
    for c in 0..n {
        let (x, y) = ((c % k) as i64, (c / k) as i64);
        for dy in -2i64..=2 {
            for dx in -2i64..=2 {
                let (u, v) = (x + dx, y + dy);
                let r = (v * k as i64 + u) as usize;
                if (0..k as i64).contains(&u) && (0..k as i64).contains(&v) && r < c {
                    let w = 0.1 + ((r * 31 + c * 17) % 97) as f64 / 97.0;
                    t.push(Triplet::new(r, c, -w));
                    t.push(Triplet::new(c, r, -w));
                    diag[r] += w;
                    diag[c] += w;
                }
            }
        }
    }
    t.extend(diag.iter().enumerate().map(|(i, &d)| Triplet::new(i, i, d)));
    SparseColMat::try_new_from_triplets(n, n, &t).unwrap()
}

fn factor(m: &SparseColMat<usize, f64>) -> (SymbolicCholesky<usize>, Vec<f64>) {
    let params = CholeskySymbolicParams {
        supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
        ..Default::default()
    };
    let sym =
        factorize_symbolic_cholesky(m.symbolic(), Side::Lower, SymmetricOrdering::Amd, params)
            .unwrap();
    let values = faer_values(&sym, m).unwrap();
    (sym, values)
}

fn rhs(n: usize, k: usize) -> Mat<f64> {
    Mat::from_fn(n, k, |i, j| {
        (((i * 7919 + j * 104729) % 1013) as f64 / 1013.0) - 0.5
    })
}

fn max_abs_diff(a: &Mat<f64>, b: &Mat<f64>) -> f64 {
    let mut d: f64 = 0.0;
    for j in 0..a.ncols() {
        for i in 0..a.nrows() {
            d = d.max((a[(i, j)] - b[(i, j)]).abs());
        }
    }
    d
}

#[test]
fn matches_faers_solve_and_m_for_one_to_seven_columns() {
    let m = spd(30);
    let n = m.nrows();
    let (sym, values) = factor(&m);
    let SymbolicCholeskyRaw::Supernodal(sn) = sym.raw() else {
        panic!("forced supernodal")
    };
    assert!(sym.perm().is_some());
    // a two-thread plan even at this size, to test it
    let plan = SolvePlan::with_min_values(sn, 0).expect("the grid's tree splits");
    // and with the top's supernodes swept on two threads each, over
    // several panels
    let dense = SolvePlan::with_min_values(sn, 0)
        .unwrap()
        .with_dense_min_width(4);
    let widths = dense.dense_widths(sn);
    assert!(
        widths.iter().any(|&w| w > 2 * dense::PANEL),
        "top widths {widths:?}"
    );
    for (k, plan) in (1..=7).flat_map(|k| [(k, None), (k, Some(&plan)), (k, Some(&dense))]) {
        let b = rhs(n, k);
        let mut ours = b.clone();
        let mut mem = MemBuffer::new(scratch(sn, plan));
        solve_in_place(
            sn,
            sym.perm(),
            &values,
            plan,
            ours.as_mut(),
            MemStack::new(&mut mem),
        );
        let mut theirs = b.clone();
        let mut mem2 = MemBuffer::new(sym.solve_in_place_scratch::<f64>(k, Par::Seq));
        LltRef::new(&sym, &values).solve_in_place_with_conj(
            Conj::No,
            theirs.as_mut(),
            Par::Seq,
            MemStack::new(&mut mem2),
        );
        let scale = theirs.norm_max();
        assert!(max_abs_diff(&ours, &theirs) < 1e-12 * scale, "k = {k}");
        // and independently: M x = b
        let mx = &m * &ours;
        assert!(max_abs_diff(&mx, &b) < 1e-10 * b.norm_max(), "k = {k}");
    }
}

#[test]
fn baseline_and_fused_kernels_agree() {
    let m = spd(24);
    let n = m.nrows();
    let (sym, values) = factor(&m);
    let SymbolicCholeskyRaw::Supernodal(sn) = sym.raw() else {
        panic!("forced supernodal")
    };
    let b = rhs(n, 4);
    let perm = sym.perm().unwrap().arrays().0.to_vec();
    let gather = || -> Vec<Lanes> {
        (0..n)
            .map(|i| [0, 1, 2, 3].map(|j| b[(perm[i], j)]))
            .collect()
    };
    let mut tmp = vec![[0.0; 4]; scratch_rows(sn)];
    let f = Supernodal {
        sym: sn,
        values: &values,
    };
    let all = 0..sn.n_supernodes();
    let mut plain = gather();
    let rows = Rows::new(&mut plain);
    forward_impl::<f64, false>(f, all.clone(), rows, &mut tmp, Scatter::Direct);
    backward_impl::<f64, false>(f, all.clone().rev(), rows, &mut tmp);
    let mut dispatched = gather();
    let rows = Rows::new(&mut dispatched);
    forward(f, all.clone(), rows, &mut tmp, Scatter::Direct);
    backward(f, all.rev(), rows, &mut tmp);
    let scale = plain.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let diff = plain
        .iter()
        .flatten()
        .zip(dispatched.iter().flatten())
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    assert!(diff < 1e-12 * scale, "diff {diff}");
}
