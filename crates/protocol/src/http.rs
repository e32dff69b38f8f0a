//! The bodies of the HTTP routes that are neither a mesh, a pose nor a
//! session message: the constraints answer, curvatures, presets and named
//! poses (`api/openapi.yaml` describes each route).

use serde::{Deserialize, Serialize};

use crate::params::SessionParams;
use crate::ws::{PoseInfo, SessionState};

/// `POST /v1/meshes` body of a mesh sent as JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshJson {
    /// Vertex positions.
    pub positions: Vec<[f64; 3]>,
    /// Triangles, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

/// `POST /v1/meshes/generate` body: a shape and its sizes (the core's
/// `dend::mesh::gen::ShapeSpec` on the wire; `crates/server/src/wire.rs`
/// keeps the two equal).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GenerateMesh {
    /// `bar`, `cylinder`, `flag`, `plane`, `bumpy-plane`, `torus`,
    /// `creature`, `saddle`, `wavy-sheet` or `limb` (an unknown one is
    /// answered `invalid_json`).
    pub shape: String,
    /// Its sizes, each the shape's default when absent.
    #[serde(default)]
    pub params: ShapeParams,
}

impl GenerateMesh {
    /// The shape `shape` at its default sizes.
    pub fn new(shape: &str) -> Self {
        GenerateMesh {
            shape: shape.to_owned(),
            params: ShapeParams::default(),
        }
    }
}

/// The sizes of a generated shape (`api/openapi.yaml` says what each
/// means for each shape).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ShapeParams {
    /// First resolution.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nu: Option<u32>,
    /// Second resolution.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nv: Option<u32>,
    /// First size.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub size: Option<f64>,
    /// Second size.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub size2: Option<f64>,
    /// The bumpy plane's bump height, a fraction of its x extent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub amplitude: Option<f64>,
}

/// `PUT /v1/sessions/{id}/constraints` answer (202, the factor builds in
/// the background; the `ETag` is the revision too).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ConstraintsAccepted {
    /// The session's state after the edit (`building`, or `ready` when
    /// the factor was cached).
    pub state: SessionState,
    /// The new constraints revision (what `If-Match` names).
    pub constraints_revision: u64,
}

/// `GET /v1/sessions/{id}/curvature` answer: per-vertex curvatures of the
/// current pose, mesh units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Curvature {
    /// The session revision of the pose they were computed on.
    pub revision: u64,
    /// Mean curvature `H` (`+1/r` on a sphere of radius `r`).
    pub mean: Vec<f64>,
    /// Gaussian curvature `K` (angle defect over area).
    pub gaussian: Vec<f64>,
    /// `G = max(H² − K, 0)`.
    pub g: Vec<f64>,
}

/// One preset of `GET /v1/presets`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PresetInfo {
    /// The name a session's `params.preset` takes.
    pub name: String,
    /// A short title for a menu.
    pub label: String,
    /// What the preset is for.
    pub description: String,
    /// Every parameter the preset sets.
    pub params: SessionParams,
}

/// `GET /v1/presets` answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PresetList {
    /// The preset of a session whose parameters name none.
    pub default: String,
    /// Every preset, the default first.
    pub presets: Vec<PresetInfo>,
}

/// `POST /v1/sessions/{id}/poses` body: save the settled pose as `name`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavePose {
    /// The pose's name.
    pub name: String,
    /// Replace a pose of the same name (else 409 `pose_exists`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub replace: bool,
}

/// `PATCH /v1/sessions/{id}/poses/{name}` body: the new name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenamePose {
    /// The pose's new name.
    pub name: String,
}

/// `GET /v1/sessions/{id}/poses` answer.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PoseList {
    /// The named poses, in save order.
    pub poses: Vec<PoseInfo>,
}

/// `GET /v1/sessions/{id}/poses/{name}` answer: the listing and the
/// positions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedPose {
    /// Name, index, revision, save time.
    #[serde(flatten)]
    pub info: PoseInfo,
    /// Vertex positions (mesh units), `#V×3`.
    pub positions: Vec<[f64; 3]>,
}
