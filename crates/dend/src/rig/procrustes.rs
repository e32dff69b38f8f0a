//! The two weighted Procrustes problems the rig fit is made of.
//!
//! - [`rotation`]: `argmin_{R ∈ SO(3)} Σ_i |b_i − R a_i|²`, given the
//!   cross-covariance `B = Σ_i b_i a_iᵀ`: with `B = U Σ Vᵀ`,
//!   `R = U diag(1, 1, det(U Vᵀ)) Vᵀ` (Kabsch 1976; Umeyama 1991 for the
//!   reflection case).
//! - [`rigid`]: `argmin_{R, t} Σ_i |b_i − R a_i − s_i t|²` with per-point
//!   scalars `s_i` (the skinning weight of the bone being updated in Le and
//!   Deng 2012, "Smooth Skinning Decomposition with Rigid Bones", §4.2,
//!   eqs. 8–10): with `ā = Σ s_i a_i / Σ s_i²` and `b̄ = Σ s_i b_i / Σ s_i²`,
//!   `R` is [`rotation`] of `Σ (b_i − s_i b̄)(a_i − s_i ā)ᵀ` and
//!   `t = b̄ − R ā`. (For every `s_i = 1` this is the familiar centred
//!   Kabsch fit.)
//!
//! A covariance that does not pin the rotation down (all `a_i` on a line,
//! or no points: rank ≤ 1) is completed towards `prior` (`B + ε·prior`,
//! `ε` a small multiple of `|B|`), so an under-determined bone keeps the
//! rotation it had instead of taking an arbitrary one.

use nalgebra::{Matrix3, Vector3};

/// `ε` relative to the covariance's norm (module documentation).
const PRIOR: f64 = 1e-6;
/// A covariance whose second singular value is below this fraction of
/// its first has rank ≤ 1 and is completed by the prior.
const DEGENERATE: f64 = 1e-9;

/// `argmin_{R ∈ SO(3)} Σ |b_i − R a_i|²` for `cov = Σ b_i a_iᵀ`, completed
/// towards `prior` where `cov` does not determine it (module documentation).
pub fn rotation(cov: &Matrix3<f64>, prior: &Matrix3<f64>) -> Matrix3<f64> {
    let scale = cov.norm();
    if !(scale > 0.0 && scale.is_finite()) {
        return *prior;
    }
    let svd = cov.svd(false, false);
    let mut s = svd.singular_values;
    s.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
    // rank ≤ 1: turns about the one direction are free
    let b = if s[1] <= DEGENERATE * s[0] {
        cov + prior * (PRIOR * scale)
    } else {
        *cov
    };
    kabsch(&b).unwrap_or(*prior)
}

/// `U diag(1, 1, det(U Vᵀ)) Vᵀ` for `b = U Σ Vᵀ`.
fn kabsch(b: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    let svd = b.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        // flip the direction of the smallest singular value
        let k = svd.singular_values.imin();
        d[(k, k)] = -1.0;
    }
    let r = u * d * vt;
    r.iter().all(|v| v.is_finite()).then_some(r)
}

/// `argmin_{R, t} Σ |b_i − R a_i − s_i t|²` over `(a_i, b_i, s_i)`
/// (module documentation); `None` when every `s_i` is zero.
pub fn rigid(
    points: impl Iterator<Item = (Vector3<f64>, Vector3<f64>, f64)> + Clone,
    prior: &Matrix3<f64>,
) -> Option<(Matrix3<f64>, Vector3<f64>)> {
    let (mut sa, mut sb, mut ss) = (Vector3::zeros(), Vector3::zeros(), 0.0);
    for (a, b, s) in points.clone() {
        sa += a * s;
        sb += b * s;
        ss += s * s;
    }
    if ss <= 0.0 {
        return None;
    }
    let (abar, bbar) = (sa / ss, sb / ss);
    let mut cov = Matrix3::zeros();
    for (a, b, s) in points {
        cov += (b - bbar * s) * (a - abar * s).transpose();
    }
    let r = rotation(&cov, prior);
    Some((r, bbar - r * abar))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Unit};

    fn cloud() -> Vec<Vector3<f64>> {
        (0..20)
            .map(|i| {
                let t = i as f64;
                Vector3::new((t * 0.7).sin(), (t * 1.3).cos(), 0.1 * t - 1.0)
            })
            .collect()
    }

    #[test]
    fn rotation_recovers_a_known_rotation() {
        let axis = Unit::new_normalize(Vector3::new(1.0, -2.0, 0.5));
        let r = Rotation3::from_axis_angle(&axis, 2.5).into_inner();
        let mut cov = Matrix3::zeros();
        for a in cloud() {
            cov += (r * a) * a.transpose();
        }
        let got = rotation(&cov, &Matrix3::identity());
        assert!((got - r).norm() < 1e-12, "{got} vs {r}");
        assert!((got.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn rotation_never_reflects() {
        // b is a mirror image of a: the best proper rotation is not the mirror
        let mut cov = Matrix3::zeros();
        for a in cloud() {
            cov += Vector3::new(-a.x, a.y, a.z) * a.transpose();
        }
        let got = rotation(&cov, &Matrix3::identity());
        assert!((got.determinant() - 1.0).abs() < 1e-12);
        assert!((got * got.transpose() - Matrix3::identity()).norm() < 1e-12);
    }

    #[test]
    fn an_undetermined_rotation_keeps_the_prior() {
        // points on the z axis fix nothing about a turn around z
        let prior = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.7).into_inner();
        let mut cov = Matrix3::zeros();
        for k in 0..5 {
            let a = Vector3::new(0.0, 0.0, k as f64);
            cov += a * a.transpose();
        }
        let got = rotation(&cov, &prior);
        assert!((got - prior).norm() < 1e-6, "{got}");
        assert_eq!(rotation(&Matrix3::zeros(), &prior), prior);
    }

    #[test]
    fn rigid_with_weights_matches_the_exact_motion() {
        // b_i = s_i (R a_i + t) + (1 - s_i) c_i is not what rigid fits; the
        // identity it fits is b_i = R a_i + s_i t exactly
        let axis = Unit::new_normalize(Vector3::new(0.3, 1.0, -0.2));
        let r = Rotation3::from_axis_angle(&axis, -1.1).into_inner();
        let t = Vector3::new(0.5, -2.0, 3.0);
        let pts: Vec<_> = cloud()
            .into_iter()
            .enumerate()
            .map(|(i, a)| {
                let s = 0.2 + 0.04 * i as f64;
                (a, r * a + t * s, s)
            })
            .collect();
        let (got_r, got_t) = rigid(pts.iter().copied(), &Matrix3::identity()).unwrap();
        assert!((got_r - r).norm() < 1e-12);
        assert!((got_t - t).norm() < 1e-12);
        assert!(rigid(pts.iter().map(|&(a, b, _)| (a, b, 0.0)), &r).is_none());
    }

    #[test]
    fn rigid_is_the_least_squares_minimum() {
        // perturbing the optimum in any direction does not lower the cost
        let pts: Vec<_> = cloud()
            .into_iter()
            .enumerate()
            .map(|(i, a)| {
                let noise = Vector3::new((i as f64).sin(), (2.0 * i as f64).cos(), 0.3) * 0.05;
                (a, a.yzx() + noise, 0.5 + 0.02 * i as f64)
            })
            .collect();
        let (r, t) = rigid(pts.iter().copied(), &Matrix3::identity()).unwrap();
        let cost = |r: &Matrix3<f64>, t: &Vector3<f64>| {
            pts.iter()
                .map(|(a, b, s)| (b - r * a - t * *s).norm_squared())
                .sum::<f64>()
        };
        let best = cost(&r, &t);
        for k in 0..3 {
            let mut dt = Vector3::zeros();
            dt[k] = 1e-4;
            assert!(cost(&r, &(t + dt)) >= best);
            assert!(cost(&r, &(t - dt)) >= best);
            let mut w = Vector3::zeros();
            w[k] = 1e-4;
            let turn = Rotation3::new(w).into_inner();
            assert!(cost(&(turn * r), &t) >= best);
        }
    }
}
