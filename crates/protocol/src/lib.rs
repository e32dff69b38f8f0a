//! The dend server's wire format, shared by the server and its clients:
//! the binary pose frames ([`frame`]), the session socket's JSON messages
//! and the session requests and answers ([`ws`]), the error body of every
//! failed request ([`error`]), the solver parameters ([`params`]) and the
//! constraints ([`constraints`]) a client sends, the other HTTP bodies
//! ([`http`]), and the mesh and pose JSON of the HTTP API (this module). `api/ws-protocol.md` and
//! `api/openapi.yaml` describe them for clients in other languages.

pub mod constraints;
pub mod error;
pub mod frame;
pub mod http;
pub mod params;
pub mod ws;

pub use constraints::{
    ConstraintWarning, ConstraintsSpec, HandleSpec, RotationSpec, VertexSet, WarningKind,
};
pub use error::{ErrorBody, ErrorCode};
pub use frame::delta::{self, DeltaEncoder};
pub use frame::{
    bounding_box, decode_frame, decode_frame_full, encode_frame_v3, reencode_v2, DecodedFrame,
    FrameBody, FrameDecoder, FrameEncoding, FrameError, FrameHeader, FRAME_HEADER_BYTES,
    FRAME_MAGIC, FRAME_V3_HEADER_BYTES, FRAME_VERSION, FRAME_VERSION_3, LEVEL_COARSE, LEVEL_FULL,
};
pub use http::{
    ConstraintsAccepted, Curvature, GenerateMesh, MeshJson, NamedPose, PoseList, PresetInfo,
    PresetList, RenamePose, SavePose, ShapeParams,
};
pub use params::SessionParams;
pub use ws::{
    AxisAngle, BuildStage, ClientId, ClientMsg, ClientMsgOf, CreateSession, CreateSessionOf,
    Created, DeltaJson, DragRequest, HandleRef, PeerEvent, PoseInfo, ServerMsg, SessionInfo,
    SessionState, StreamOptions,
};

use serde::{Deserialize, Serialize};

/// A mesh as the API describes it: the answer of upload, generate and
/// `GET /v1/meshes/{id}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshInfo {
    /// Mesh id.
    pub id: String,
    /// Vertex count.
    pub vertices: usize,
    /// Triangle count.
    pub triangles: usize,
    /// Bounding box `[min, max]`.
    pub bbox: [[f64; 3]; 2],
    /// For uploads kept as assets (glTF/GLB, OBJ, PLY): the file's format, its
    /// own vertex count (seam copies included; `vertices` counts the welded
    /// surface the sessions deform) and what export keeps besides positions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub asset: Option<AssetSummary>,
    /// What is odd about the mesh though it was accepted (an extent or
    /// coordinates no real asset has); absent when nothing is.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<MeshWarning>,
}

/// A warning about a mesh that was accepted (`MeshInfo::warnings`), or about
/// what an export leaves out (the export's `Dend-Warnings` header).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MeshWarning {
    /// Stable code: `huge_extent`, `tiny_extent`, `far_from_origin`,
    /// `attributes_dropped`.
    pub code: String,
    /// What it means, for people.
    pub message: String,
}

/// What an uploaded asset holds (see [`MeshInfo::asset`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AssetSummary {
    /// `glb`, `gltf`, `obj` or `ply`.
    pub format: String,
    /// The glTF scene's (else first mesh's) name, the name on the OBJ's first `o`/`g` line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Vertices in the file's own layout.
    pub asset_vertices: usize,
    /// Attributes and counts kept by export (`TEXCOORD_0`, `JOINTS_0`,
    /// `skins: 1`, `vt: 120`, …).
    pub attributes: Vec<String>,
    /// The named parts constraints can select by (`{"group": …}`): OBJ
    /// `g`/`o` names, glTF nodes, meshes and primitives.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub groups: Vec<AssetGroup>,
    /// A skinned glTF/GLB's skeleton: its joints, which constraints can
    /// select by (`{"joint": …}`) and a skeleton export poses.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skeleton: Option<AssetSkeleton>,
    /// Why a skinned asset's skin cannot be used as a rig (its skeleton is
    /// then absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skin_error: Option<String>,
}

/// The skeleton of a skinned asset (see [`AssetSummary::skeleton`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AssetSkeleton {
    /// The skin's index in the glTF document.
    pub skin: usize,
    /// Its joints, in the skin's order.
    pub joints: Vec<AssetJoint>,
    /// Vertices whose skin weights did not sum to one and were normalised
    /// (a warning about the file).
    #[serde(default)]
    pub renormalised_vertices: usize,
}

/// A joint of a skeleton (see [`AssetSkeleton::joints`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AssetJoint {
    /// Its name (what `{"joint": …}` selects by).
    pub name: String,
    /// Its index in the skin's joint list.
    pub index: usize,
    /// Its glTF node.
    pub node: usize,
    /// Its parent joint's name; absent for a root.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parent: Option<String>,
    /// Its head (origin) in the mesh's bind space, where a gizmo sits.
    pub head: [f64; 3],
    /// Welded vertices whose largest skin weight is this joint's.
    pub vertices: usize,
    /// Those vertices (welded indices, ascending): the joint's region, as a
    /// client paints it.
    #[serde(default)]
    pub region: Vec<u32>,
}

/// A named part of an uploaded asset (see [`AssetSummary::groups`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct AssetGroup {
    /// `g`, `o`, `node`, `mesh` or `primitive`.
    pub kind: String,
    /// Its name (a primitive's is its mesh's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The glTF node or mesh index (a primitive's mesh).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<usize>,
    /// A primitive's index in its mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub primitive: Option<usize>,
    /// Asset triangles in it.
    pub triangles: usize,
    /// Welded vertices (the ones sessions deform) it selects.
    pub vertices: usize,
}

/// A pose as JSON: the answer of drags, undo/redo/reset and
/// `GET /v1/sessions/{id}/pose`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseJson {
    /// Session revision.
    pub revision: u64,
    /// Last applied client sequence number.
    pub ack_seq: u64,
    /// Iterations since the targets last changed.
    pub iteration: u32,
    /// Whether the solve converged.
    pub converged: bool,
    /// Whether the server stopped iterating until the next change
    /// (converged, or its iteration budget spent).
    #[serde(default)]
    pub settled: bool,
    /// The solver's objective at this pose (absent before any solve).
    #[serde(default)]
    pub objective: Option<f64>,
    /// `#V×3` positions, mesh units.
    pub positions: Vec<[f64; 3]>,
}
