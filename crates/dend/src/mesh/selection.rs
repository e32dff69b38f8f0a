//! The constraints JSON as written (`api/constraints.schema.json`): which
//! vertices ([`VertexSet`]: index lists, boxes, spheres, asset groups),
//! how each handle moves ([`HandleSpec`], [`RotationSpec`]) and the whole
//! edit ([`ConstraintsSpec`]). Plain data about a mesh's vertices, below
//! both the generators and assets that write it and the solver that
//! resolves it (`deform::constraints`: [`select`], `ConstraintsSpec::resolve`).
//!
//! [`select`]: crate::deform::select

use serde::{Deserialize, Serialize};

use super::asset::groups::{GroupSel, NameOrIndex};
use super::Point;

/// A set of vertices, as written in the constraints JSON: an index list, a box
/// or a sphere (selected on the rest mesh, in the mesh's own units), or a
/// named part of the asset file (resolved by
/// [`Asset::resolve_groups`](crate::mesh::asset::Asset::resolve_groups)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum VertexSet {
    /// Explicit indices `[0, 5, 9]`.
    Indices(Vec<u64>),
    /// `{"box": {"min": [x,y,z], "max": [x,y,z]}}` (inclusive).
    Box {
        /// The box.
        #[serde(rename = "box")]
        bbox: BoxSel,
    },
    /// `{"sphere": {"center": [x,y,z], "radius": r}}` (inclusive).
    Sphere {
        /// The sphere.
        sphere: SphereSel,
    },
    /// `{"group": "LeftArm"}`, `{"group": {"node": "Arm"}}`, … : a named
    /// part of the asset (see [`crate::mesh::asset::groups`]).
    Group(GroupSel),
    /// `{"joint": "hand.L"}`, `{"joint": "spine", "with_children": true}`:
    /// the region a joint of the asset's skin dominates (see
    /// [`crate::rig`]).
    Joint(JointSel),
}

/// The vertex set `{"joint": …, "with_children": …}`: the welded vertices
/// whose largest skin weight is the joint's (with its descendants' when
/// `with_children`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSel {
    /// The joint: its node's name, or its index in the skin's joint list.
    pub joint: NameOrIndex,
    /// Also the regions of the joint's descendants.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub with_children: bool,
}

/// An axis-aligned box selector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSel {
    /// Lower corner.
    pub min: Point,
    /// Upper corner.
    pub max: Point,
}

/// A ball selector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSel {
    /// Centre.
    pub center: Point,
    /// Radius (≥ 0).
    pub radius: f64,
}

/// One handle in the constraints JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandleSpec {
    /// Name (defaults to `handle<k>`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The handle's vertices.
    pub vertices: VertexSet,
    /// Translation (default zero).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translate: Option<Point>,
    /// Rotation (default identity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate: Option<RotationSpec>,
    /// Rotation centre (default: the handle's rest centroid).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pivot: Option<Point>,
    /// Explicit target positions, one per handle vertex in increasing index
    /// order; the rigid transform then applies to these instead of the rest
    /// positions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub positions: Option<Vec<Point>>,
}

/// The constraints JSON: `{"fixed": VERTEX_SET, "handles": [HANDLE...]}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintsSpec {
    /// Vertices that stay where they are: at their rest positions, or at
    /// `fixed_positions`.
    #[serde(default = "empty_set")]
    pub fixed: VertexSet,
    /// Explicit positions of the fixed vertices, one per fixed vertex in
    /// increasing index order (default: their rest positions). A constraint
    /// edit on a posed session pins the new set where the pose has it
    /// ([`ConstraintsSpec::resolve_at`], [`ConstraintsSpec::anchored`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_positions: Option<Vec<Point>>,
    /// Handle groups.
    #[serde(default)]
    pub handles: Vec<HandleSpec>,
}

fn empty_set() -> VertexSet {
    VertexSet::Indices(Vec::new())
}

/// A rotation in the constraints JSON: axis–angle in degrees, or a unit
/// quaternion. Quaternions are `[x, y, z, w]` across the whole API (as in
/// drags, WebSocket messages, the store and glTF); `[w, x, y, z]` is
/// accepted only under its explicit name `quaternion_wxyz`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum RotationSpec {
    /// `{"axis": [x,y,z], "degrees": a}`.
    AxisAngle {
        /// Rotation axis (any non-zero length).
        axis: Point,
        /// Angle in degrees (right-hand rule).
        degrees: f64,
    },
    /// `{"quaternion": [x, y, z, w]}` (normalised on use).
    Quaternion {
        /// `[x, y, z, w]`.
        quaternion: [f64; 4],
    },
    /// `{"quaternion_wxyz": [w, x, y, z]}` (normalised on use).
    QuaternionWxyz {
        /// `[w, x, y, z]`.
        quaternion_wxyz: [f64; 4],
    },
}
