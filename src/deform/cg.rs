//! Jacobi-preconditioned conjugate gradient on the normal matrix `M`
//! (dend.md §4): the paper's own solver ("conjugate gradient", no
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
//! the product `M p` runs on the rayon pool above [`PARALLEL_MIN`] unknowns.

use faer::dyn_stack::{MemStack, StackReq};
use faer::MatMut;
use rayon::prelude::*;
use sprs::CsMat;

use crate::mesh::Real;

/// Unknown count above which `M p` runs in parallel.
const PARALLEL_MIN: usize = 4096;

/// The preconditioned CG solver of one normal matrix: `P⁻¹ = 1 / diag(M)`.
#[derive(Debug, Clone)]
pub(crate) struct Cg {
    inv_diag: Vec<Real>,
    /// Relative residual tolerance `|M x - b| ≤ tol |b|`.
    pub(crate) tol: Real,
    /// Iteration cap per column.
    pub(crate) max_iters: usize,
}

/// What one [`Cg::solve_in_place`] did (summed over the columns).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct CgStats {
    /// CG iterations over all columns.
    pub iterations: usize,
    /// The largest final relative residual over the columns.
    pub rel_residual: Real,
}

impl Cg {
    /// The Jacobi preconditioner of `m` (CSR, square, symmetric).
    pub(crate) fn new(m: &CsMat<Real>, tol: Real, max_iters: usize) -> Self {
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
    pub(crate) fn scratch(n: usize) -> StackReq {
        StackReq::new::<Real>(5 * n)
    }

    /// Solves `M X = B` for every column of `b` (overwritten by `X`).
    pub(crate) fn solve_in_place(
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
            matvec(m, p, q);
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

/// `q = M p` for CSR `m`.
fn matvec(m: &CsMat<Real>, p: &[Real], q: &mut [Real]) {
    let (indptr, indices, data) = (m.indptr(), m.indices(), m.data());
    let row = |(i, out): (usize, &mut Real)| {
        let (s, e) = (indptr.index(i), indptr.index(i + 1));
        let mut acc = 0.0;
        for k in s..e {
            acc += data[k] * p[indices[k]];
        }
        *out = acc;
    };
    if q.len() >= PARALLEL_MIN {
        q.par_iter_mut().enumerate().for_each(row);
    } else {
        q.iter_mut().enumerate().for_each(row);
    }
}

#[cfg(test)]
pub(super) mod tests {
    use std::sync::Arc;

    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::MatMut;

    use crate::deform::{
        Constraints, Deformer, Factor, Params, Rest, RigidTransform, SolveOptions, SolverChoice,
    };
    use crate::mesh::Mesh;

    /// A wavy `k × k` grid in the xy plane.
    pub(in crate::deform) fn grid(k: usize) -> Mesh {
        let mut p = Vec::new();
        for r in 0..k {
            for c in 0..k {
                let (x, y) = (c as f64, r as f64 * 0.93);
                p.push([x, y, 0.3 * (0.7 * x).sin() * (0.5 * y).cos()]);
            }
        }
        let mut t = Vec::new();
        let k = k as u32;
        for r in 0..k - 1 {
            for c in 0..k - 1 {
                let v = r * k + c;
                t.push([v, v + 1, v + k + 1]);
                t.push([v, v + k + 1, v + k]);
            }
        }
        Mesh::new(p, t).unwrap()
    }

    pub(in crate::deform) fn edit(mesh: &Mesh, k: usize) -> Constraints {
        let fixed: Vec<u32> = (0..k as u32).map(|r| r * k as u32).collect();
        let handle: Vec<u32> = (0..k as u32).map(|r| r * k as u32 + k as u32 - 1).collect();
        let mut t = RigidTransform::identity([0.0; 3]);
        t.translation = [0.0, 0.0, 3.0];
        Constraints::new(mesh, fixed, vec![("h".into(), handle, Some(t))]).unwrap()
    }

    fn options(solver: SolverChoice, cg_tol: f64) -> SolveOptions {
        SolveOptions {
            solver,
            cg_tol,
            ..SolveOptions::default()
        }
    }

    /// A fixed pseudo-random right-hand side of `len` values in [-0.5, 0.5).
    pub(in crate::deform) fn pseudo_random(len: usize) -> Vec<f64> {
        (0..len)
            .map(|i| ((i * 7919 % 1013) as f64 / 1013.0) - 0.5)
            .collect()
    }

    /// Solves `M X = B` with `f` for a fixed pseudo-random `B` (`n × 3`).
    pub(in crate::deform) fn solve(f: &Factor, b: &[f64]) -> Vec<f64> {
        let n = f.num_unknowns();
        let mut x = b.to_vec();
        let mut mem = MemBuffer::new(f.solve_scratch(3));
        f.solve_in_place(
            MatMut::from_column_major_slice_mut(&mut x, n, 3),
            MemStack::new(&mut mem),
        );
        x
    }

    pub(in crate::deform) fn residual(f: &Factor, x: &[f64], b: &[f64]) -> f64 {
        let n = f.num_unknowns();
        let mut worst: f64 = 0.0;
        for c in 0..3 {
            let xc = &x[c * n..(c + 1) * n];
            let bc = &b[c * n..(c + 1) * n];
            let mx: Vec<f64> = f
                .sys
                .m
                .outer_iterator()
                .map(|row| row.iter().map(|(j, v)| v * xc[j]).sum())
                .collect();
            let r: f64 = mx.iter().zip(bc).map(|(a, b)| (a - b).powi(2)).sum();
            let bn: f64 = bc.iter().map(|v| v * v).sum();
            worst = worst.max((r / bn).sqrt());
        }
        worst
    }

    #[test]
    fn cg_and_cholesky_agree_to_the_cg_tolerance() {
        let k = 14;
        let mesh = grid(k);
        let rest = Rest::new(mesh.clone()).unwrap();
        let c = edit(&mesh, k);
        let params = Params::default();
        let direct =
            Factor::build_with(&rest, &params, &c, &options(SolverChoice::Direct, 1e-4)).unwrap();
        assert!(!direct.uses_cg() && direct.factor_nnz() > 0);
        let n = direct.num_unknowns();
        let b = pseudo_random(3 * n);
        let x_chol = solve(&direct, &b);
        assert!(residual(&direct, &x_chol, &b) < 1e-9);
        for tol in [1e-4, 1e-10] {
            let cg =
                Factor::build_with(&rest, &params, &c, &options(SolverChoice::Cg, tol)).unwrap();
            assert!(cg.uses_cg() && cg.factor_nnz() == 0);
            let x_cg = solve(&cg, &b);
            assert!(cg.cg_iterations() > 0);
            // CG's stopping test, checked independently with M.
            let res = residual(&cg, &x_cg, &b);
            assert!(res <= tol * 1.01, "tol {tol}: residual {res}");
            // The tight solve agrees with Cholesky to well below the scale of x.
            if tol < 1e-8 {
                let scale = x_chol.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let diff = x_chol
                    .iter()
                    .zip(&x_cg)
                    .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                assert!(diff < 1e-5 * scale, "diff {diff} scale {scale}");
            }
        }
    }

    #[test]
    fn over_a_tiny_budget_the_mesh_still_deforms_by_cg() {
        let k = 12;
        let mesh = grid(k);
        let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
        let c = edit(&mesh, k);
        let params = Params::default();
        let tiny = SolveOptions {
            factor_budget_bytes: 1,
            cg_tol: 1e-8,
            ..SolveOptions::default()
        };
        let auto = Factor::build_with(&rest, &params, &c, &tiny).unwrap();
        assert!(auto.uses_cg());
        let direct = Factor::build(&rest, &params, &c).unwrap();
        assert!(!direct.uses_cg());
        let mut d_cg = Deformer::new(rest.clone(), params);
        let mut d_dir = Deformer::new(rest.clone(), params);
        let r_cg = d_cg.step(&auto, &c, 100).unwrap();
        let r_dir = d_dir.step(&direct, &c, 100).unwrap();
        assert!(r_cg.converged && !r_cg.diverged, "{r_cg:?}");
        // The handle reached its target and the free vertices moved.
        let moved = d_cg
            .pose()
            .iter()
            .zip(mesh.positions())
            .filter(|(a, b)| (a[2] - b[2]).abs() > 0.1)
            .count();
        assert!(moved > k * k / 3, "only {moved} vertices moved");
        let h = k - 1;
        assert!((d_cg.pose()[h][2] - mesh.positions()[h][2] - 3.0).abs() < 1e-9);
        // Same pose as the direct solver, to the iteration tolerance.
        let diff = d_cg
            .pose()
            .iter()
            .zip(d_dir.pose())
            .map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).abs()).fold(0.0, f64::max))
            .fold(0.0, f64::max);
        assert!(
            diff < 0.05 * mesh.mean_edge_length(),
            "diff {diff}; {r_dir:?}"
        );
    }
}
