//! glTF 2.0: `.gltf` (JSON, with base64 data-URI or side-car buffers) and
//! `.glb` (binary), read through the `gltf` crate's document model and
//! validation, written by editing the document as JSON.
//!
//! # What is read
//! - **The scene**: the default scene (`scene`), else the first scene, else
//!   every node that is nobody's child. Every node with a mesh contributes its
//!   primitives, placed by the node's world matrix (the product of the
//!   transforms from the root). **All these meshes are deformed together, as
//!   one surface**: the solver sees their union (welded as [`crate::mesh::asset`]
//!   documents), so a constraint on one part moves the parts connected to it,
//!   and separate parts are separate components. Meshes not reached from the
//!   scene are copied unchanged. Skinned meshes ignore their node's transform
//!   (glTF 2.0 §3.7.3) and are deformed in mesh space, their bind pose.
//! - **Primitives**: mode TRIANGLES only; indices `u8`, `u16`, `u32` or none
//!   (then consecutive triples); POSITION `f32` VEC3; NORMAL (`f32` VEC3) and
//!   TANGENT (`f32` VEC4) if present. A node whose world matrix has a negative
//!   determinant has its triangles' winding reversed for the solver, as
//!   renderers do.
//! - **Refused with a [`GltfError`]** (never a panic): other modes (points,
//!   lines, strips, fans), sparse POSITION/NORMAL/TANGENT/index accessors,
//!   accessors without a bufferView, non-`f32` positions (quantization),
//!   Draco and meshopt compression (`KHR_draco_mesh_compression`,
//!   `EXT_meshopt_compression`, `KHR_mesh_quantization`,
//!   `EXT_mesh_gpu_instancing` named in `extensionsUsed`/`extensionsRequired`),
//!   a mesh placed by two nodes (instancing: one pose cannot be written back
//!   to both), singular node matrices, index values past the POSITION count,
//!   buffers shorter than their `byteLength`, accessors or views outside
//!   their buffer, side-car buffers when no folder is given.
//! - **Passed through unchanged**: morph targets (their displacements then
//!   apply on top of the posed base mesh), skins (`JOINTS_n`/`WEIGHTS_n`,
//!   inverse bind matrices), UVs, colours, materials, textures, images,
//!   animations, cameras, other extensions and extras.
//!
//! # What is written
//! See [`GltfAsset::export`]: the deformed positions go back into the
//! file's own POSITION accessors in local coordinates (world → local by the
//! inverse node matrix), normals and tangents into NORMAL/TANGENT; buffers are
//! merged into one. A plain mesh is written by [`write_mesh`].

mod accessor;
mod asset;
mod container;
mod error;
mod morph;
mod read;
mod skeleton;
mod skin;
mod write;

pub use asset::{Container, GltfAsset, GltfSummary, PrimitivePart};
pub use container::Sidecars;
pub use error::GltfError;
pub use morph::MorphTarget;
pub use skeleton::{NodeTrs, SkeletonPose};
pub use skin::{SkinData, SkinError, SkinJoint, Trs, WEIGHT_SUM_TOLERANCE};

/// A document and its single buffer as `container`: GLB with a BIN chunk,
/// or `.gltf` with the buffer as a data URI (`doc` must have one buffer).
pub fn assemble(doc: &[u8], buffer: Vec<u8>, container: Container) -> Vec<u8> {
    match container {
        Container::Glb => container::assemble_glb(doc, &buffer),
        Container::Json => {
            let mut json: serde_json::Value = serde_json::from_slice(doc).unwrap_or_default();
            if let Some(b) = json.pointer_mut("/buffers/0") {
                b["uri"] = serde_json::json!(container::data_uri(&buffer));
            }
            serde_json::to_vec(&json).unwrap_or_default()
        }
    }
}
pub use write::{write_mesh, Shading};

impl GltfAsset {
    /// Parses a GLB or glTF JSON file; side-car buffers are read as
    /// `sidecars` says.
    pub fn parse(bytes: &[u8], sidecars: Sidecars<'_>) -> Result<Self, GltfError> {
        read::parse(bytes, sidecars)
    }
}
