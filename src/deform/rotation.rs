//! The best rotation of a 3×3 covariance (orthogonal Procrustes), the kernel
//! of the local rotations `T_i` (dend.md §8.2).
//!
//! Two solvers of the same problem, `max_{R ∈ SO(3)} tr(Rᵀ A)`:
//! - [`rotation_from_covariance`] / [`best_rotation`]: the closed form
//!   through the SVD (Kabsch 1976, Umeyama 1991), from no guess at all;
//! - [`fit_rotation`]: Newton's method on SO(3) warm-started from a guess
//!   (the previous iteration's `T_i`), with Müller et al.'s 2016 step ("A
//!   robust method to extract the rotational part of deformations") where
//!   the Newton model is not concave, and the SVD as the last resort. In
//!   the DEND iteration it takes ~2 Newton steps per vertex and cut the
//!   rotations' share of an iteration from ~50 % to ~19 % (docs/performance.md).
//!   Steps are taken by a trigonometry-free retraction ([`retract`]), and a
//!   Newton step below `1e-7` rad ends the iteration without a confirming
//!   step.
//!
//! Newton step (derivation): with `R' = exp([ω]ₓ) R` and `B = A Rᵀ`,
//! `tr(R'ᵀ A) ≈ tr B + g·ω − ½ ωᵀ H ω` where `g = Σ_c r_c × a_c`
//! (`r_c`, `a_c` the columns of `R`, `A`) and `H = tr(B) I − sym(B)`. So
//! `ω = H⁻¹ g` when `H` is positive definite; Müller's step replaces `H` by
//! `|tr B| I`. At the maximum `B` is symmetric and `H` positive
//! (semi-)definite, so the iteration converges quadratically from a nearby
//! guess, which is what an iteration of DEND provides.

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};

use crate::mesh::Real;

/// Newton iterations before falling back to the SVD.
const MAX_NEWTON: usize = 12;

/// The rotation `R = V Uᵀ` maximising `tr(R S)` for `S = U Σ Vᵀ`, with the
/// sign of the smallest singular direction flipped if needed (`det R = +1`).
/// Equivalently `argmax tr(Rᵀ Sᵀ)`.
pub fn rotation_from_covariance(s: &Matrix3<Real>) -> Matrix3<Real> {
    let svd = s.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let mut r = vt.transpose() * u.transpose();
    if r.determinant() < 0.0 {
        // flip the column of U with the smallest singular value
        let (mut kmin, mut smin) = (0, Real::INFINITY);
        for k in 0..3 {
            if svd.singular_values[k] < smin {
                smin = svd.singular_values[k];
                kmin = k;
            }
        }
        let mut u2 = u;
        u2.column_mut(kmin).neg_mut();
        r = vt.transpose() * u2.transpose();
    }
    if r.iter().all(|v| v.is_finite()) {
        r
    } else {
        Matrix3::identity()
    }
}

/// `argmax_{R ∈ SO(3)} tr(Rᵀ A)` by Newton's method from `guess` (module
/// docs). Falls back to [`rotation_from_covariance`]`(Aᵀ)` when Newton does
/// not converge within a few iterations or converges to a non-maximum.
/// Allocation-free; the result is a proper rotation to rounding.
pub fn fit_rotation(a: &Matrix3<Real>, guess: &Matrix3<Real>) -> Matrix3<Real> {
    let scale = a.abs().max();
    if !(scale.is_finite()) {
        return Matrix3::identity();
    }
    if scale == 0.0 {
        return *guess;
    }
    let a = a / scale;
    let mut q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*guess));
    for _ in 0..MAX_NEWTON {
        let r = q.to_rotation_matrix().into_inner();
        let b = a * r.transpose();
        let g = r.column(0).cross(&a.column(0))
            + r.column(1).cross(&a.column(1))
            + r.column(2).cross(&a.column(2));
        let tr = b.trace();
        let h = Matrix3::identity() * tr - 0.5 * (b + b.transpose());
        let newton = h.cholesky().map(|c| c.solve(&g));
        let (omega, is_newton) = match newton {
            Some(w) if w.iter().all(|v| v.is_finite()) => (w, true),
            _ => (g / (tr.abs() + 1e-12), false),
        };
        let angle = omega.norm();
        if is_newton && angle < CONVERGED_STEP {
            // H is positive definite here, so this is a maximum, and the
            // quadratic convergence leaves an error of ~angle² after the step
            return retract(&q, &omega).to_rotation_matrix().into_inner();
        }
        if angle < 1e-13 {
            // converged: accept only a maximum (H positive semi-definite)
            if h.cholesky().is_some() || h.symmetric_eigenvalues().min() > -1e-9 {
                return q.to_rotation_matrix().into_inner();
            }
            break;
        }
        // limit the step to a quarter turn: far from the maximum the
        // quadratic model is poor
        let step = angle.min(std::f64::consts::FRAC_PI_2);
        q = retract(&q, &(omega * (step / angle)));
    }
    rotation_from_covariance(&a.transpose())
}

/// A Newton step this short ends the iteration (after being taken).
const CONVERGED_STEP: Real = 1e-7;

/// `q` moved by the rotation vector `ω`: `normalise((1, ω/2) q)`, a
/// retraction on SO(3) (first-order exact: its rotation angle is
/// `2 atan(|ω|/2) = |ω| + O(|ω|³)`), which keeps Riemannian Newton's
/// quadratic convergence (Absil, Mahony & Sepulchre 2008, Thm. 6.3.2)
/// without the trigonometric functions of `exp`.
#[inline]
fn retract(q: &UnitQuaternion<Real>, omega: &Vector3<Real>) -> UnitQuaternion<Real> {
    let d = Quaternion::new(1.0, 0.5 * omega.x, 0.5 * omega.y, 0.5 * omega.z);
    UnitQuaternion::new_normalize(d * q.into_inner())
}

/// `argmax_{R ∈ SO(3)} tr(Rᵀ A)` from a cold start (the SVD).
pub fn best_rotation(a: &Matrix3<Real>) -> Matrix3<Real> {
    rotation_from_covariance(&a.transpose())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Unit;
    use proptest::prelude::*;

    fn mat(v: &[f64]) -> Matrix3<f64> {
        Matrix3::from_row_slice(v)
    }

    fn objective(r: &Matrix3<f64>, a: &Matrix3<f64>) -> f64 {
        (r.transpose() * a).trace()
    }

    fn is_rotation(r: &Matrix3<f64>) -> bool {
        (r.transpose() * r - Matrix3::identity()).norm() < 1e-10
            && (r.determinant() - 1.0).abs() < 1e-10
    }

    #[test]
    fn hand_computed_cases() {
        // A = a rotation about z by 90°: the answer is A itself, from identity
        let rz = mat(&[0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        let r = fit_rotation(&rz, &Matrix3::identity());
        assert!((r - rz).norm() < 1e-12, "{r}");
        // A = diag(2, 1, -0.5): a reflection-free best rotation is diag(1, 1, 1)?
        // tr(Rᵀ A) over SO(3): identity gives 2.5; rotating 180° about x gives
        // 2 - 1 + 0.5 = 1.5; about y gives -2 + 1 ... so identity.
        let d = mat(&[2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -0.5]);
        let r = fit_rotation(&d, &Matrix3::identity());
        assert!((r - Matrix3::identity()).norm() < 1e-12, "{r}");
        // zero covariance keeps the guess; NaN gives the identity
        let g = rz;
        assert_eq!(fit_rotation(&Matrix3::zeros(), &g), g);
        let nan = Matrix3::from_element(f64::NAN);
        assert_eq!(fit_rotation(&nan, &g), Matrix3::identity());
    }

    #[test]
    fn planar_covariance_has_a_unique_rotation() {
        // rank-2 A (a flat ring): R q in the plane, the answer is a proper rotation
        let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), 2.5).into_inner();
        let flat = mat(&[1.3, 0.2, 0.0, 0.2, 0.7, 0.0, 0.0, 0.0, 0.0]);
        let a = rot * flat;
        let r = fit_rotation(&a, &Matrix3::identity());
        let r_svd = best_rotation(&a);
        assert!(is_rotation(&r));
        assert!((objective(&r, &a) - objective(&r_svd, &a)).abs() < 1e-12);
        assert!((r - rot).norm() < 1e-9, "{r} vs {rot}");
    }

    proptest! {
        /// Independent check: the SVD's closed form and Newton from an
        /// arbitrary guess reach the same maximum of tr(Rᵀ A).
        #[test]
        fn newton_matches_the_svd(
            e in proptest::collection::vec(-3.0f64..3.0, 9),
            axis in proptest::collection::vec(-1.0f64..1.0, 3),
            angle in -3.1f64..3.1,
            rank in 1usize..4,
        ) {
            let mut a = Matrix3::from_row_slice(&e);
            if rank < 3 {
                // project the covariance to rank 2 (flat ring) or 1 (a line)
                let svd = a.svd(true, true);
                let mut s = svd.singular_values;
                for k in rank..3 { s[k] = 0.0; }
                a = svd.u.unwrap() * Matrix3::from_diagonal(&s) * svd.v_t.unwrap();
            }
            let ax = Vector3::new(axis[0], axis[1], axis[2] + 1e-3);
            let guess = Rotation3::from_axis_angle(&Unit::new_normalize(ax), angle).into_inner();
            let r = fit_rotation(&a, &guess);
            let r_svd = best_rotation(&a);
            prop_assert!(is_rotation(&r), "{}", r);
            let (f, f_svd) = (objective(&r, &a), objective(&r_svd, &a));
            prop_assert!(f >= f_svd - 1e-9 * (1.0 + a.norm()), "newton {} < svd {}", f, f_svd);
            if rank == 3 {
                // the full-rank maximum is unique (up to a degenerate smallest singular pair)
                let sv = a.singular_values();
                let mut s: Vec<f64> = sv.iter().cloned().collect();
                s.sort_by(f64::total_cmp);
                if s[0] + s[1] > 1e-3 && s[1] - s[0] > 1e-3 {
                    prop_assert!((r - r_svd).norm() < 1e-6, "{} vs {}", r, r_svd);
                }
            }
        }
    }
}
