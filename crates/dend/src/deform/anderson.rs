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
#[derive(Debug, Default)]
pub struct Anderson {
    window: usize,
    /// Differences of residuals `f = G(x) - x` and of images `g = G(x)`;
    /// the first `used` are live. Buffers are kept across resets, so a
    /// reset and refill allocate nothing.
    df: Vec<Vec<Real>>,
    dg: Vec<Vec<Real>>,
    /// `M ΔF` for the metric `M` of [`Anderson::step_in_metric`] (empty
    /// without one).
    mdf: Vec<Vec<Real>>,
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
            df: Vec::with_capacity(window),
            dg: Vec::with_capacity(window),
            mdf: Vec::with_capacity(window),
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
        let n = x.len();
        for i in 0..n {
            out[i] = x[i] + f[i]; // g = G(x)
        }
        let mut newest = None;
        if self.has_prev && self.window > 0 {
            let k = if self.used < self.window {
                if self.df.len() == self.used {
                    self.df.push(vec![0.0; n]);
                    self.dg.push(vec![0.0; n]);
                }
                if mf.is_some() && self.mdf.len() <= self.used {
                    self.mdf.resize(self.used + 1, vec![0.0; n]);
                }
                self.used += 1;
                self.used - 1
            } else {
                self.next % self.window
            };
            self.next = (k + 1) % self.window.max(1);
            for i in 0..n {
                self.df[k][i] = f[i] - self.prev_f[i];
                self.dg[k][i] = out[i] - self.prev_g[i];
            }
            if let Some(mf) = mf {
                for ((d, &a), &b) in self.mdf[k].iter_mut().zip(mf).zip(&self.prev_mf) {
                    *d = a - b;
                }
            }
            newest = Some(k);
        }
        if let Some(mf) = mf {
            self.prev_mf.clear();
            self.prev_mf.extend_from_slice(mf);
        }
        self.prev_f.copy_from_slice(f);
        self.prev_g.copy_from_slice(out);
        self.has_prev = true;
        // no pair was added only with an empty history (new or reset)
        let Some(k) = newest else {
            return false;
        };
        let (m, w) = (self.used, self.window);
        // the new pair's row of the Gram matrix and b = ΔFᵀ f, one pass
        let mut row = [0.0; MAX_WINDOW];
        let mut b = [0.0; MAX_WINDOW];
        // ΔFᵀ M ΔF and ΔFᵀ M f with a metric (M symmetric: (M Δf_k)ᵀ Δf_q),
        // ΔFᵀ ΔF and ΔFᵀ f without
        let (dk, rhs) = match mf {
            Some(mf) => (&self.mdf[k], mf),
            None => (&self.df[k], f),
        };
        for (i, (&dki, &ri)) in dk.iter().zip(rhs).enumerate() {
            for q in 0..m {
                let d = self.df[q][i];
                row[q] += dki * d;
                b[q] += d * ri;
            }
        }
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
                acc += theta[p] * self.dg[p][i];
            }
            *o -= acc;
        }
        true
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
                    let e: f64 = aa.df[p].iter().zip(&aa.df[q]).map(|(a, b)| a * b).sum();
                    let got = aa.gram[p * w + q];
                    assert!(
                        (got - e).abs() <= 1e-12 * (1.0 + e.abs()),
                        "step {step} ({p},{q})"
                    );
                }
            }
        }
    }
}
