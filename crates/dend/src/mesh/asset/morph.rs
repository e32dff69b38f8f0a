//! Welded poses exported as glTF morph targets on a glTF asset
//! ([`Asset::export_morph_targets`](super::Asset::export_morph_targets); the writing is
//! [`GltfAsset::export_morph_targets`](crate::mesh::io::gltf::GltfAsset::export_morph_targets)).

use thiserror::Error;

use crate::mesh::io::{Format, IoError};

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
