//! Solved poses written onto the asset's rig as glTF
//! ([`export_skeleton`]): per pose the fitted joint transforms
//! ([`super::fit`]) and, unless left out, the corrective as a morph target
//! (written by `GltfAsset::export_skeleton`).
//!
//! The corrective target's normals: engines skin a normal by the blended
//! matrix `L_i = Σ w_ij lin(A_j)` (three.js, Blender), so the target holds
//! `normalise(L_i⁻¹ n_i)` for the solved pose's normal `n_i` (the normals
//! [`Asset::export`] writes), and the skinned, morphed mesh shows the
//! solved pose's shading too.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::error::RigError;
use super::fit::{FitOptions, Residual};
use super::pose::{fit, RigPose};
use super::skeleton::Skeleton;
use crate::mesh::asset::Asset;
use crate::mesh::io::gltf::{Container, MorphTarget, NodeTrs, Shading, SkeletonPose};
use crate::mesh::io::Format;
use crate::mesh::Point;

/// What a skeleton export reports about each pose's fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseFit {
    /// The pose's name.
    pub name: String,
    /// The skinned pose without the corrective against the solved pose.
    pub residual: Residual,
    /// Sweeps the fit took.
    pub sweeps: usize,
}

/// A skeleton export: the file and each pose's fit.
#[derive(Debug, Clone)]
pub struct SkeletonExport {
    /// The glTF/GLB bytes.
    pub bytes: Vec<u8>,
    /// Per pose, in order.
    pub fits: Vec<PoseFit>,
    /// Asset vertices whose weights were normalised (a warning: the file's
    /// weights do not sum to one there).
    pub renormalised: usize,
}

/// The corrective of `pose` as a morph target named `name`: bind pose plus
/// corrective, and the solved pose's normals taken back to bind space.
fn corrective_target(
    asset: &Asset,
    sk: &Skeleton,
    name: &str,
    rig: &RigPose,
    solved: &[Point],
) -> Result<MorphTarget, RigError> {
    let asset_pose = asset.asset_pose(solved).map_err(|_| RigError::PoseSize {
        expected: asset.mesh().num_vertices(),
        got: solved.len(),
    })?;
    let posed = asset.gltf_pose_shading(&asset_pose);
    let rest = asset.positions();
    let pose: Vec<Point> = rest
        .iter()
        .zip(&rig.corrective)
        .map(|(v, d)| [v[0] + d[0], v[1] + d[1], v[2] + d[2]])
        .collect();
    let normals = posed
        .normals
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let n = Vector3::from((*n)?);
            let l: Matrix3<f64> = sk.influences()[i]
                .iter()
                .map(|&(j, w)| rig.skinning[j as usize].fixed_view::<3, 3>(0, 0) * w)
                .sum();
            let b = l.try_inverse()? * n;
            let len = b.norm();
            (len > 0.0 && len.is_finite()).then(|| [b.x / len, b.y / len, b.z / len])
        })
        .collect();
    Ok(MorphTarget {
        name: name.to_owned(),
        pose,
        shading: Shading {
            normals,
            tangents: Vec::new(),
        },
    })
}

/// The asset with `poses` (name, welded pose) fitted onto its rig, as
/// `format` (glTF or GLB): the first pose in the joint nodes, or with
/// `animation` every pose as a keyframe (see `GltfAsset::export_skeleton`);
/// with `corrective`, each pose's corrective as a morph target.
pub fn export_skeleton(
    asset: &Asset,
    poses: &[(String, &[Point])],
    animation: bool,
    corrective: bool,
    format: Format,
) -> Result<SkeletonExport, RigError> {
    let container = match format {
        Format::Glb => Container::Glb,
        Format::Gltf => Container::Json,
        requested => return Err(RigError::ExportFormat { requested }),
    };
    let g = asset.gltf().ok_or(RigError::NotGltf {
        format: asset.format(),
    })?;
    let sk = asset.skeleton()?;
    let mut out = Vec::with_capacity(poses.len());
    let mut fits = Vec::with_capacity(poses.len());
    for (name, pose) in poses {
        let rig = fit(asset, &sk, pose, &FitOptions::default())?;
        let nodes = sk
            .joints()
            .iter()
            .zip(&rig.joints)
            .map(|(j, t)| NodeTrs {
                node: j.node,
                translation: t.translation,
                rotation: t.rotation,
                scale: t.scale,
            })
            .collect();
        let target = if corrective {
            Some(corrective_target(asset, &sk, name, &rig, pose)?)
        } else {
            None
        };
        fits.push(PoseFit {
            name: name.clone(),
            residual: rig.residual,
            sweeps: rig.sweeps,
        });
        out.push(SkeletonPose {
            name: name.clone(),
            nodes,
            corrective: target,
        });
    }
    Ok(SkeletonExport {
        bytes: g.export_skeleton(&out, animation, container),
        fits,
        renormalised: sk.skin().renormalised,
    })
}
