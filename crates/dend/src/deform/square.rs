//! The paper's eq. (23) as a *square* system (design.md §5), beside the eq. (24)
//! least-squares rows of [`super::system`].
//!
//! With `L = D Lbar`, `D = diag(1/A_i)`, the residual on the unknown rows `U`
//! (hard constraints: the free vertices; the constrained columns are known)
//! is the mass-weighted Euler–Lagrange condition
//!
//! ```text
//!   F(Y) = D⁻¹ P (L Y − T δ)  +  λ2 Lbar_{U,R} (L Y − δ̂)_R  [+ λ1 Sᵀ(S Y − C)]  = 0
//! ```
//!
//! with the energies' pre-operators read with Euler–Lagrange signs (the
//! gradient of `∫|∇X|²` is `−ΔX`): membrane `P = −I`, thin plate `P = L`,
//! combined `P = −k_s I + k_b L`, total curvature `P = L − 2G`. Its linear part
//! `K = D⁻¹ P L + λ2 Lbar_{U,R} D_R Lbar_{R,·}` is 4th order (2-ring stencil):
//! `D⁻¹ L L = Lbar D Lbar` (positive semi-definite, since `Lbar` is negative
//! semi-definite), `D⁻¹(−L) = −Lbar` (PSD), and for `E_T` the extra
//! `−2 G Lbar` (`G ≥ 0`), non-symmetric but similar to the PSD
//! `2 G^{1/2} (−Lbar) G^{1/2}`. The literal `L² − 2LG` has no `P` form; its
//! square operator is `D⁻¹(L² − 2LG) = Lbar D Lbar − 2 Lbar G`.
//!
//! The factor cache factors the symmetric positive definite
//! `N = [K with −2GLbar replaced by 2 G^{1/2}(−Lbar)G^{1/2}]_{UU} + λ1 SᵀS`
//! once per constraint set; the iteration (`Deformer::step`) evaluates the
//! exact nonlinear residual `r = −F(Y)` and steps `Y ← Y + α N⁻¹ r`, with `N`
//! an approximate Jacobian (exact for membrane, thin plate and combined with
//! `T`, `δ̂` frozen). The merit is `Σ_u |r_u|² / A_u` (the squared L² norm of
//! the strong-form residual `D F`).
//!
//! `F` has the invariances of design.md §10: `Y = X` at rest gives `T = I`,
//! `δ̂ = δ`, `F = 0`; `K 1 = 0` (translation); a rigid motion `R` of every
//! constraint gives `T = R`, `δ̂ = R δ`, `F(R X) = R F(X) = 0`.

use sprs::{CsMat, TriMat};

use super::energy::{Energy, Shape};
use super::error::DeformError;
use super::params::{Formulation, Params};
use super::system::{add_soft_diagonal, partition, System};
use crate::mesh::{Point, Real};
use crate::operators::Operators;
use dend_linalg::sparse::{matmul, scale_entries};

/// The eq. (23) operators of one constraint set.
#[derive(Debug, Clone)]
pub(crate) struct Square {
    /// The exact linear part `K`, `|U| × #V`, CSR (without `λ1`).
    k: CsMat<Real>,
    /// `λ2 Lbar_{U,R}`, `|U| × #V`, CSR (columns in `R` only): maps `δ̂` to
    /// the right-hand side.
    ld: CsMat<Real>,
    /// `A_u` for each unknown `u` (the `D⁻¹` of the internal target).
    mass: Vec<Real>,
    /// `K_UU + λ1 SᵀS` (exact, non-symmetric): factored by LU
    /// ([`Formulation::SquareLu`]) or solved by GMRES preconditioned with
    /// the Cholesky of `N` ([`Formulation::Square`]).
    pub(crate) k_uu: Option<CsMat<Real>>,
}

/// Rows `rows` of `m`, columns mapped through `col` (dropped where `None`).
fn select(
    m: &CsMat<Real>,
    rows: &[u32],
    ncols: usize,
    col: impl Fn(usize) -> Option<usize>,
) -> CsMat<Real> {
    let mut t = TriMat::new((rows.len(), ncols));
    for (r, &i) in rows.iter().enumerate() {
        if let Some(row) = m.outer_view(i as usize) {
            for (c, &v) in row.iter() {
                if let Some(c) = col(c) {
                    t.add_triplet(r, c, v);
                }
            }
        }
    }
    t.to_csr()
}

/// Assembles the eq. (23) system of `constrained` (sorted): the shared
/// [`System`] (unknowns, rows, `m = N`; no stacked rows), the [`Square`]
/// operators, and the rest target `A X` with `A = D K_int` (used by the
/// literal paper mode and the linear detail term).
pub(crate) fn assemble(
    ops: &Operators,
    params: &Params,
    constrained: &[u32],
    active: &[bool],
) -> Result<(System, Square, Vec<Point>), DeformError> {
    let n = ops.num_vertices();
    let soft = params.lambda1 > 0.0;
    let (rows, unknowns, col_of) = partition(n, constrained, active, soft);
    let (k_int, n_int) = params.energy.square_operators(ops);
    // rest target A X = D (K_int X)
    let kx = crate::operators::laplacian_coordinates(&k_int, &ops.positions);
    let ax: Vec<Point> = kx
        .iter()
        .zip(&ops.area)
        .map(|(p, &a)| [p[0] / a, p[1] / a, p[2] / a])
        .collect();
    // λ2 Lbar_{·,R} D_R Lbar_{R,·}
    let lambda2 = params.lambda2;
    let mut in_r = vec![0.0; n];
    for &r in &rows {
        in_r[r as usize] = lambda2;
    }
    let detail = matmul(&ops.lbar, &scale_entries(&ops.l, |i, _| in_r[i]));
    let k_full = &k_int + &detail;
    let n_full = &n_int + &detail;
    let k = select(&k_full, &unknowns, n, Some);
    let col = |c: usize| (col_of[c] != u32::MAX).then(|| col_of[c] as usize);
    let mut m = select(&n_full, &unknowns, unknowns.len(), col);
    if soft {
        m = add_soft_diagonal(&m, constrained, &col_of, params.lambda1);
    }
    let k_uu = (params.formulation.kind() != Formulation::LeastSquares).then(|| {
        let mut k_uu = select(&k_full, &unknowns, unknowns.len(), col);
        if soft {
            k_uu = add_soft_diagonal(&k_uu, constrained, &col_of, params.lambda1);
        }
        k_uu
    });
    let ld = select(&ops.lbar.map(|v| lambda2 * v), &unknowns, n, |c| {
        (in_r[c] != 0.0).then_some(c)
    });
    let mass = unknowns.iter().map(|&u| ops.area[u as usize]).collect();
    let sys = System {
        row_weight: rows.iter().map(|&i| ops.area[i as usize].sqrt()).collect(),
        rows,
        sqrt_lambda2: lambda2.sqrt(),
        unknowns,
        col_of,
        m,
        constrained: constrained.to_vec(),
        lambda1: params.lambda1,
    };
    Ok((sys, Square { k, ld, mass, k_uu }, ax))
}

impl Square {
    /// Approximate heap bytes of `K` and `λ2 Lbar_{U,R}`.
    pub(crate) fn memory_bytes(&self) -> usize {
        let csr = |m: &CsMat<Real>| m.nnz() * 16 + (m.rows() + 1) * 8;
        csr(&self.k) + csr(&self.ld) + self.mass.len() * 8 + self.k_uu.as_ref().map_or(0, csr)
    }

    /// The residual `r = −F(Y)` on the unknown rows into `r` (column-major
    /// `|U| × 3`), given the internal target `t = P T δ` (or `A X`) over all
    /// vertices, `δ̂`, the pose and, with soft constraints (`sys.lambda1 >
    /// 0`), the targets. Returns the merit `Σ_u |r_u|² / A_u`.
    pub(crate) fn residual(
        &self,
        sys: &System,
        internal: &[Point],
        dhat: &[Point],
        y: &[Point],
        targets: &[(u32, Point)],
        r: &mut [Real],
    ) -> Real {
        let nu = sys.unknowns.len();
        for (k, ((krow, lrow), &u)) in self
            .k
            .outer_iterator()
            .zip(self.ld.outer_iterator())
            .zip(&sys.unknowns)
            .enumerate()
        {
            let a = self.mass[k];
            let t = internal[u as usize];
            let mut acc = [a * t[0], a * t[1], a * t[2]];
            for (c, &v) in lrow.iter() {
                let d = dhat[c];
                acc[0] += v * d[0];
                acc[1] += v * d[1];
                acc[2] += v * d[2];
            }
            for (c, &v) in krow.iter() {
                let p = y[c];
                acc[0] -= v * p[0];
                acc[1] -= v * p[1];
                acc[2] -= v * p[2];
            }
            r[k] = acc[0];
            r[nu + k] = acc[1];
            r[2 * nu + k] = acc[2];
        }
        sys.add_soft_rhs(targets, y, r);
        let mut merit = 0.0;
        for (k, &a) in self.mass.iter().enumerate() {
            merit += (r[k] * r[k] + r[nu + k] * r[nu + k] + r[2 * nu + k] * r[2 * nu + k]) / a;
        }
        merit
    }
}

/// `v ← P v`, the energy's pre-operator in `A = P L` (membrane `I`, thin
/// plate `L`, combined `k_s I + k_b L`, total curvature `L - 2G`), its
/// identity part multiplied by `sign` (`-1`: the eq. (23) Euler–Lagrange
/// signs, module docs); the literal `L² - 2LG` has no such form and its
/// target `T (A X)` is used as is.
pub(super) fn apply_p(
    energy: Energy,
    sign: Real,
    ops: &Operators,
    v: &mut [Point],
    lv: &mut [Point],
) {
    let Shape::Left { ci, cl, g } = energy.shape() else {
        return;
    };
    if (ci, cl, g) == (1.0, 0.0, 0.0) && sign == 1.0 {
        return;
    }
    // (a zero stays +0: the sum below keeps the signs of zeros it had)
    let ci = if ci == 0.0 { 0.0 } else { sign * ci };
    let g2 = g != 0.0;
    for (i, row) in ops.l.outer_iterator().enumerate() {
        let mut acc = [0.0; 3];
        for (j, &w) in row.iter() {
            acc[0] += w * v[j][0];
            acc[1] += w * v[j][1];
            acc[2] += w * v[j][2];
        }
        lv[i] = acc;
    }
    for (i, p) in v.iter_mut().enumerate() {
        let g = if g2 { -2.0 * ops.g[i] } else { 0.0 };
        for k in 0..3 {
            p[k] = (ci + g) * p[k] + cl * lv[i][k];
        }
    }
}

/// Solves `K x = b` in place (`b` → `x`) by right-preconditioned restarted
/// GMRES (Saad & Schultz 1986), `precond(v)` applying `N⁻¹` in place; stops
/// at relative residual `tol` or after `max_iters` inner steps. Returns the
/// inner steps taken.
pub(crate) fn gmres(
    k: &CsMat<Real>,
    b: &mut [Real],
    mut precond: impl FnMut(&mut [Real]),
    tol: Real,
    max_iters: usize,
) -> usize {
    const RESTART: usize = 20;
    let n = b.len();
    let matvec = |x: &[Real], out: &mut [Real]| {
        for (o, row) in out.iter_mut().zip(k.outer_iterator()) {
            *o = row.iter().map(|(c, &v)| v * x[c]).sum();
        }
    };
    let norm = |v: &[Real]| v.iter().map(|x| x * x).sum::<Real>().sqrt();
    let b0 = b.to_vec();
    let bnorm = norm(&b0);
    let mut x = vec![0.0; n];
    if bnorm == 0.0 {
        return 0;
    }
    let mut steps = 0;
    let mut w = vec![0.0; n];
    let mut z = vec![0.0; n];
    while steps < max_iters {
        // r = b - K x
        matvec(&x, &mut w);
        let r: Vec<Real> = b0.iter().zip(&w).map(|(b, kx)| b - kx).collect();
        let beta = norm(&r);
        if beta <= tol * bnorm {
            break;
        }
        let mut v: Vec<Vec<Real>> = vec![r.iter().map(|x| x / beta).collect()];
        let mut zs: Vec<Vec<Real>> = Vec::new();
        let mut h = vec![[0.0; RESTART + 1]; RESTART];
        let (mut cs, mut sn) = ([0.0; RESTART], [0.0; RESTART]);
        let mut g = [0.0; RESTART + 1];
        g[0] = beta;
        let mut m = 0;
        while m < RESTART && steps < max_iters {
            z.copy_from_slice(&v[m]);
            precond(&mut z);
            matvec(&z, &mut w);
            zs.push(z.clone());
            for (i, vi) in v.iter().enumerate() {
                let hij: Real = w.iter().zip(vi).map(|(a, b)| a * b).sum();
                h[m][i] = hij;
                for (wk, vk) in w.iter_mut().zip(vi) {
                    *wk -= hij * vk;
                }
            }
            let hn = norm(&w);
            h[m][m + 1] = hn;
            for i in 0..m {
                let t = cs[i] * h[m][i] + sn[i] * h[m][i + 1];
                h[m][i + 1] = -sn[i] * h[m][i] + cs[i] * h[m][i + 1];
                h[m][i] = t;
            }
            let d = (h[m][m] * h[m][m] + hn * hn).sqrt();
            (cs[m], sn[m]) = if d == 0.0 {
                (1.0, 0.0)
            } else {
                (h[m][m] / d, hn / d)
            };
            h[m][m] = d;
            h[m][m + 1] = 0.0;
            g[m + 1] = -sn[m] * g[m];
            g[m] *= cs[m];
            steps += 1;
            m += 1;
            if g[m].abs() <= tol * bnorm || hn == 0.0 {
                break;
            }
            v.push(w.iter().map(|x| x / hn).collect());
        }
        // back substitution, x += Z y
        let mut y = [0.0; RESTART];
        for i in (0..m).rev() {
            let s: Real = (i + 1..m).map(|j| h[j][i] * y[j]).sum();
            y[i] = (g[i] - s) / h[i][i];
        }
        for (j, zj) in zs.iter().enumerate().take(m) {
            for (xk, zk) in x.iter_mut().zip(zj) {
                *xk += y[j] * zk;
            }
        }
        if g[m].abs() <= tol * bnorm {
            break;
        }
    }
    b.copy_from_slice(&x);
    steps
}
