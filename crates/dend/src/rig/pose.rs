//! A solved pose as the rig's joint transforms ([`RigPose`]): the fitted
//! motions ([`super::fit`]) written as parent-relative TRS per joint node,
//! and the corrective shape that makes the skinned result the solved pose.
//!
//! **Local TRS.** Joint `j`'s posed global transform is
//! `G'_j = M_j · IBM_j⁻¹`; its parent node's `P'` is the parent joint's
//! `G'` (or, for nodes that are not joints, their parent's times their own
//! rest transform); the local transform is `L_j = P'⁻¹ G'_j`, written as
//! translation, the rotation nearest `L_j`'s linear part with the rest
//! scale divided out (polar decomposition, [`procrustes::rotation`]), and
//! the rest scale. A non-root joint's translation equals its rest one (the
//! fit keeps bone lengths) and is written as the rest value; a rotation
//! within `1e-9` rad of the rest one is written as the rest value, so
//! joints that did not move keep their rest transforms bit for bit.
//!
//! **Corrective.** The TRS are rounded to `f32` as a file stores them and
//! the skinning matrices `A_j = G_j · IBM_j` recomputed from them (what an
//! engine computes). A morph target `d_i` (bind space) is added before
//! skinning, so the engine draws `Σ_j w_ij A_j (v_i + d_i)
//! = f_i + L_i d_i` with `f_i = Σ w_ij A_j v_i` and `L_i = Σ w_ij lin(A_j)`;
//! hence `d_i = L_i⁻¹ (p_i − f_i)` reproduces the solved `p_i` exactly
//! (to `f32` rounding). Where `L_i` is singular (weights blending opposite
//! rotations to nothing), `d_i = p_i − f_i`.

use nalgebra::{Matrix3, Matrix4, Quaternion, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::error::RigError;
use super::fit::{fit_motions, FitOptions, Motions, Residual};
use super::procrustes;
use super::skeleton::Skeleton;
use crate::mesh::asset::Asset;
use crate::mesh::io::gltf::Trs;
use crate::mesh::Point;

/// Rotations closer than this (radians) to the rest one are written as
/// the rest one.
const SNAP_ANGLE: f64 = 1e-9;

/// A joint's local transform as written into its node (`f32`, as glTF
/// stores it; rotation `[x, y, z, w]`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct JointTrs {
    /// Translation.
    pub translation: [f32; 3],
    /// Rotation, a unit quaternion `[x, y, z, w]`.
    pub rotation: [f32; 4],
    /// Scale.
    pub scale: [f32; 3],
}

impl JointTrs {
    fn trs(&self) -> Trs {
        let [x, y, z, w] = self.rotation.map(f64::from);
        Trs {
            translation: Vector3::from(self.translation.map(f64::from)),
            rotation: UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
            scale: Vector3::from(self.scale.map(f64::from)),
        }
    }
}

/// A pose of the rig (module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct RigPose {
    /// Per joint (the skin's order), its node's local transform.
    pub joints: Vec<JointTrs>,
    /// Per joint, the skinning matrix `A_j = G_j · IBM_j` the written
    /// transforms give (bind space to posed space).
    pub skinning: Vec<Matrix4<f64>>,
    /// Per asset vertex, the corrective displacement (bind space).
    pub corrective: Vec<Point>,
    /// The skinned pose without the corrective against the solved pose.
    pub residual: Residual,
    /// Sweeps the fit took.
    pub sweeps: usize,
    /// Asset vertices whose weights were normalised.
    pub renormalised: usize,
}

/// Fits `skeleton` (of `asset`) to the welded `pose` of `asset`'s surface
/// (module documentation of [`crate::rig`]).
pub fn fit(
    asset: &Asset,
    skeleton: &Skeleton,
    pose: &[Point],
    opts: &FitOptions,
) -> Result<RigPose, RigError> {
    let expected = asset.mesh().num_vertices();
    if pose.len() != expected {
        return Err(RigError::PoseSize {
            expected,
            got: pose.len(),
        });
    }
    let pose = asset.asset_pose(pose).map_err(|_| RigError::PoseSize {
        expected,
        got: pose.len(),
    })?;
    let rest = asset.positions();
    let motions = fit_motions(skeleton, rest, &pose, opts);
    Ok(RigPose::new(skeleton, rest, &pose, &motions))
}

/// The bounding-box diagonal of `points` (1 for an empty or flat-zero set).
fn diagonal(points: &[Point]) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let d = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    if d > 0.0 && d.is_finite() {
        d
    } else {
        1.0
    }
}

/// `[R | t]` as a 4×4 matrix.
fn rigid(r: &Matrix3<f64>, t: &Vector3<f64>) -> Matrix4<f64> {
    let mut m = r.to_homogeneous();
    m.fixed_view_mut::<3, 1>(0, 3).copy_from(t);
    m
}

fn lin(m: &Matrix4<f64>) -> Matrix3<f64> {
    m.fixed_view::<3, 3>(0, 0).into_owned()
}

fn column(m: &Matrix4<f64>) -> Vector3<f64> {
    Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)])
}

/// Globals of every node, parents first: `fixed(k)` where it gives one,
/// else the parent's global times `local(k)`.
fn globals(
    sk: &Skeleton,
    fixed: &dyn Fn(usize) -> Option<Matrix4<f64>>,
    local: &dyn Fn(usize) -> Matrix4<f64>,
) -> Vec<Matrix4<f64>> {
    let s = &sk.skin;
    let n = s.node_locals.len();
    let mut out: Vec<Option<Matrix4<f64>>> = vec![None; n];
    for start in 0..n {
        // the chain up to a node already placed (bounded: no cycles)
        let mut chain = vec![start];
        while let Some(p) = s.node_parents[*chain.last().unwrap_or(&start)] {
            if out[p].is_some() || chain.contains(&p) {
                break;
            }
            chain.push(p);
        }
        for &k in chain.iter().rev() {
            if out[k].is_some() {
                continue;
            }
            let m = fixed(k).unwrap_or_else(|| {
                let parent = s.node_parents[k].and_then(|p| out[p]);
                parent.map_or(local(k), |p| p * local(k))
            });
            out[k] = Some(m);
        }
    }
    out.into_iter()
        .map(|m| m.unwrap_or_else(Matrix4::identity))
        .collect()
}

impl RigPose {
    fn new(sk: &Skeleton, rest: &[Point], pose: &[Point], m: &Motions) -> RigPose {
        let s = &sk.skin;
        let node_joint = |node: usize| sk.joints.iter().position(|j| j.node == node);
        let file = |k: usize| s.node_locals[k].matrix();
        // posed globals from the fitted motions
        let fitted: Vec<Matrix4<f64>> = (0..sk.joints.len())
            .map(|j| {
                let h = sk.joints[j].head;
                rigid(&m.rotations[j], &(m.heads[j] - m.rotations[j] * h)) * sk.joints[j].bind
            })
            .collect();
        let g = globals(sk, &|k| node_joint(k).map(|j| fitted[j]), &file);
        let diag = diagonal(rest);
        let joints: Vec<JointTrs> = (0..sk.joints.len())
            .map(|j| {
                let node = sk.joints[j].node;
                let parent = s.node_parents[node].map_or(Matrix4::identity(), |p| g[p]);
                let local = parent.try_inverse().unwrap_or_else(Matrix4::identity) * fitted[j];
                local_trs(
                    &s.joints[j].rest,
                    &local,
                    sk.joints[j].parent.is_some(),
                    diag,
                )
            })
            .collect();
        // what the written transforms give
        let g2 = globals(sk, &|_| None, &|k| {
            node_joint(k).map_or_else(|| file(k), |j| joints[j].trs().matrix())
        });
        let skinning: Vec<Matrix4<f64>> = (0..sk.joints.len())
            .map(|j| g2[sk.joints[j].node] * s.joints[j].inverse_bind)
            .collect();
        let mut corrective = Vec::with_capacity(rest.len());
        let (mut max, mut sum) = (0.0f64, 0.0);
        for (i, (v, p)) in rest.iter().zip(pose).enumerate() {
            let v = Vector3::from(*v).push(1.0);
            let (mut f, mut l) = (Vector3::zeros(), Matrix3::zeros());
            for &(j, w) in &s.influences[i] {
                let a = &skinning[j as usize];
                f += (a * v).xyz() * w;
                l += lin(a) * w;
            }
            let miss = Vector3::from(*p) - f;
            let dist = miss.norm();
            max = max.max(dist);
            sum += dist;
            let d = l.try_inverse().map_or(miss, |inv| inv * miss);
            corrective.push([d.x, d.y, d.z]);
        }
        let count = rest.len().max(1) as f64;
        RigPose {
            joints,
            skinning,
            corrective,
            residual: Residual {
                max: max / diag,
                mean: sum / count / diag,
            },
            sweeps: m.sweeps,
            renormalised: s.renormalised,
        }
    }
}

/// `local` as TRS: the rest scale kept, the rotation nearest the linear
/// part with the scale divided out, the translation (the rest one for a
/// joint with a parent joint, within `1e-6` of the diagonal); values
/// equal to the rest ones within [`SNAP_ANGLE`] are the rest ones.
fn local_trs(rest: &Trs, local: &Matrix4<f64>, has_parent: bool, diag: f64) -> JointTrs {
    let s = rest.scale;
    let unscaled =
        lin(local) * Matrix3::from_diagonal(&s.map(|x| if x != 0.0 { 1.0 / x } else { 1.0 }));
    let r = procrustes::rotation(&unscaled, &rest.rotation.to_rotation_matrix().into_inner());
    let mut q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    if q.angle_to(&rest.rotation) < SNAP_ANGLE {
        q = rest.rotation;
    } else if q.coords.dot(&rest.rotation.coords) < 0.0 {
        // the same rotation, on the rest one's side (animation blends)
        q = UnitQuaternion::new_unchecked(-q.into_inner());
    }
    let mut t = column(local);
    if has_parent && (t - rest.translation).norm() <= 1e-6 * diag {
        t = rest.translation;
    }
    let c = q.coords;
    JointTrs {
        translation: [t.x as f32, t.y as f32, t.z as f32],
        rotation: [c.x as f32, c.y as f32, c.z as f32, c.w as f32],
        scale: [s.x as f32, s.y as f32, s.z as f32],
    }
}
