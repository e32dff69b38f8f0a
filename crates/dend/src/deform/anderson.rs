//! Anderson acceleration of the DEND fixed-point iteration (type II, windowed),
//! as used for local–global geometry solvers by Peng, Deng, Zhang & Liu,
//! "Anderson acceleration for geometry optimization and physics simulation",
//! ACM TOG 37(4), 2018. The caller keeps it safe: an accelerated iterate is
//! accepted only if it lowers the objective, otherwise the plain step is
//! taken (the least-squares iteration also resets the history then; the
//! elastic one keeps it, as Peng et al. do: its pairs are exact iterates of
//! the map).

use nalgebra::{DMatrix, DVector};

use crate::mesh::Real;

/// Windowed Anderson history for vectors of a fixed length.
///
/// The residuals' differences are stored interleaved, `window` values per
/// vector entry (`df[i * window + q]` is entry `i` of pair `q`), so that a
/// step reads them as one stream: the step is one pass over the vectors
/// for the new pair, its row of the Gram matrix and `ΔFᵀ f`, and one over
/// the images' differences (pair after pair, `dg[q * len + i]`: the first
/// pass writes one pair of them) for the extrapolation (on the camel's 9770 vertices the history
/// held in separate vectors, read and written in several passes, was
/// ~6 % of an elastic iteration). The sums run over the entries in order,
/// as they did, so the steps are the same to the last bit.
#[derive(Debug, Default)]
pub struct Anderson {
    window: usize,
    /// Vector length.
    len: usize,
    /// Differences of residuals `f = G(x) - x`, interleaved, and of images
    /// `g = G(x)`, pair after pair (`len × window` each, allocated at the
    /// first pair); the first `used` pairs are live. Buffers are
    /// kept across resets, so a reset and refill allocate nothing.
    df: Vec<Real>,
    dg: Vec<Real>,
    /// `M f` of the previous step with the metric `M` of
    /// [`Anderson::step_in_metric`] (empty without one).
    prev_mf: Vec<Real>,
    used: usize,
    prev_f: Vec<Real>,
    prev_g: Vec<Real>,
    has_prev: bool,
    next: usize,
    /// `ΔFᵀΔF` of the live pairs, `window × window`, row-major.
    gram: Vec<Real>,
}

/// The longest history [`Anderson`] keeps (`Params::validate` bounds the
/// window by it).
pub const MAX_WINDOW: usize = 50;

impl Anderson {
    /// A history of `window` pairs for vectors of length `len`.
    pub fn new(window: usize, len: usize) -> Self {
        let window = window.min(MAX_WINDOW);
        Anderson {
            window,
            len,
            df: Vec::new(),
            dg: Vec::new(),
            prev_mf: Vec::new(),
            used: 0,
            prev_f: vec![0.0; len],
            prev_g: vec![0.0; len],
            has_prev: false,
            next: 0,
            gram: vec![0.0; window * window],
        }
    }

    /// Forgets every stored pair.
    pub fn reset(&mut self) {
        self.used = 0;
        self.has_prev = false;
        self.next = 0;
    }

    /// Records the iterate `x` and its fixed-point residual `f = G(x) - x`,
    /// then writes the extrapolated next iterate into `out`; returns whether
    /// any history was used (otherwise `out = x + f`, the plain step).
    ///
    /// The Gram matrix `ΔFᵀΔF` is kept between steps: a step computes only
    /// the new pair's row of it and `ΔFᵀ f`, in one pass over the history.
    pub fn step(&mut self, x: &[Real], f: &[Real], out: &mut [Real]) -> bool {
        self.step_in_metric(x, f, None, out)
    }

    /// [`Anderson::step`] with the least squares `θ = argmin |f − ΔF θ|_M`
    /// in the norm of a symmetric positive definite `M` (given as
    /// `mf = M f`): with `M` the global step's matrix, the extrapolation
    /// weighs the residual as the energy does (Peng et al. 2018, §4).
    pub fn step_in_metric(
        &mut self,
        x: &[Real],
        f: &[Real],
        mf: Option<&[Real]>,
        out: &mut [Real],
    ) -> bool {
        let n = self.len;
        assert!(x.len() == n && f.len() == n && out.len() == n);
        assert!(mf.is_none_or(|mf| mf.len() == n));
        let w = self.window;
        if !(self.has_prev && w > 0) {
            // no pair to add (new or reset history): the plain step
            for i in 0..n {
                out[i] = x[i] + f[i]; // g = G(x)
            }
            self.keep_previous(f, out, mf);
            self.has_prev = true;
            return false;
        }
        let k = if self.used < w {
            self.used += 1;
            self.used - 1
        } else {
            self.next % w
        };
        self.next = (k + 1) % w;
        if self.df.len() != n * w {
            self.df = vec![0.0; n * w];
            self.dg = vec![0.0; n * w];
        }
        if mf.is_some() && self.prev_mf.len() != n {
            // (a metric after steps without one: the previous M f reads
            // as 0)
            self.prev_mf = vec![0.0; n];
        }
        let m = self.used;
        // one pass: g = G(x), the new pair, the previous step's vectors
        // replaced, and the new pair's row of the Gram matrix and b
        // (`Anderson::new_pair`), with the sums held in registers for the
        // usual windows
        let (row, b) = match m {
            1 => self.new_pair::<1>((x, f, mf), k, m, out),
            2 => self.new_pair::<2>((x, f, mf), k, m, out),
            3 => self.new_pair::<3>((x, f, mf), k, m, out),
            4 => self.new_pair::<4>((x, f, mf), k, m, out),
            5 => self.new_pair::<5>((x, f, mf), k, m, out),
            6 => self.new_pair::<6>((x, f, mf), k, m, out),
            7 => self.new_pair::<7>((x, f, mf), k, m, out),
            8 => self.new_pair::<8>((x, f, mf), k, m, out),
            _ => self.new_pair::<MAX_WINDOW>((x, f, mf), k, m, out),
        };
        for (q, &v) in row[..m].iter().enumerate() {
            self.gram[k * w + q] = v;
            self.gram[q * w + k] = v;
        }
        // θ = argmin |f - ΔF θ|, through the regularised normal equations.
        let mut a = DMatrix::<Real>::from_fn(m, m, |p, q| self.gram[p * w + q]);
        let trace: Real = (0..m).map(|p| a[(p, p)]).sum();
        for p in 0..m {
            a[(p, p)] += 1e-10 * trace.max(1e-300);
        }
        let b = DVector::<Real>::from_column_slice(&b[..m]);
        let Some(theta) = a.cholesky().map(|c| c.solve(&b)) else {
            return false;
        };
        if theta.iter().any(|t| !t.is_finite()) {
            return false;
        }
        for (i, o) in out.iter_mut().enumerate() {
            let mut acc = 0.0;
            for p in 0..m {
                acc += theta[p] * self.dg[p * n + i];
            }
            *o -= acc;
        }
        true
    }

    /// One pass over the vectors for the new pair `k` of `m` live ones:
    /// `out = g = G(x)`, `Δf_k`, `Δg_k`, the previous `f`, `g` (and `M f`)
    /// replaced, and the new pair's row of the Gram matrix and `b`:
    /// `ΔFᵀ M Δf_k` and `ΔFᵀ M f` with a metric (`M` symmetric:
    /// `(M Δf_k)ᵀ Δf_q`), `ΔFᵀ Δf_k` and `ΔFᵀ f` without. `M` is `m` (its
    /// sums then stay in registers), or [`MAX_WINDOW`] for any `m`; each sum
    /// runs over the entries in order either way.
    #[inline(always)]
    fn new_pair<const M: usize>(
        &mut self,
        (x, f, mf): (&[Real], &[Real], Option<&[Real]>),
        k: usize,
        m: usize,
        out: &mut [Real],
    ) -> ([Real; MAX_WINDOW], [Real; MAX_WINDOW]) {
        let (n, w) = (self.len, self.window);
        let live = if M == MAX_WINDOW { m } else { M };
        debug_assert!(live == m && m <= w && k < m);
        let mut row = [0.0; M];
        let mut b = [0.0; M];
        for i in 0..n {
            let (fi, gi) = (f[i], x[i] + f[i]);
            out[i] = gi;
            let dfi = &mut self.df[i * w..i * w + w];
            dfi[k] = fi - self.prev_f[i];
            self.dg[k * n + i] = gi - self.prev_g[i];
            self.prev_f[i] = fi;
            self.prev_g[i] = gi;
            let (dki, ri) = match mf {
                Some(mf) => {
                    let d = mf[i] - self.prev_mf[i];
                    self.prev_mf[i] = mf[i];
                    (d, mf[i])
                }
                None => (dfi[k], fi),
            };
            for q in 0..live {
                let d = dfi[q];
                row[q] += dki * d;
                b[q] += d * ri;
            }
        }
        let mut wide = ([0.0; MAX_WINDOW], [0.0; MAX_WINDOW]);
        wide.0[..M].copy_from_slice(&row);
        wide.1[..M].copy_from_slice(&b);
        wide
    }

    /// Keeps `f`, `g` and `M f` as the previous step's.
    fn keep_previous(&mut self, f: &[Real], g: &[Real], mf: Option<&[Real]>) {
        if let Some(mf) = mf {
            self.prev_mf.clear();
            self.prev_mf.extend_from_slice(mf);
        }
        self.prev_f.copy_from_slice(f);
        self.prev_g.copy_from_slice(g);
    }

    /// Entry `i` of the live pair `q`'s `Δf` (tests).
    #[cfg(test)]
    fn df_entry(&self, q: usize, i: usize) -> Real {
        self.df[i * self.window + q]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a linear contraction `G(x) = M x + c`, Anderson with a window of at
    /// least the dimension converges far faster than the plain iteration.
    #[test]
    fn accelerates_a_slow_linear_contraction() {
        let m = [[0.95, 0.02, 0.0], [0.0, 0.9, 0.03], [0.01, 0.0, 0.97]];
        let c = [1.0, -2.0, 0.5];
        let g = |x: &[f64]| -> Vec<f64> {
            (0..3)
                .map(|i| (0..3).map(|j| m[i][j] * x[j]).sum::<f64>() + c[i])
                .collect()
        };
        let solve_iters = |window: usize| {
            let mut aa = Anderson::new(window, 3);
            let mut x = vec![0.0; 3];
            let mut out = vec![0.0; 3];
            for k in 0..2000 {
                let gx = g(&x);
                let f: Vec<f64> = gx.iter().zip(&x).map(|(a, b)| a - b).collect();
                if f.iter().map(|v| v.abs()).fold(0.0, f64::max) < 1e-10 {
                    return k;
                }
                aa.step(&x, &f, &mut out);
                x.copy_from_slice(&out);
            }
            2000
        };
        // a reset history behaves as a new one (its buffers are reused)
        let mut used = Anderson::new(3, 3);
        let mut fresh = Anderson::new(3, 3);
        let (mut o1, mut o2) = (vec![0.0; 3], vec![0.0; 3]);
        for k in 0..5 {
            let x = [k as f64, 1.0, -1.0];
            used.step(&x, &g(&x), &mut o1);
        }
        used.reset();
        for k in 0..4 {
            let x = [0.3 * k as f64, 2.0 - k as f64, 0.5];
            let f: Vec<f64> = g(&x).iter().zip(&x).map(|(a, b)| a - b).collect();
            assert_eq!(used.step(&x, &f, &mut o1), fresh.step(&x, &f, &mut o2));
            assert_eq!(o1, o2);
        }
        let plain = solve_iters(0);
        let fast = solve_iters(4);
        assert!(plain > 200, "plain iteration should be slow: {plain}");
        assert!(fast < 20, "Anderson should converge in a few steps: {fast}");
    }

    /// The Gram matrix kept between steps equals `ΔFᵀΔF` recomputed from
    /// the live pairs, through wrap-arounds of the window and a reset.
    #[test]
    fn kept_gram_matrix_matches_a_recomputation() {
        let n = 7;
        let mut aa = Anderson::new(3, n);
        let mut out = vec![0.0; n];
        for step in 0..11 {
            if step == 6 {
                aa.reset();
            }
            let x: Vec<f64> = (0..n)
                .map(|i| ((i * 31 + step * 17) % 13) as f64 * 0.1)
                .collect();
            let f: Vec<f64> = (0..n)
                .map(|i| ((i * 7 + step * step) % 11) as f64 * 0.05 - 0.2)
                .collect();
            aa.step(&x, &f, &mut out);
            let (m, w) = (aa.used, aa.window);
            for p in 0..m {
                for q in 0..m {
                    let e: f64 = (0..n).map(|i| aa.df_entry(p, i) * aa.df_entry(q, i)).sum();
                    let got = aa.gram[p * w + q];
                    assert!(
                        (got - e).abs() <= 1e-12 * (1.0 + e.abs()),
                        "step {step} ({p},{q})"
                    );
                }
            }
        }
    }

    /// In the metric of an SPD `M`, the extrapolation is
    /// `g − ΔG θ` with `θ` from the regularised normal equations
    /// `(ΔFᵀ M ΔF + 1e-10 tr I) θ = ΔFᵀ M f` of the last `window` pairs,
    /// recomputed here from the whole sequence of iterates, for windows
    /// below and above the specialised sizes (9 > 8), through the window's
    /// wrap-around and a reset.
    #[test]
    fn extrapolation_solves_the_normal_equations_of_the_window() {
        let n = 13;
        let mut state = 7u64;
        let mut rnd = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        // M: tridiagonal (−1, 3, −1), SPD
        let metric = |v: &[f64]| -> Vec<f64> {
            (0..v.len())
                .map(|i| {
                    let l = if i > 0 { v[i - 1] } else { 0.0 };
                    let r = v.get(i + 1).copied().unwrap_or(0.0);
                    3.0 * v[i] - l - r
                })
                .collect()
        };
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x - y).collect::<Vec<_>>();
        for window in [3, 5, 9] {
            let mut aa = Anderson::new(window, n);
            let mut out = vec![0.0; n];
            // (f, g, M f) since the last reset
            let mut seq: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> = Vec::new();
            for step in 0..25 {
                if step == 14 {
                    aa.reset();
                    seq.clear();
                }
                let x: Vec<f64> = (0..n).map(|_| rnd()).collect();
                let f: Vec<f64> = (0..n).map(|_| 0.3 * rnd()).collect();
                let mf = metric(&f);
                let g: Vec<f64> = x.iter().zip(&f).map(|(a, b)| a + b).collect();
                let used = aa.step_in_metric(&x, &f, Some(&mf), &mut out);
                seq.push((f.clone(), g.clone(), mf.clone()));
                let pairs: Vec<_> = seq
                    .windows(2)
                    .map(|p| {
                        (
                            diff(&p[1].0, &p[0].0),
                            diff(&p[1].1, &p[0].1),
                            diff(&p[1].2, &p[0].2),
                        )
                    })
                    .collect();
                let live = &pairs[pairs.len().saturating_sub(window)..];
                assert_eq!(used, !live.is_empty(), "window {window} step {step}");
                let want = if live.is_empty() {
                    g
                } else {
                    let m = live.len();
                    let mut a = DMatrix::from_fn(m, m, |p, q| dot(&live[p].2, &live[q].0));
                    let trace: f64 = (0..m).map(|p| a[(p, p)]).sum();
                    for p in 0..m {
                        a[(p, p)] += 1e-10 * trace;
                    }
                    let b = DVector::from_fn(m, |p, _| dot(&live[p].0, &mf));
                    let theta = a.cholesky().expect("SPD").solve(&b);
                    (0..n)
                        .map(|i| g[i] - (0..m).map(|p| theta[p] * live[p].1[i]).sum::<f64>())
                        .collect()
                };
                for i in 0..n {
                    assert!(
                        (out[i] - want[i]).abs() <= 1e-10 * (1.0 + want[i].abs()),
                        "window {window} step {step} entry {i}: {} against {}",
                        out[i],
                        want[i]
                    );
                }
            }
        }
    }
}
