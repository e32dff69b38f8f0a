//! The rigid motion of a handle ([`RigidTransform`]: target, drag deltas,
//! fractions for `--steps`, from a 4x4 matrix) and the rotations of the
//! constraints JSON ([`RotationSpec`]).

use nalgebra::{Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};

use crate::deform::error::DeformError;
use crate::mesh::selection::RotationSpec;
use crate::mesh::Point;

/// A rigid handle target `p' = pivot + R (p - pivot) + translation`
/// (mesh units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidTransform {
    /// The rotation `R`.
    pub rotation: UnitQuaternion<f64>,
    /// The translation, applied after the rotation.
    pub translation: Point,
    /// The rotation centre (a handle's rest centroid unless given).
    pub pivot: Point,
}

impl RigidTransform {
    /// The identity about `pivot`.
    pub fn identity(pivot: Point) -> Self {
        RigidTransform {
            rotation: UnitQuaternion::identity(),
            translation: [0.0; 3],
            pivot,
        }
    }

    /// `pivot + R (p - pivot) + translation`.
    pub fn apply(&self, p: Point) -> Point {
        let v = Vector3::new(
            p[0] - self.pivot[0],
            p[1] - self.pivot[1],
            p[2] - self.pivot[2],
        );
        let r = self.rotation * v;
        [
            self.pivot[0] + r.x + self.translation[0],
            self.pivot[1] + r.y + self.translation[1],
            self.pivot[2] + r.z + self.translation[2],
        ]
    }

    /// Composes a drag delta: rotate by `d_rotation` about the handle's
    /// *current* pivot (`pivot + translation`), then translate by
    /// `d_translation`. In closed form `R ← dR·R`, `t ← t + dt`, so applying
    /// deltas one by one equals applying their composition.
    pub fn then(&self, d_rotation: UnitQuaternion<f64>, d_translation: Point) -> Self {
        RigidTransform {
            rotation: d_rotation * self.rotation,
            translation: [
                self.translation[0] + d_translation[0],
                self.translation[1] + d_translation[1],
                self.translation[2] + d_translation[2],
            ],
            pivot: self.pivot,
        }
    }

    /// The fraction `s ∈ [0, 1]` of this transform: rotation angle and
    /// translation scaled by `s` about the same pivot (for `--steps`).
    /// The angle is read from the quaternion as stored, in `[0°, 360°]`
    /// (`2 atan2(|v|, w)`), so a 300° rotation is split into 300° / N steps;
    /// `slerp` would take the short way (−60° in total).
    pub fn fraction(&self, s: f64) -> Self {
        let q = self.rotation.quaternion();
        let angle = 2.0 * q.vector().norm().atan2(q.w);
        let rotation = match Unit::try_new(q.vector().into_owned(), 1e-300) {
            Some(axis) => UnitQuaternion::from_axis_angle(&axis, s * angle),
            None => UnitQuaternion::identity(),
        };
        RigidTransform {
            rotation,
            translation: [
                self.translation[0] * s,
                self.translation[1] * s,
                self.translation[2] * s,
            ],
            pivot: self.pivot,
        }
    }

    /// From a 4×4 affine matrix (row-major, column vectors: `p' = M p`) whose
    /// 3×3 block is a rotation (orthonormalised by polar decomposition),
    /// re-expressed about `pivot`.
    pub fn from_matrix(m: &[[f64; 4]; 4], pivot: Point) -> Result<Self, DeformError> {
        if m.iter().flatten().any(|v| !v.is_finite()) {
            return Err(DeformError::NonFinite {
                what: "handle transform",
            });
        }
        let a = Matrix3::new(
            m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
        );
        let svd = a.svd(true, true);
        let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
        let mut r = u * vt;
        if r.determinant() < 0.0 {
            return Err(DeformError::InvalidTransform {
                reason: "the 3x3 block is a reflection",
            });
        }
        r = Rotation3::from_matrix_unchecked(r).into_inner();
        let q = UnitQuaternion::from_matrix(&r);
        // canonical sign (w ≥ 0): the angle `fraction` reads is then ≤ 180°
        let rotation = if q.w < 0.0 {
            UnitQuaternion::new_unchecked(-q.into_inner())
        } else {
            q
        };
        // p' = R p + t = pivot + R (p - pivot) + (R pivot + t - pivot)
        let c = Vector3::from(pivot);
        let t = Vector3::new(m[0][3], m[1][3], m[2][3]);
        let tr = rotation * c + t - c;
        Ok(RigidTransform {
            rotation,
            translation: [tr.x, tr.y, tr.z],
            pivot,
        })
    }
}

impl RotationSpec {
    /// The rotation as a unit quaternion; rejects NaN and zero axes.
    pub fn to_quaternion(&self) -> Result<UnitQuaternion<f64>, DeformError> {
        match self {
            RotationSpec::AxisAngle { axis, degrees } => {
                if !axis.iter().chain([degrees]).all(|v| v.is_finite()) {
                    return Err(DeformError::NonFinite { what: "rotation" });
                }
                if *degrees == 0.0 {
                    return Ok(UnitQuaternion::identity());
                }
                let a = Vector3::from(*axis);
                if a.norm() == 0.0 {
                    return Err(DeformError::InvalidTransform {
                        reason: "rotation axis is zero",
                    });
                }
                Ok(UnitQuaternion::from_axis_angle(
                    &Unit::new_normalize(a),
                    degrees.to_radians(),
                ))
            }
            RotationSpec::Quaternion { quaternion: q }
            | RotationSpec::QuaternionWxyz { quaternion_wxyz: q } => {
                if !q.iter().all(|v| v.is_finite()) {
                    return Err(DeformError::NonFinite { what: "rotation" });
                }
                // nalgebra's constructor takes (w, x, y, z)
                let quat = match self {
                    RotationSpec::Quaternion { .. } => {
                        nalgebra::Quaternion::new(q[3], q[0], q[1], q[2])
                    }
                    _ => nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]),
                };
                if quat.norm() == 0.0 {
                    return Err(DeformError::InvalidTransform {
                        reason: "quaternion is zero",
                    });
                }
                Ok(UnitQuaternion::from_quaternion(quat))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn composing_deltas_equals_applying_them_in_turn() {
        let t0 = RigidTransform::identity([1.0, 2.0, 3.0]);
        let d1 = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3);
        let d2 = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -0.7);
        let t = t0.then(d1, [0.5, 0.0, 0.0]).then(d2, [0.0, 1.0, -1.0]);
        // apply step by step: each delta rotates about the current pivot
        let p = [4.0, -1.0, 2.0];
        let step = |q: Point, d: UnitQuaternion<f64>, c: Point, dt: Point| {
            let v = d * Vector3::new(q[0] - c[0], q[1] - c[1], q[2] - c[2]);
            [c[0] + v.x + dt[0], c[1] + v.y + dt[1], c[2] + v.z + dt[2]]
        };
        let q1 = step(p, d1, [1.0, 2.0, 3.0], [0.5, 0.0, 0.0]);
        let q2 = step(q1, d2, [1.5, 2.0, 3.0], [0.0, 1.0, -1.0]);
        let got = t.apply(p);
        for k in 0..3 {
            assert!((got[k] - q2[k]).abs() < 1e-12, "{got:?} vs {q2:?}");
        }
    }

    #[test]
    fn from_matrix_reexpresses_about_the_pivot() {
        let r = Rotation3::from_axis_angle(&Vector3::y_axis(), 2.0);
        let m = r.matrix();
        let mat = [
            [m[(0, 0)], m[(0, 1)], m[(0, 2)], 1.0],
            [m[(1, 0)], m[(1, 1)], m[(1, 2)], -2.0],
            [m[(2, 0)], m[(2, 1)], m[(2, 2)], 0.5],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let t = RigidTransform::from_matrix(&mat, [3.0, 1.0, -1.0]).unwrap();
        let p = [0.2, 0.7, 9.0];
        let want = r * Vector3::from(p) + Vector3::new(1.0, -2.0, 0.5);
        let got = t.apply(p);
        for k in 0..3 {
            assert!((got[k] - want[k]).abs() < 1e-12);
        }
        // half the transform, twice, is the whole (same pivot, linear translation)
        let h = t.fraction(0.5);
        assert!((h.rotation.angle() - 1.0).abs() < 1e-12);
        // a 300° rotation is split the long way: a fifth is +60° about +z
        let q = RotationSpec::AxisAngle {
            axis: [0.0, 0.0, 1.0],
            degrees: 300.0,
        }
        .to_quaternion()
        .unwrap();
        let fifth = RigidTransform {
            rotation: q,
            translation: [0.0; 3],
            pivot: [0.0; 3],
        }
        .fraction(0.2);
        let a = fifth.rotation.scaled_axis();
        assert!((a.z - 60f64.to_radians()).abs() < 1e-12, "{a:?}");
    }

    #[test]
    fn quaternions_are_xyzw_unless_named_wxyz() {
        let axis_angle = RotationSpec::AxisAngle {
            axis: [0.0, 0.0, 1.0],
            degrees: 90.0,
        }
        .to_quaternion()
        .unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let xyzw: RotationSpec =
            serde_json::from_str(&format!("{{\"quaternion\": [0, 0, {h}, {h}]}}")).unwrap();
        let wxyz: RotationSpec =
            serde_json::from_str(&format!("{{\"quaternion_wxyz\": [{h}, 0, 0, {h}]}}")).unwrap();
        for r in [xyzw, wxyz] {
            assert!(
                r.to_quaternion().unwrap().angle_to(&axis_angle) < 1e-12,
                "{r:?}"
            );
        }
        // [w, x, y, z] under the plain name is another rotation
        let wrong: RotationSpec =
            serde_json::from_str(&format!("{{\"quaternion\": [{h}, 0, 0, {h}]}}")).unwrap();
        assert!(wrong.to_quaternion().unwrap().angle_to(&axis_angle) > 0.5);
    }
}
