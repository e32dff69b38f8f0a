//! Supernodal triangular solves `L Lᵀ x = b` for a few right-hand sides.
//!
//! A DEND iteration solves the factor cache's `M = L Lᵀ` for the three
//! coordinates at once (dend.md §4). faer's general solve calls a packed
//! GEMM per supernode, which pays off for wide right-hand sides; with three
//! columns it spends its time packing the factor and in per-call overhead
//! (measured on tube:10000: 11.8 ms per solve for 2.65 M factor nonzeros,
//! ~3.6 GB/s). This module runs the same two sweeps (Rose & Tarjan; the
//! supernodal layout of Ng & Peyton 1993, as faer stores it) with the
//! right-hand sides interleaved four to a row (`[f64; 4]`, the fourth lane
//! padding or a fourth column), so every factor entry is read once per
//! sweep and used in one 4-lane multiply-add: the sweeps are bound by
//! memory bandwidth, not by call overhead.
//!
//! The kernel is compiled twice: for the baseline target and with AVX2+FMA,
//! chosen at run time.

use faer::dyn_stack::MemStack;
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

/// `M X = B` for a supernodal factor with [`solve_llt`], four
/// columns of `b` at a time: gathered into the factor's row order, solved,
/// scattered back.
pub(crate) fn solve_in_place<V: FactorValue>(
    sn: &SymbolicSupernodalCholesky<usize>,
    perm: Option<faer::perm::PermRef<'_, usize>>,
    values: &[V],
    mut b: MatMut<'_, Real>,
    stack: &mut MemStack,
) {
    let n = sn.nrows();
    let (mut x, stack) = stack.make_with::<Lanes>(n, |_| [0.0; 4]);
    let (mut tmp, _) = stack.make_with::<Lanes>(scratch_rows(sn), |_| [0.0; 4]);
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
        solve_llt(sn, values, &mut x, &mut tmp);
        for i in 0..n {
            let xi = x[inv.map_or(i, |v| v[i])];
            for l in 0..k {
                b[(i, c0 + l)] = xi[l];
            }
        }
    }
}

/// Length of the gather/scatter buffer [`solve_llt`] needs: the longest
/// off-diagonal pattern of a supernode.
pub(crate) fn scratch_rows(sym: &SymbolicSupernodalCholesky<usize>) -> usize {
    let cpr = sym.col_ptr_for_row_idx();
    (0..sym.n_supernodes())
        .map(|s| cpr[s + 1] - cpr[s])
        .max()
        .unwrap_or(0)
}

/// Solves `L Lᵀ x = b` in place, where `L` is the supernodal Cholesky factor
/// described by `sym` with values `values` (faer's layout: per supernode a
/// column-major block, diagonal block on top of the off-diagonal rows), `x`
/// holds `b` in the factor's (permuted) row order, four lanes per row, and
/// `tmp` has at least [`scratch_rows`] rows.
pub(crate) fn solve_llt<V: FactorValue>(
    sym: &SymbolicSupernodalCholesky<usize>,
    values: &[V],
    x: &mut [Lanes],
    tmp: &mut [Lanes],
) {
    assert_eq!(values.len(), sym.len_val());
    assert_eq!(x.len(), sym.nrows());
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports the features the function is compiled for.
            unsafe { solve_avx2_fma(sym, values, x, tmp) };
            return;
        }
    }
    sweeps::<V, false>(sym, values, x, tmp);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn solve_avx2_fma<V: FactorValue>(
    sym: &SymbolicSupernodalCholesky<usize>,
    values: &[V],
    x: &mut [Lanes],
    tmp: &mut [Lanes],
) {
    sweeps::<V, true>(sym, values, x, tmp);
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

#[inline(always)]
fn sweeps<V: FactorValue, const FMA: bool>(
    sym: &SymbolicSupernodalCholesky<usize>,
    values: &[V],
    x: &mut [Lanes],
    tmp: &mut [Lanes],
) {
    let ns = sym.n_supernodes();
    let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
    let (cpr, cpv, row_idx) = (
        sym.col_ptr_for_row_idx(),
        sym.col_ptr_for_val(),
        sym.row_idx(),
    );
    // Forward: L y = b, supernode by supernode in elimination order.
    for s in 0..ns {
        let (c0, w) = (begin[s], end[s] - begin[s]);
        let pattern = &row_idx[cpr[s]..cpr[s + 1]];
        let h = w + pattern.len();
        let block = &values[cpv[s]..cpv[s + 1]];
        let t = &mut tmp[..pattern.len()];
        t.fill([0.0; 4]);
        let xs = &mut x[c0..c0 + w];
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
        for (ti, &r) in t.iter().zip(pattern) {
            let xr = &mut x[r];
            for k in 0..4 {
                xr[k] -= ti[k];
            }
        }
    }
    // Backward: Lᵀ x = y, in reverse elimination order.
    for s in (0..ns).rev() {
        let (c0, w) = (begin[s], end[s] - begin[s]);
        let pattern = &row_idx[cpr[s]..cpr[s + 1]];
        let h = w + pattern.len();
        let block = &values[cpv[s]..cpv[s + 1]];
        let t = &mut tmp[..pattern.len()];
        for (ti, &r) in t.iter_mut().zip(pattern) {
            *ti = x[r];
        }
        let xs = &mut x[c0..c0 + w];
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
mod tests {
    use super::*;
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
        let mut values = vec![0.0; sym.len_val()];
        let mut mem =
            MemBuffer::new(sym.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()));
        sym.factorize_numeric_llt::<f64>(
            &mut values,
            m.as_ref(),
            Side::Lower,
            Default::default(),
            Par::Seq,
            MemStack::new(&mut mem),
            Default::default(),
        )
        .unwrap();
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
        for k in 1..=7 {
            let b = rhs(n, k);
            let mut ours = b.clone();
            let mut mem = MemBuffer::new(faer::dyn_stack::StackReq::all_of(&[
                faer::dyn_stack::StackReq::new::<Lanes>(n),
                faer::dyn_stack::StackReq::new::<Lanes>(scratch_rows(sn)),
            ]));
            solve_in_place(
                sn,
                sym.perm(),
                &values,
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
        let mut plain = gather();
        sweeps::<f64, false>(sn, &values, &mut plain, &mut tmp);
        let mut dispatched = gather();
        solve_llt(sn, &values, &mut dispatched, &mut tmp);
        let scale = plain.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = plain
            .iter()
            .flatten()
            .zip(dispatched.iter().flatten())
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(diff < 1e-12 * scale, "diff {diff}");
    }

    #[test]
    fn a_single_precision_factor_halves_the_values_and_keeps_the_deformation() {
        use crate::deform::cg::tests::{edit, grid, residual, solve};
        use crate::deform::{
            Deformer, Factor, FactorPrecision, Params, Rest, SolveOptions, SolverChoice,
        };
        use std::sync::Arc;
        let k = 40;
        let mesh = grid(k);
        let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
        let c = edit(&mesh, k);
        let params = Params::default();
        let build = |precision| {
            let opts = SolveOptions {
                solver: SolverChoice::Direct,
                precision,
                ..SolveOptions::default()
            };
            Factor::build_with(&rest, &params, &c, &opts).unwrap()
        };
        let (f64_, f32_) = (
            build(FactorPrecision::Double),
            build(FactorPrecision::Single),
        );
        assert!(f32_.is_supernodal());
        assert_eq!(f32_.factor_nnz(), f64_.factor_nnz());
        // values 8 -> 4 bytes; the row indices stay
        assert!(f32_.factor_bytes() < f64_.factor_bytes());
        assert!(f64_.factor_bytes() - f32_.factor_bytes() == 4 * f64_.factor_nnz());
        let n = f64_.num_unknowns();
        let b: Vec<f64> = (0..3 * n)
            .map(|i| ((i * 7919 % 1013) as f64 / 1013.0) - 0.5)
            .collect();
        let (x64, x32) = (solve(&f64_, &b), solve(&f32_, &b));
        assert!(residual(&f64_, &x64, &b) < 1e-9);
        // the error the rounding adds: small, but not zero
        let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
        let err: Vec<f64> = x64.iter().zip(&x32).map(|(a, b)| a - b).collect();
        let rel = norm(&err) / norm(&x64);
        assert!(
            rel > 0.0 && rel < 1e-3,
            "single-precision relative error {rel}"
        );
        // the fixed point does not depend on the factor's precision
        let pose = |f: &Factor| {
            let mut d = Deformer::new(rest.clone(), params);
            let r = d.step(f, &c, 200).unwrap();
            assert!(r.converged, "{r:?}");
            d.pose().to_vec()
        };
        let (p64, p32) = (pose(&f64_), pose(&f32_));
        let diff = p64
            .iter()
            .zip(&p32)
            .flat_map(|(a, b)| (0..3).map(move |i| (a[i] - b[i]).abs()))
            .fold(0.0f64, f64::max);
        assert!(diff < 1e-3 * mesh.diagonal(), "poses differ by {diff}");
    }
}
