//! The best rotation of a 3×3 covariance (orthogonal Procrustes), the kernel
//! of the local rotations `T_i` (design.md §6.4).
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
//!   step. [`fit_rotation_quat`] is the same iteration on unit quaternions,
//!   in scalar arithmetic with a short dependency chain (one division per
//!   step, Cramer's rule); the iteration keeps its rotations as quaternions
//!   (tube:10000: 1.74 → 0.88 ms of rotations per DEND iteration).
//!
//! Newton step (derivation): with `R' = exp([ω]ₓ) R` and `B = A Rᵀ`,
//! `tr(R'ᵀ A) ≈ tr B + g·ω − ½ ωᵀ H ω` where `g = Σ_c r_c × a_c`
//! (`r_c`, `a_c` the columns of `R`, `A`) and `H = tr(B) I − sym(B)`. So
//! `ω = H⁻¹ g` when `H` is positive definite; Müller's step replaces `H` by
//! `|tr B| I`. At the maximum `B` is symmetric and `H` positive
//! (semi-)definite, so the iteration converges quadratically from a nearby
//! guess, which is what an iteration of DEND provides.

use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion};

use crate::mesh::Real;

pub(super) mod lanes;

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
/// Allocation-free; the result is a proper rotation to rounding. The
/// rotation-matrix face of [`fit_rotation_quat`].
pub fn fit_rotation(a: &Matrix3<Real>, guess: &Matrix3<Real>) -> Matrix3<Real> {
    if a.iter().all(|&v| v == 0.0) {
        return *guess;
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(*guess));
    fit_rotation_quat(a, &q).to_rotation_matrix().into_inner()
}

/// [`fit_rotation`] on unit quaternions: the guess and the result (the
/// form [`super::local_rotations`] keeps between iterations, so that no
/// rotation matrix is converted back to a quaternion). Each Newton step
/// works on the 3×3 `B = A R(q)ᵀ` with scalar arithmetic: `g` and `H` are
/// read off `B`, and `H ω = g` is solved by Cramer's rule, with
/// Sylvester's criterion as the test of positive definiteness.
pub fn fit_rotation_quat(a: &Matrix3<Real>, guess: &UnitQuaternion<Real>) -> UnitQuaternion<Real> {
    // ω = H⁻¹ g does not depend on the scale of A, so A is not normalised;
    // only the rare non-Newton branches need its scale
    let (mut finite, mut zero) = (true, true);
    for &v in a.iter() {
        finite &= v.is_finite();
        zero &= v == 0.0;
    }
    if !finite {
        return UnitQuaternion::identity();
    }
    if zero {
        return *guess;
    }
    let g0 = guess.quaternion();
    let mut q = [g0.w, g0.i, g0.j, g0.k];
    for _ in 0..MAX_NEWTON {
        let r = quat_to_rows(&q);
        // B = A Rᵀ: b[i][j] = row i of A · row j of R
        let mut b = [[0.0; 3]; 3];
        for (i, bi) in b.iter_mut().enumerate() {
            for (j, bij) in bi.iter_mut().enumerate() {
                *bij = a[(i, 0)] * r[j][0] + a[(i, 1)] * r[j][1] + a[(i, 2)] * r[j][2];
            }
        }
        let g = [b[2][1] - b[1][2], b[0][2] - b[2][0], b[1][0] - b[0][1]];
        let tr = b[0][0] + b[1][1] + b[2][2];
        let h = [
            tr - b[0][0],
            tr - b[1][1],
            tr - b[2][2],
            -0.5 * (b[0][1] + b[1][0]),
            -0.5 * (b[0][2] + b[2][0]),
            -0.5 * (b[1][2] + b[2][1]),
        ];
        let (omega, is_newton) = match solve_spd3(&h, &g) {
            Some(w) => (w, true),
            None => {
                let scale = a.abs().max();
                (g.map(|v| v / (tr.abs() + 1e-12 * scale)), false)
            }
        };
        let angle2 = omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2];
        if is_newton && angle2 < CONVERGED_STEP * CONVERGED_STEP {
            // H is positive definite here, so this is a maximum, and the
            // quadratic convergence leaves an error of ~angle² after the step
            return to_unit(retract(&q, &omega));
        }
        if angle2.is_nan() || angle2 < 1e-26 {
            // converged (or NaN): accept only a maximum (H positive semi-definite)
            let hm = Matrix3::new(h[0], h[3], h[4], h[3], h[1], h[5], h[4], h[5], h[2]);
            if angle2.is_finite() && hm.symmetric_eigenvalues().min() > -1e-9 * a.abs().max() {
                return to_unit(q);
            }
            break;
        }
        // limit the step to a quarter turn: far from the maximum the
        // quadratic model is poor
        const MAX_STEP: Real = std::f64::consts::FRAC_PI_2;
        if angle2 > MAX_STEP * MAX_STEP {
            let f = MAX_STEP / angle2.sqrt();
            q = retract(&q, &omega.map(|v| v * f));
        } else {
            q = retract(&q, &omega);
        }
    }
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
        rotation_from_covariance(&a.transpose()),
    ))
}

/// The rows of the rotation matrix of the unit quaternion `q = (w, x, y, z)`.
#[inline(always)]
fn quat_to_rows(q: &[Real; 4]) -> [[Real; 3]; 3] {
    let [w, x, y, z] = *q;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, xz, yz) = (x * y, x * z, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    [
        [1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)],
        [2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)],
        [2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)],
    ]
}

/// `H⁻¹ g` for the symmetric `H = [h00, h11, h22, h01, h02, h12]`, or
/// `None` unless `H` is positive definite (Sylvester's criterion: its
/// leading minors are positive) and the result finite. Cramer's rule: the
/// cofactors are independent of one another and there is one division, a
/// short dependency chain for the out-of-order core.
#[inline(always)]
fn solve_spd3(h: &[Real; 6], g: &[Real; 3]) -> Option<[Real; 3]> {
    let [h00, h11, h22, h01, h02, h12] = *h;
    // cofactors (adjugate of a symmetric matrix)
    let c00 = h11 * h22 - h12 * h12;
    let c01 = h02 * h12 - h01 * h22;
    let c02 = h01 * h12 - h02 * h11;
    let c11 = h00 * h22 - h02 * h02;
    let c12 = h01 * h02 - h00 * h12;
    let c22 = h00 * h11 - h01 * h01;
    let det = h00 * c00 + h01 * c01 + h02 * c02;
    if !(h00 > 0.0 && c22 > 0.0 && det > 0.0) {
        return None;
    }
    let inv = 1.0 / det;
    let w = [
        (c00 * g[0] + c01 * g[1] + c02 * g[2]) * inv,
        (c01 * g[0] + c11 * g[1] + c12 * g[2]) * inv,
        (c02 * g[0] + c12 * g[1] + c22 * g[2]) * inv,
    ];
    w.iter().all(|v| v.is_finite()).then_some(w)
}

#[inline(always)]
fn to_unit(q: [Real; 4]) -> UnitQuaternion<Real> {
    UnitQuaternion::new_unchecked(Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// A Newton step this short ends the iteration (after being taken).
const CONVERGED_STEP: Real = 1e-7;

/// `q` moved by the rotation vector `ω`: `normalise((1, ω/2) q)`, a
/// retraction on SO(3) (first-order exact: its rotation angle is
/// `2 atan(|ω|/2) = |ω| + O(|ω|³)`), which keeps Riemannian Newton's
/// quadratic convergence (Absil, Mahony & Sepulchre 2008, Thm. 6.3.2)
/// without the trigonometric functions of `exp`.
#[inline(always)]
fn retract(q: &[Real; 4], omega: &[Real; 3]) -> [Real; 4] {
    let [w, x, y, z] = *q;
    let [a, b, c] = omega.map(|v| 0.5 * v);
    // (1, a, b, c) ⊗ (w, x, y, z)
    let p = [
        w - a * x - b * y - c * z,
        x + a * w + b * z - c * y,
        y + b * w + c * x - a * z,
        z + c * w + a * y - b * x,
    ];
    let inv = 1.0 / (p[0] * p[0] + p[1] * p[1] + p[2] * p[2] + p[3] * p[3]).sqrt();
    p.map(|v| v * inv)
}

/// `argmax_{R ∈ SO(3)} tr(Rᵀ A)` from a cold start (the SVD).
pub fn best_rotation(a: &Matrix3<Real>) -> Matrix3<Real> {
    rotation_from_covariance(&a.transpose())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Unit, Vector3};
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
        /// `solve_spd3` against nalgebra's Cholesky: the same verdict on
        /// definiteness (away from the boundary) and the same solution.
        #[test]
        fn spd3_solve_matches_cholesky(
            e in proptest::collection::vec(-2.0f64..2.0, 6),
            g in proptest::collection::vec(-1.0f64..1.0, 3),
        ) {
            let h = [e[0], e[1], e[2], e[3], e[4], e[5]];
            let m = Matrix3::new(h[0], h[3], h[4], h[3], h[1], h[5], h[4], h[5], h[2]);
            let gv = Vector3::new(g[0], g[1], g[2]);
            let lmin = m.symmetric_eigenvalues().min();
            let ours = solve_spd3(&h, &[g[0], g[1], g[2]]);
            if lmin > 1e-6 {
                let w = ours.expect("positive definite");
                let w2 = m.cholesky().unwrap().solve(&gv);
                let err = (Vector3::new(w[0], w[1], w[2]) - w2).norm();
                prop_assert!(err <= 1e-9 * (1.0 + w2.norm()) / lmin, "{:?} vs {}", w, w2);
            } else if lmin < -1e-6 {
                prop_assert!(ours.is_none(), "indefinite H accepted: {:?}", h);
            }
        }

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
