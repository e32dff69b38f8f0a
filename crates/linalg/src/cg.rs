//! Jacobi-preconditioned conjugate gradient on the normal matrix `M`
//! (design.md §4.4): the paper's own solver ("conjugate gradient", no
//! factorisation), kept as a benchmark baseline and as the fallback when the
//! Cholesky factor of `M` would exceed the memory budget.
//!
//! For `M x = b` with `M` symmetric positive definite and `P = diag(M)`
//! (Hestenes & Stiefel 1952; Saad, *Iterative Methods for Sparse Linear
//! Systems*, 2nd ed., Alg. 9.1):
//!
//! ```text
//!   x0 = 0, r0 = b, z0 = P⁻¹ r0, p0 = z0
//!   αk = (rk·zk) / (pk·M pk);  x += αk pk;  r -= αk M pk
//!   stop when |r| ≤ tol·|b|;   z = P⁻¹ r;  βk = (r'·z') / (r·z);  p = z + βk p
//! ```
//!
//! DEND solves for the *update* `ΔY` each iteration, so the natural warm start
//! is `x0 = 0`. Each of the three coordinate columns is solved on its own;
//! the product `M p` is [`crate::sparse::mul_columns`] (on the rayon pool
//! from 4096 unknowns).

use faer::dyn_stack::{MemStack, StackReq};
use faer::MatMut;
use sprs::CsMat;

use crate::sparse::mul_columns;
use crate::Real;

/// The preconditioned CG solver of one normal matrix: `P⁻¹ = 1 / diag(M)`.
#[derive(Debug, Clone)]
pub struct Cg {
    inv_diag: Vec<Real>,
    /// Relative residual tolerance `|M x - b| ≤ tol |b|`.
    pub tol: Real,
    /// Iteration cap per column.
    pub max_iters: usize,
}

/// What one [`Cg::solve_in_place`] did (summed over the columns).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CgStats {
    /// CG iterations over all columns.
    pub iterations: usize,
    /// The largest final relative residual over the columns.
    pub rel_residual: Real,
}

impl Cg {
    /// The Jacobi preconditioner of `m` (CSR, square, symmetric).
    pub fn new(m: &CsMat<Real>, tol: Real, max_iters: usize) -> Self {
        let inv_diag = m
            .outer_iterator()
            .enumerate()
            .map(|(i, row)| {
                let d = row.get(i).copied().unwrap_or(0.0);
                if d > 0.0 {
                    1.0 / d
                } else {
                    1.0
                }
            })
            .collect();
        Cg {
            inv_diag,
            tol,
            max_iters,
        }
    }

    /// Scratch for [`Cg::solve_in_place`]: five work vectors of `n` reals.
    pub fn scratch(n: usize) -> StackReq {
        StackReq::new::<Real>(5 * n)
    }

    /// Solves `M X = B` for every column of `b` (overwritten by `X`).
    pub fn solve_in_place(
        &self,
        m: &CsMat<Real>,
        mut b: MatMut<'_, Real>,
        stack: &mut MemStack,
    ) -> CgStats {
        let n = self.inv_diag.len();
        let (mut work, _) = stack.make_with::<Real>(5 * n, |_| 0.0);
        let (x, rest) = work.split_at_mut(n);
        let (r, rest) = rest.split_at_mut(n);
        let (z, rest) = rest.split_at_mut(n);
        let (p, q) = rest.split_at_mut(n);
        let mut stats = CgStats::default();
        for col in 0..b.ncols() {
            let mut bc = b.as_mut().col_mut(col);
            for (ri, bi) in r.iter_mut().zip(bc.as_ref().iter()) {
                *ri = *bi;
            }
            let (k, res) = self.solve_one(m, x, r, z, p, q);
            stats.iterations += k;
            stats.rel_residual = stats.rel_residual.max(res);
            for (bi, xi) in bc.as_mut().iter_mut().zip(x.iter()) {
                *bi = *xi;
            }
        }
        stats
    }

    /// One column: `r` holds `b` on entry; `x` receives the solution.
    #[allow(clippy::needless_range_loop)] // five arrays updated in one fused pass
    fn solve_one(
        &self,
        m: &CsMat<Real>,
        x: &mut [Real],
        r: &mut [Real],
        z: &mut [Real],
        p: &mut [Real],
        q: &mut [Real],
    ) -> (usize, Real) {
        x.fill(0.0);
        let b_norm = dot(r, r).sqrt();
        if b_norm == 0.0 {
            return (0, 0.0);
        }
        for ((zi, di), ri) in z.iter_mut().zip(&self.inv_diag).zip(r.iter()) {
            *zi = di * ri;
        }
        p.copy_from_slice(z);
        let mut rz = dot(r, z);
        let goal = self.tol * b_norm;
        let mut res = b_norm;
        let mut k = 0;
        while k < self.max_iters && res > goal {
            mul_columns::<1>(m, p, q);
            let pq = dot(p, q);
            if pq.is_nan() || pq <= 0.0 {
                break; // breakdown: M not positive definite on p
            }
            let alpha = rz / pq;
            let mut rr = 0.0;
            for i in 0..x.len() {
                x[i] += alpha * p[i];
                r[i] -= alpha * q[i];
                rr += r[i] * r[i];
                z[i] = self.inv_diag[i] * r[i];
            }
            res = rr.sqrt();
            let rz_new = dot(r, z);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..p.len() {
                p[i] = z[i] + beta * p[i];
            }
            k += 1;
        }
        (k, res / b_norm)
    }
}

fn dot(a: &[Real], b: &[Real]) -> Real {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
