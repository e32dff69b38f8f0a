//! Welded poses exported as glTF morph targets on a glTF asset
//! ([`Asset::export_morph_targets`]; the writing is
//! [`GltfAsset::export_morph_targets`](crate::mesh::io::gltf::GltfAsset::export_morph_targets)).

use thiserror::Error;

use super::{Asset, Source};
use crate::mesh::io::gltf::{Container, MorphTarget};
use crate::mesh::io::{Format, IoError};
use crate::mesh::Point;

/// Why poses could not be exported as morph targets.
#[derive(Debug, Error)]
pub enum MorphExportError {
    /// The asset was not read from glTF/GLB, or the format asked for is not
    /// glTF/GLB: morph targets exist only there. Fix: upload the mesh as
    /// glTF/GLB and export as `glb` or `gltf`.
    #[error("morph targets need a glTF/GLB asset exported as glb or gltf (the asset is {asset}, the export {requested})")]
    NotGltf {
        /// The asset's format.
        asset: Format,
        /// The format asked for.
        requested: Format,
    },
    /// A pose does not fit the welded surface.
    #[error(transparent)]
    Pose(#[from] IoError),
}

impl Asset {
    /// The asset as read plus one morph target per `(name, welded pose)`
    /// (each `#W×3`) on every deformed primitive, as `format` (glTF or GLB);
    /// with `animation`, an animation keying the weights through them in
    /// order. Normals of each pose are those [`Asset::export`] writes.
    pub fn export_morph_targets(
        &self,
        poses: &[(String, &[Point])],
        animation: bool,
        format: Format,
    ) -> Result<Vec<u8>, MorphExportError> {
        let container = match format {
            Format::Glb => Container::Glb,
            Format::Gltf => Container::Json,
            requested => {
                return Err(MorphExportError::NotGltf {
                    asset: self.format,
                    requested,
                })
            }
        };
        let Source::Gltf(g) = &self.source else {
            return Err(MorphExportError::NotGltf {
                asset: self.format,
                requested: format,
            });
        };
        let targets = poses
            .iter()
            .map(|(name, pose)| {
                let pose = self.asset_pose(pose)?;
                let shading = self.gltf_shading(g, &pose);
                Ok(MorphTarget {
                    name: name.clone(),
                    pose,
                    shading,
                })
            })
            .collect::<Result<Vec<_>, IoError>>()?;
        Ok(g.export_morph_targets(&targets, animation, container))
    }
}
