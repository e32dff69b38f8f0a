//! The Hessian of the elastic energy with its rotations and area targets
//! eliminated: the matrix of the Newton step (`solver/newton.rs`).
//!
//! Every rotation-dependent term of `E(Y, R, P)` belongs to one element:
//! a free vertex `i` (its spokes and its Laplacian row, rotation `R_i`) or
//! a triangle `t` (its area target `P_t`). The reduced energy
//! `E(Y) = min_{R, P} E(Y, R, P)` is what the local/global iteration
//! minimises; at the element's best `R` (or `P`), the envelope theorem
//! gives its gradient, and its Hessian is the element's Hessian in
//! `(dY, ξ)` with the element's own unknowns `ξ` eliminated (a Schur
//! complement, the static condensation of a mixed finite element).
//!
//! **A vertex's rotation.** Turning `R_i` by a small world-frame vector
//! `ω`, `R ← exp([ω]×) R`, each residual `ρ = d − t` of the element (`d`
//! the deformed vector, `(y_j − y_i)` or `(L Y)_i`; `t` the rotated rest
//! vector, `R_i e_ij` or `R_i δ_i`) becomes, to second order,
//!
//! ```text
//! ρ + A dY + [t]× ω − ½ [ω]×² t
//! ```
//!
//! so the element's energy `Σ w |ρ|²` has the blocks
//!
//! ```text
//! H_YY = Σ w AᵀA,   J = Σ w [t]×ᵀ A,
//! C = Σ w (|t|² I − t tᵀ) + Σ w ((ρ·t) I − sym(ρ tᵀ)) = Σ w ((d·t) I − sym(d tᵀ))
//! ```
//!
//! (`C = tr(S) I − S`, `S = sym(Σ w d tᵀ)`: the Hessian of the polar
//! decomposition's nuclear norm, as in ARAP's exact Hessian). The first
//! part of `C` is the Gauss–Newton one (the rotations' residuals held
//! linear); the second is the curvature of the rotations, positive where
//! the element is stretched along its rest vectors and negative where it
//! is compressed. With all of it ([`Curvature::Full`]) the Schur
//! complement `H_YY − Jᵀ C⁻¹ J` is the reduced energy's Hessian, which
//! compressed elements can make indefinite; with its positive
//! semi-definite part only ([`Curvature::Projected`]) `C` is at least the
//! Gauss–Newton `C`, so the element's `(dY, ω)` matrix and its Schur
//! complement stay positive semi-definite (the usual projection of an
//! indefinite Hessian to a convex model; Smith, de Goes & Kim 2019 do it
//! per eigenvalue). Newton's method converges quadratically with the
//! first near a minimum and only linearly with the second, since a
//! minimum of an edit has compressed elements too.
//!
//! **A triangle's area target.** `P_t` is the nearest point to `F_t` on
//! the set `M` of 3×2 matrices with singular values `d, 1/d`, which has
//! dimension 5 in the 6 of `F` (three rotations of the columns' frame,
//! one of the stretch directions in the rest plane, and `d`). The term
//! `‖F − P(F)‖²` is a function of `F`'s singular values, and its Hessian
//! in `F` has a closed-form eigensystem ([`area_eigensystem`]); on `M`
//! four of its eigenvalues vanish (the tangent directions, along which
//! the term does not change to second order) and one is 1, along the
//! normal
//!
//! ```text
//! N = U diag(1/d, d) Vᵀ = P (PᵀP)⁻¹,   n = N / |N|
//! ```
//!
//! which is what eliminating the five tangent unknowns leaves: the area
//! term resists the change of area, which is what it penalises. Holding
//! `d` and the stretch directions instead (eliminating the rotation only)
//! makes the term as stiff as a triangle-wise ARAP term of weight `k_a`
//! (15 against the stretch's 3 with the characters' weights), and a
//! Newton step with that matrix converged only linearly on edits that
//! shear triangles (a patch whose far side turns 70°: 44 Newton
//! iterations to tolerance 1e-6 against 11 with the eigensystem). Off
//! `M`, [`Curvature::Projected`] keeps the eigenvalues' positive parts.
//! A nearly flat triangle, whose eigensystem is ill-conditioned, gets the
//! normal alone.

use nalgebra::{Matrix2, Matrix3, UnitQuaternion, Vector2, Vector3};

use super::area::{area_root, curvature as area_curvature, gradient};
use super::{ElasticOps, ElasticSet};
use crate::mesh::{Point, Real};
use crate::operators::Operators;

/// `[t]×`, the cross-product matrix: `[t]× v = t × v`.
fn cross_matrix(t: &Vector3<Real>) -> Matrix3<Real> {
    Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0)
}

/// `|t|² I − t tᵀ = [t]×ᵀ [t]×`.
fn gram(t: &Vector3<Real>) -> Matrix3<Real> {
    Matrix3::identity() * t.norm_squared() - t * t.transpose()
}

/// Adds `−Σ_k,l J_kᵀ C⁻¹ J_l` through `add` for the blocks `J` of one
/// element (vertex, 3×3 block), in unknown numbering `col_of` (`add(k, l,
/// B)` adds the 3×3 block `B` at unknowns `(k, l)`); blocks of vertices
/// that are not unknowns are skipped. Nothing when `C` is singular.
fn add_schur(
    c: &Matrix3<Real>,
    blocks: &[(u32, Matrix3<Real>)],
    col_of: &[u32],
    add: &mut impl FnMut(u32, u32, &Matrix3<Real>),
) {
    let Some(c_inv) = c.try_inverse() else {
        return;
    };
    for &(k, jk) in blocks {
        let ck = col_of[k as usize];
        if ck == u32::MAX {
            continue;
        }
        let left = jk.transpose() * c_inv;
        for &(l, jl) in blocks {
            let cl = col_of[l as usize];
            if cl == u32::MAX {
                continue;
            }
            add(ck, cl, &-(left * jl));
        }
    }
}

/// The positive semi-definite part of the symmetric `m` (its negative
/// eigenvalues set to zero).
fn positive_part(m: &Matrix3<Real>) -> Matrix3<Real> {
    let eig = m.symmetric_eigen();
    let mut out = Matrix3::zeros();
    for k in 0..3 {
        let l = eig.eigenvalues[k];
        if l > 0.0 {
            let v = eig.eigenvectors.column(k);
            out += l * v * v.transpose();
        }
    }
    out
}

/// `(ρ·t) I − sym(ρ tᵀ)`: the rotation's curvature term of one residual
/// `ρ` with rotated rest vector `t` (module docs).
fn rotation_curvature(rho: &Vector3<Real>, t: &Vector3<Real>) -> Matrix3<Real> {
    let outer = rho * t.transpose();
    Matrix3::identity() * rho.dot(t) - 0.5 * (outer + outer.transpose())
}

/// The unit normal `n = N / |N|`, `N = P (PᵀP)⁻¹`, of the area targets'
/// set at `p` (column-major 3×2; module docs), as its two columns; `None`
/// where `P` is degenerate.
fn area_normal(p: &[Real; 6]) -> Option<[Vector3<Real>; 2]> {
    let p0 = Vector3::new(p[0], p[1], p[2]);
    let p1 = Vector3::new(p[3], p[4], p[5]);
    let (a, b, c) = (p0.dot(&p0), p0.dot(&p1), p1.dot(&p1));
    let det = a * c - b * b;
    // (written so that NaN is degenerate too)
    if det.partial_cmp(&(1e-12 * (a + c) * (a + c))) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let n0 = (c * p0 - b * p1) / det;
    let n1 = (a * p1 - b * p0) / det;
    let norm = (n0.norm_squared() + n1.norm_squared()).sqrt();
    (norm > 0.0 && norm.is_finite()).then(|| [n0 / norm, n1 / norm])
}

/// Which part of the elements' curvature (the rotations' and the area
/// targets' second-order terms, module docs) the matrix keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Curvature {
    /// All of it: the reduced energy's Hessian, indefinite where elements
    /// are compressed enough.
    Full,
    /// Its positive semi-definite part per element: a positive
    /// semi-definite matrix.
    Projected,
}

impl Curvature {
    /// The least eigenvalue an element's curvature keeps.
    fn floor(self) -> Real {
        match self {
            Curvature::Full => Real::NEG_INFINITY,
            Curvature::Projected => 0.0,
        }
    }
}

/// One eigenpair of [`area_eigensystem`]: the eigenvalue and its unit
/// 3×2 eigenmatrix as two columns.
type AreaMode = (Real, [Vector3<Real>; 2]);

/// Half the Hessian in `F` of the area term's `‖F − P(F)‖²` (3×2, `P` the
/// nearest matrix with singular values `d, 1/d`), as six eigenpairs with
/// the negative eigenvalues set to zero (module docs); `None` where `F`
/// is nearly flat (`σ2 ≤ 10⁻⁴ σ1`) or its `d` is not a strict minimum.
///
/// The term is a function `ψ(σ1, σ2) = min_d (σ1 − d)² + (σ2 − 1/d)²` of
/// `F`'s singular values, so its Hessian has the eigensystem of any such
/// function of a 3×2 matrix (Smith, de Goes & Kim 2019 for the square
/// case), with `F = U Σ Vᵀ`, `u₂ = u₀ × u₁`, `p = (d, 1/d)` and
/// `ψ_k = 2 (σ_k − p_k)`:
///
/// ```text
/// ½ ∇²ψ = I − τ τᵀ / g        on u₀v₀ᵀ, u₁v₁ᵀ   (τ = (1, −1/d²), g = ½ ∂²_d of the min)
/// 1 − (p₀ + p₁)/(σ₀ + σ₁)      on (u₀v₁ᵀ − u₁v₀ᵀ)/√2   (a turn in the plane)
/// 1 − (p₀ − p₁)/(σ₀ − σ₁)      on (u₀v₁ᵀ + u₁v₀ᵀ)/√2   (a shear)
/// 1 − p_k/σ_k                  on u₂v_kᵀ               (out of the plane)
/// ```
fn area_eigensystem(f: &[Real; 6], curvature: Curvature) -> Option<[AreaMode; 6]> {
    let floor = curvature.floor();
    let c0 = Vector3::new(f[0], f[1], f[2]);
    let c1 = Vector3::new(f[3], f[4], f[5]);
    let ftf = Matrix2::new(c0.dot(&c0), c0.dot(&c1), c0.dot(&c1), c1.dot(&c1));
    let eig = ftf.symmetric_eigen();
    let (i0, i1) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    let s = [
        eig.eigenvalues[i0].max(0.0).sqrt(),
        eig.eigenvalues[i1].max(0.0).sqrt(),
    ];
    if s[1].partial_cmp(&(1e-4 * s[0])) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let v: [Vector2<Real>; 2] = [
        eig.eigenvectors.column(i0).into(),
        eig.eigenvectors.column(i1).into(),
    ];
    let u0 = (c0 * v[0][0] + c1 * v[0][1]) / s[0];
    let u1 = (c0 * v[1][0] + c1 * v[1][1]) / s[1];
    let u2 = u0.cross(&u1).try_normalize(1e-300)?;
    let u = [u0, u1];
    let d = area_root(s[0], s[1]);
    let p = [d, 1.0 / d];
    let g = 0.5 * area_curvature(s[1], d);
    if g.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    // x yᵀ as two columns
    let outer = |x: Vector3<Real>, y: Vector2<Real>| [x * y[0], x * y[1]];
    let tau = Vector2::new(1.0, -p[1] * p[1]);
    let scaling = Matrix2::identity() - tau * tau.transpose() / g;
    let se = scaling.symmetric_eigen();
    let mode = |k: usize| -> AreaMode {
        let w = se.eigenvectors.column(k);
        let [a0, a1] = outer(u[0], v[0] * w[0]);
        let [b0, b1] = outer(u[1], v[1] * w[1]);
        (se.eigenvalues[k].max(floor), [a0 + b0, a1 + b1])
    };
    let shear = if s[0] - s[1] > 1e-8 * s[0] {
        1.0 - (p[0] - p[1]) / (s[0] - s[1])
    } else {
        // the limit σ₀ → σ₁: the scaling block along (1, −1)
        scaling[(0, 0)] - scaling[(0, 1)]
    };
    let turn = 1.0 - (p[0] + p[1]) / (s[0] + s[1]);
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let [x0, x1] = outer(u[0], v[1]);
    let [y0, y1] = outer(u[1], v[0]);
    Some([
        mode(0),
        mode(1),
        (turn.max(floor), [h * (x0 - y0), h * (x1 - y1)]),
        (shear.max(floor), [h * (x0 + y0), h * (x1 + y1)]),
        ((1.0 - p[0] / s[0]).max(floor), outer(u2, v[0])),
        ((1.0 - p[1] / s[1]).max(floor), outer(u2, v[1])),
    ])
}

impl ElasticOps {
    /// Adds what eliminating each element's rotation or area target (with
    /// the elements' `curvature`)
    /// changes in `Q ⊗ I₃` (module docs) at the normalised pose `y`, the
    /// rotations `rot` and area targets `proj`, through `add(k, l, B)`,
    /// the 3×3 block `B` of unknowns `(k, l)` in `col_of`'s numbering
    /// (vertex → unknown, `u32::MAX` for none): `−Jᵀ C⁻¹ J` per free
    /// vertex, `w ((Aᵀn)(Aᵀn)ᵀ − AᵀA)` per triangle. Both triangles of the
    /// symmetric matrix are added, duplicates to be summed. The blocks
    /// added are among [`ElasticOps::coupling_supports`]' pairs.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn rotation_coupling(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        y: &[Point],
        rot: &[UnitQuaternion<Real>],
        proj: &[[Real; 6]],
        col_of: &[u32],
        curvature: Curvature,
        mut add: impl FnMut(u32, u32, &Matrix3<Real>),
    ) {
        let mut blocks: Vec<(u32, Matrix3<Real>)> = Vec::new();
        for (i, q) in rot.iter().enumerate().take(set.free.len()) {
            if !(set.free[i] && set.fit[i]) {
                continue;
            }
            let r = q.to_rotation_matrix();
            let yi = Vector3::from(y[i]);
            let mut c = Matrix3::zeros();
            let mut bend = Matrix3::zeros();
            blocks.clear();
            blocks.push((i as u32, Matrix3::zeros()));
            for s in self.ptr[i]..self.ptr[i + 1] {
                let t = r * Vector3::from(self.e[s]);
                let j = self.nbr[s] as usize;
                let rho = Vector3::from(y[j]) - yi - t;
                c += self.c[s] * gram(&t);
                bend += self.c[s] * rotation_curvature(&rho, &t);
                // ρ = (y_j − y_i) − R_i e_ij: A dY = dy_j − dy_i
                let k = self.c[s] * cross_matrix(&t).transpose();
                blocks.push((self.nbr[s], k));
                blocks[0].1 -= k;
            }
            if self.b[i] > 0.0 {
                // ρ = (L Y)_i − R_i δ_i: A dY = Σ_k L_ik dy_k, L = D⁻¹ Lbar
                let t = r * Vector3::from(ops.delta[i]);
                let kt = self.b[i] * cross_matrix(&t).transpose();
                let row = ops.lbar.outer_view(i).expect("row of a vertex");
                let mut ly = Vector3::zeros();
                for (k, &w) in row.iter() {
                    let l = w / ops.area[i];
                    ly += l * Vector3::from(y[k]);
                    match blocks.iter_mut().find(|(v, _)| *v as usize == k) {
                        Some(b) => b.1 += l * kt,
                        None => blocks.push((k as u32, l * kt)),
                    }
                }
                c += self.b[i] * gram(&t);
                bend += self.b[i] * rotation_curvature(&(ly - t), &t);
            }
            c += match curvature {
                Curvature::Projected => positive_part(&bend),
                Curvature::Full => bend,
            };
            add_schur(&c, &blocks, col_of, &mut add);
        }
        for (el, p) in self.area.iter().zip(proj) {
            let k = el.corners();
            let cols: [u32; 3] = el.v.map(|v| col_of[v as usize]);
            let w = el.weight;
            // `Q` holds w AᵀA: take it out, then add w Aᵀ (½ ∇²_F) A
            for (a, &ca) in cols.iter().enumerate() {
                for (bi, &cb) in cols.iter().enumerate() {
                    if ca != u32::MAX && cb != u32::MAX {
                        let kk = k[a][0] * k[bi][0] + k[a][1] * k[bi][1];
                        add(ca, cb, &(Matrix3::identity() * (-w * kk)));
                    }
                }
            }
            let modes = area_eigensystem(&gradient(y, el), curvature);
            let gauss_newton;
            let modes: &[AreaMode] = match &modes {
                Some(m) => m,
                None => match area_normal(p) {
                    Some(n) => {
                        gauss_newton = [(1.0, n)];
                        &gauss_newton
                    }
                    None => &[],
                },
            };
            for &(lambda, [m0, m1]) in modes {
                if lambda == 0.0 {
                    continue;
                }
                // (Aᵀ m)_v = k_v0 m_0 + k_v1 m_1
                let am = k.map(|kv| kv[0] * m0 + kv[1] * m1);
                for (a, &ca) in cols.iter().enumerate() {
                    for (bi, &cb) in cols.iter().enumerate() {
                        if ca != u32::MAX && cb != u32::MAX {
                            add(ca, cb, &(w * lambda * am[a] * am[bi].transpose()));
                        }
                    }
                }
            }
        }
    }

    /// Calls `f` with the vertices of each element that
    /// [`ElasticOps::rotation_coupling`] visits (a fitted free vertex with
    /// its spokes' ends and its Laplacian row, a triangle with an area
    /// term): every pair of unknowns among one element's vertices may get
    /// a block, whatever the rotations. The pattern of the Newton matrix.
    pub(crate) fn coupling_supports(
        &self,
        set: &ElasticSet,
        ops: &Operators,
        mut f: impl FnMut(&[u32]),
    ) {
        let mut support: Vec<u32> = Vec::new();
        for i in 0..set.free.len() {
            if !(set.free[i] && set.fit[i]) {
                continue;
            }
            support.clear();
            support.push(i as u32);
            support.extend(&self.nbr[self.ptr[i]..self.ptr[i + 1]]);
            if self.b[i] > 0.0 {
                let row = ops.lbar.outer_view(i).expect("row of a vertex");
                support.extend(row.indices().iter().map(|&k| k as u32));
            }
            support.sort_unstable();
            support.dedup();
            f(&support);
        }
        for el in &self.area {
            f(&el.v);
        }
    }
}
