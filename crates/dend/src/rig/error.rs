//! Why a rig could not be read or a pose fitted to it ([`RigError`]), in a
//! file of its own so that the rig's files import it from here and none
//! goes through `rig/mod.rs`, which re-exports their items
//! (docs/architecture.md, "Layering").

use thiserror::Error;

use crate::mesh::io::gltf::SkinError;
use crate::mesh::io::Format;

/// Why a rig could not be read or a pose fitted to it.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RigError {
    /// Only glTF/GLB assets carry skins.
    #[error("rigs come from glTF/GLB assets with a skin (this asset is {format})")]
    NotGltf {
        /// The asset's format.
        format: Format,
    },
    /// The skin is missing or broken.
    #[error(transparent)]
    Skin(#[from] SkinError),
    /// A joint selector names no joint of the skin.
    #[error("unknown joint {joint}: {}", describe_joints(.available))]
    UnknownJoint {
        /// The joint asked for.
        joint: String,
        /// The skin's joint names.
        available: Vec<String>,
    },
    /// Skeleton exports are glTF or GLB.
    #[error("a skeleton export is glTF or GLB (asked for {requested})")]
    ExportFormat {
        /// The format asked for.
        requested: Format,
    },
    /// A pose with another vertex count than the asset's welded surface.
    #[error("the pose has {got} vertices, the mesh has {expected}")]
    PoseSize {
        /// The welded vertex count.
        expected: usize,
        /// The pose's.
        got: usize,
    },
}

/// The list in [`RigError::UnknownJoint`]'s message.
pub fn describe_joints(available: &[String]) -> String {
    const SHOWN: usize = 40;
    if available.is_empty() {
        return "the asset has no skin".into();
    }
    let mut s = format!(
        "the skin has {}",
        available[..available.len().min(SHOWN)].join(", ")
    );
    if available.len() > SHOWN {
        s.push_str(&format!(" and {} more", available.len() - SHOWN));
    }
    s
}
