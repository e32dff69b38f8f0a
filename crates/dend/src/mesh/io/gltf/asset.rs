//! A glTF document as read ([`GltfAsset`]): its container, the scene's
//! triangle primitives as one vertex list in world space, the parts they
//! come from, and what the file holds besides.

use nalgebra::{Matrix3, Matrix4};
use serde::{Deserialize, Serialize};

use super::accessor::Located;
use crate::mesh::Point;

/// The glTF container: binary GLB or JSON `.gltf`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Container {
    /// `.glb`: a JSON chunk and one BIN chunk.
    Glb,
    /// `.gltf`: JSON, buffers as base64 data URIs.
    Json,
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
    pub(super) json: serde_json::Value,
    pub(super) buffers: Vec<Vec<u8>>,
    pub(super) container: Container,
    pub(super) blocks: Vec<Block>,
    pub(super) positions: Vec<Point>,
    pub(super) triangles: Vec<[u32; 3]>,
    pub(super) normals: Vec<Option<Point>>,
    pub(super) tangents: Vec<Option<Point>>,
    pub(super) parts: Vec<PrimitivePart>,
    pub(super) summary: GltfSummary,
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

/// The vertices of one POSITION accessor as placed by one node.
#[derive(Debug, Clone)]
pub(crate) struct Block {
    /// The node placing it.
    pub node: usize,
    /// The POSITION accessor.
    pub position: Located,
    /// The NORMAL accessor, if any.
    pub normal: Option<Located>,
    /// The TANGENT accessor, if any.
    pub tangent: Option<Located>,
    /// The first asset vertex of this block.
    pub first: usize,
    /// Local → world (identity for skinned meshes).
    pub world: Matrix4<f64>,
    /// World → local.
    pub inverse: Matrix4<f64>,
    /// The positions as stored in the file.
    pub local: Vec<[f32; 3]>,
}

impl Block {
    /// The linear part of the world matrix.
    pub fn linear(&self) -> Matrix3<f64> {
        self.world.fixed_view::<3, 3>(0, 0).into_owned()
    }
}
