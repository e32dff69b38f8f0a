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
mod container;
mod morph;
mod read;
mod skeleton;
mod skin;
mod write;

pub use container::Sidecars;
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

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::mesh::Point;

/// Extensions that change how geometry is stored: refused.
pub(crate) const REFUSED_EXTENSIONS: &[&str] = &[
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_mesh_quantization",
    "EXT_mesh_gpu_instancing",
];

/// The glTF container: binary GLB or JSON `.gltf`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Container {
    /// `.glb`: a JSON chunk and one BIN chunk.
    Glb,
    /// `.gltf`: JSON, buffers as base64 data URIs.
    Json,
}

/// Why a glTF file could not be read.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum GltfError {
    /// The GLB envelope is malformed or truncated. Fix: re-export the file.
    #[error("GLB container at byte {offset}: {message}")]
    Glb {
        /// Byte offset of the problem.
        offset: usize,
        /// What is wrong.
        message: String,
    },
    /// The JSON document does not parse, or does not have glTF's shape.
    #[error("glTF JSON at line {line}, column {column}: {message}")]
    Json {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// The document breaks a glTF rule (a dangling index, a missing field).
    #[error("invalid glTF: {message}")]
    Invalid {
        /// What is wrong, with the JSON path.
        message: String,
    },
    /// A feature dend does not handle (see the module documentation).
    #[error("unsupported glTF: {what}")]
    Unsupported {
        /// Which feature, where.
        what: String,
    },
    /// An accessor has the wrong type or lies outside its buffer.
    #[error("glTF accessor {accessor}: {message}")]
    Accessor {
        /// The accessor's index.
        accessor: usize,
        /// What is wrong.
        message: String,
    },
    /// A triangle index names a vertex past the primitive's POSITION count.
    #[error("glTF mesh {mesh} primitive {primitive}: index {index} is out of range ({vertices} vertices)")]
    IndexOutOfRange {
        /// The mesh.
        mesh: usize,
        /// The primitive within the mesh.
        primitive: usize,
        /// The bad index value.
        index: u32,
        /// The POSITION count.
        vertices: usize,
    },
    /// A buffer holds fewer bytes than its `byteLength`.
    #[error("glTF buffer {buffer} declares {declared} bytes but holds {actual}")]
    BufferTooShort {
        /// The buffer.
        buffer: usize,
        /// Its `byteLength`.
        declared: usize,
        /// The bytes available.
        actual: usize,
    },
    /// A GLB-stored buffer (no `uri`) but the file has no BIN chunk.
    #[error("glTF buffer {buffer} has no uri and there is no GLB BIN chunk")]
    MissingBin {
        /// The buffer.
        buffer: usize,
    },
    /// A `data:` URI that is not base64 or does not decode.
    #[error("glTF buffer {buffer}: bad data URI: {message}")]
    BadDataUri {
        /// The buffer.
        buffer: usize,
        /// What is wrong.
        message: String,
    },
    /// A side-car buffer where none may be read (uploads), or an absolute or
    /// remote URI. Fix: embed the buffers (GLB or data URIs).
    #[error(
        "glTF buffer {buffer}: external uri {uri:?} is not read here (embed the buffers: use .glb)"
    )]
    ExternalBuffer {
        /// The buffer.
        buffer: usize,
        /// Its URI.
        uri: String,
    },
    /// A side-car buffer file could not be read.
    #[error("glTF buffer {buffer}: {path}: {message}")]
    BufferFile {
        /// The buffer.
        buffer: usize,
        /// The file.
        path: String,
        /// The operating-system error.
        message: String,
    },
    /// A node matrix cannot be inverted, so a pose cannot be written back.
    #[error("glTF node {node} has a singular transform")]
    SingularTransform {
        /// The node.
        node: usize,
    },
    /// The scene has no triangles.
    #[error("glTF scene has no triangle primitives")]
    NoTriangles,
}

/// Counts and names describing a glTF asset.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct GltfSummary {
    /// The scene's name, else the first deformed mesh's.
    pub name: Option<String>,
    /// Mesh instances deformed (nodes with a mesh in the scene).
    pub meshes: usize,
    /// Triangle primitives deformed.
    pub primitives: usize,
    /// Vertex attribute names of those primitives (`POSITION`, `TEXCOORD_0`, …).
    pub attributes: Vec<String>,
    /// Morph targets (passed through).
    pub morph_targets: usize,
    /// Skins in the document.
    pub skins: usize,
    /// Whether a deformed mesh is skinned.
    pub skinned: bool,
    /// Materials in the document.
    pub materials: usize,
    /// Textures in the document.
    pub textures: usize,
    /// Animations in the document.
    pub animations: usize,
}

/// A glTF document as read: the JSON, the buffers' bytes and the scene's
/// triangle primitives as one vertex list in world space.
///
/// Asset vertices are the primitives' POSITION elements, one block per
/// (node, POSITION accessor), in scene traversal order; `triangles` index
/// them.
#[derive(Debug, Clone)]
pub struct GltfAsset {
    json: serde_json::Value,
    buffers: Vec<Vec<u8>>,
    container: Container,
    blocks: Vec<read::Block>,
    positions: Vec<Point>,
    triangles: Vec<[u32; 3]>,
    normals: Vec<Option<Point>>,
    tangents: Vec<Option<Point>>,
    parts: Vec<PrimitivePart>,
    summary: GltfSummary,
}

/// Where one deformed primitive's triangles are in [`GltfAsset::triangles`],
/// and the node and mesh it belongs to: what constraints name glTF parts by
/// (see [`crate::mesh::asset::groups`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PrimitivePart {
    /// The node placing the mesh.
    pub node: usize,
    /// The node's name.
    pub node_name: Option<String>,
    /// The mesh.
    pub mesh: usize,
    /// The mesh's name.
    pub mesh_name: Option<String>,
    /// The primitive's index in its mesh.
    pub primitive: usize,
    /// Its triangles, a range of [`GltfAsset::triangles`].
    pub triangles: std::ops::Range<usize>,
}

impl GltfAsset {
    /// Parses a GLB or glTF JSON file; side-car buffers are read as
    /// `sidecars` says.
    pub fn parse(bytes: &[u8], sidecars: Sidecars<'_>) -> Result<Self, GltfError> {
        read::parse(bytes, sidecars)
    }

    /// The container the file was read from.
    pub fn container(&self) -> Container {
        self.container
    }

    /// Asset vertex positions in world space, `#A×3`.
    pub fn positions(&self) -> &[Point] {
        &self.positions
    }

    /// Triangles over asset vertices, in file order, wound for world space.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// The file's normals in world space (unit), per asset vertex; None where
    /// a primitive has no NORMAL (or a zero one).
    pub fn normals(&self) -> &[Option<Point>] {
        &self.normals
    }

    /// The file's tangent directions in world space (unit), per asset vertex.
    pub fn tangents(&self) -> &[Option<Point>] {
        &self.tangents
    }

    /// The deformed primitives, in the order of their triangles.
    pub fn parts(&self) -> &[PrimitivePart] {
        &self.parts
    }

    /// What the asset holds.
    pub fn summary(&self) -> &GltfSummary {
        &self.summary
    }
}
