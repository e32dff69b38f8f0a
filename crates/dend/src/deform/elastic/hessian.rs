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
//!
//! **Assembly.** Each element's blocks are computed on their own
//! ([`blocks`]: `−Jᵀ C⁻¹ J` over the pairs of a vertex's support, the
//! area term's over a triangle's corners), each pair once (the matrix is
//! symmetric), in parallel; the Newton iteration then sums them into its
//! pattern by a plan made once per constraint set (`solver/newton_pattern.rs`).
//! Only the elements whose curvature is indefinite differ between
//! [`Curvature::Full`] and [`Curvature::Projected`], so where the exact
//! Hessian does not factor only theirs are computed again.

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

use super::area::{area_root, curvature as area_curvature};
use crate::mesh::Real;

pub(crate) mod blocks;
pub(crate) mod galerkin;

/// `[t]×`, the cross-product matrix: `[t]× v = t × v`.
fn cross_matrix(t: &Vector3<Real>) -> Matrix3<Real> {
    Matrix3::new(0.0, -t.z, t.y, t.z, 0.0, -t.x, -t.y, t.x, 0.0)
}

/// `|t|² I − t tᵀ = [t]×ᵀ [t]×`.
fn gram(t: &Vector3<Real>) -> Matrix3<Real> {
    Matrix3::identity() * t.norm_squared() - t * t.transpose()
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
    /// None of it (Gauss–Newton): the rotations' residuals held linear,
    /// and of the area term its normal only, as where its eigensystem is
    /// ill-conditioned. Positive semi-definite, and no element needs an
    /// eigensystem: the cheap model of a coarse correction's matrix
    /// (`galerkin.rs`).
    GaussNewton,
}

impl Curvature {
    /// What the area term keeps of its eigenvalue `lambda`: all of it, or
    /// its positive part (`NaN` as before: `−∞` or 0).
    fn keep(self, lambda: Real) -> Real {
        match self {
            Curvature::Full => lambda.max(Real::NEG_INFINITY),
            Curvature::Projected | Curvature::GaussNewton => lambda.max(0.0),
        }
    }
}

/// Whether the eigenvalue `lambda` is cut by [`Curvature::Projected`]
/// (negative or `NaN`): where an element has none, its blocks are the same
/// for both curvatures.
fn cut(lambda: Real) -> bool {
    lambda
        .partial_cmp(&0.0)
        .is_none_or(|o| o == std::cmp::Ordering::Less)
}

/// Whether the symmetric `m` is positive semi-definite by its principal
/// minors (`false` for `NaN`). Rounding may class a matrix with a
/// vanishing eigenvalue either way, so [`Curvature::Projected`] keeps what
/// this test passes as it is and takes [`positive_part`] of the rest:
/// either way within rounding of the exact part, and the same blocks as
/// [`Curvature::Full`] for every element the test passes.
fn semi_definite(m: &Matrix3<Real>) -> bool {
    let minor = |a: usize, b: usize| m[(a, a)] * m[(b, b)] - m[(a, b)] * m[(b, a)];
    m[(0, 0)] >= 0.0
        && m[(1, 1)] >= 0.0
        && m[(2, 2)] >= 0.0
        && minor(0, 1) >= 0.0
        && minor(0, 2) >= 0.0
        && minor(1, 2) >= 0.0
        && m.determinant() >= 0.0
}

/// One eigenpair of [`area_eigensystem`]: the eigenvalue and its unit
/// 3×2 eigenmatrix as two columns.
type AreaMode = (Real, [Vector3<Real>; 2]);

/// Half the Hessian in `F` of the area term's `‖F − P(F)‖²` (3×2, `P` the
/// nearest matrix with singular values `d, 1/d`), as six eigenpairs (module
/// docs; [`Curvature::keep`] cuts the eigenvalues); `None` where `F` is
/// nearly flat (`σ2 ≤ 10⁻⁴ σ1`) or its `d` is not a strict minimum.
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
fn area_eigensystem(f: &[Real; 6]) -> Option<[AreaMode; 6]> {
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
        (se.eigenvalues[k], [a0 + b0, a1 + b1])
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
        (turn, [h * (x0 - y0), h * (x1 - y1)]),
        (shear, [h * (x0 + y0), h * (x1 + y1)]),
        (1.0 - p[0] / s[0], outer(u2, v[0])),
        (1.0 - p[1] / s[1], outer(u2, v[1])),
    ])
}
