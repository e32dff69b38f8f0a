//! The constraints JSON (`api/constraints.schema.json`): which vertices
//! stay fixed and which move with each handle ([`ConstraintsSpec`]), as
//! `PUT /v1/sessions/{id}/constraints` and the socket's `set_constraints`
//! send it and the session's `constraints` echoes it.
//!
//! This is the wire shape of the core's `dend::mesh::selection` types, kept
//! here so that a client does not link the solver; the server resolves the
//! same JSON against the mesh with the core's types, and a test of the
//! server (`crates/server/src/wire.rs`) keeps the two shapes equal.

use serde::{Deserialize, Serialize};

/// A position or vector, mesh units.
pub type Point = [f64; 3];

/// The constraints: `{"fixed": VERTEX_SET, "handles": [HANDLE…]}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintsSpec {
    /// Vertices that stay where they are (at rest, or at
    /// `fixed_positions`).
    #[serde(default = "empty_set")]
    pub fixed: VertexSet,
    /// Explicit positions of the fixed vertices, one per fixed vertex in
    /// increasing index order.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_positions: Option<Vec<Point>>,
    /// The handles, in order (a drag names one by index or name).
    #[serde(default)]
    pub handles: Vec<HandleSpec>,
}

fn empty_set() -> VertexSet {
    VertexSet::Indices(Vec::new())
}

impl ConstraintsSpec {
    /// `fixed` held, `handles` movable, nothing else set.
    pub fn new(fixed: VertexSet, handles: Vec<HandleSpec>) -> Self {
        ConstraintsSpec {
            fixed,
            fixed_positions: None,
            handles,
        }
    }
}

/// One handle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandleSpec {
    /// Name (default `handle<k>`).
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
    /// order (the transform then acts on these).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub positions: Option<Vec<Point>>,
}

impl HandleSpec {
    /// This handle translated by `t`.
    pub fn translated(self, t: Point) -> Self {
        HandleSpec {
            translate: Some(t),
            ..self
        }
    }

    /// This handle rotated by `degrees` about `axis` (about its pivot).
    pub fn rotated(self, axis: Point, degrees: f64) -> Self {
        HandleSpec {
            rotate: Some(RotationSpec::AxisAngle { axis, degrees }),
            ..self
        }
    }

    /// A handle named `name` on `vertices`, not moved.
    pub fn named(name: &str, vertices: VertexSet) -> Self {
        HandleSpec {
            name: Some(name.to_owned()),
            vertices,
            translate: None,
            rotate: None,
            pivot: None,
            positions: None,
        }
    }
}

/// A set of vertices: an index list, a box or a sphere (selected on the
/// rest mesh, mesh units), a named part of the uploaded asset, or the
/// region a joint of its skin dominates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum VertexSet {
    /// `[0, 5, 9]`.
    Indices(Vec<u64>),
    /// `{"box": {"min": [x,y,z], "max": [x,y,z]}}` (inclusive).
    Box {
        /// The box.
        #[serde(rename = "box")]
        bbox: BoxSel,
    },
    /// `{"sphere": {"center": [x,y,z], "radius": r}}` (inclusive).
    Sphere {
        /// The ball.
        sphere: SphereSel,
    },
    /// `{"group": "LeftArm"}`, `{"group": {"node": 3}}`, …
    Group(GroupSel),
    /// `{"joint": "hand.L"}`, `{"joint": 2, "with_children": true}`.
    Joint(JointSel),
}

impl VertexSet {
    /// The index list of `vertices`.
    pub fn indices(vertices: impl IntoIterator<Item = usize>) -> Self {
        VertexSet::Indices(vertices.into_iter().map(|v| v as u64).collect())
    }

    /// The box `[min, max]` (inclusive).
    pub fn bbox(min: Point, max: Point) -> Self {
        VertexSet::Box {
            bbox: BoxSel { min, max },
        }
    }

    /// The ball of `radius` about `center` (inclusive).
    pub fn sphere(center: Point, radius: f64) -> Self {
        VertexSet::Sphere {
            sphere: SphereSel { center, radius },
        }
    }

    /// Every part of the asset named `name` (`{"group": name}`).
    pub fn group(name: &str) -> Self {
        VertexSet::Group(GroupSel {
            group: GroupRef::Name(name.to_owned()),
        })
    }

    /// The region joint `name` dominates, with its descendants' when
    /// `with_children`.
    pub fn joint(name: &str, with_children: bool) -> Self {
        VertexSet::Joint(JointSel {
            joint: NameOrIndex::Name(name.to_owned()),
            with_children,
        })
    }
}

impl From<Vec<u64>> for VertexSet {
    fn from(v: Vec<u64>) -> Self {
        VertexSet::Indices(v)
    }
}

impl From<Vec<u32>> for VertexSet {
    fn from(v: Vec<u32>) -> Self {
        VertexSet::Indices(v.into_iter().map(u64::from).collect())
    }
}

impl From<Vec<usize>> for VertexSet {
    fn from(v: Vec<usize>) -> Self {
        VertexSet::Indices(v.into_iter().map(|i| i as u64).collect())
    }
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

/// A glTF node or mesh, by index or name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum NameOrIndex {
    /// Its index in the document.
    Index(usize),
    /// Its `name`.
    Name(String),
}

/// The vertex set `{"group": …}` (no other key).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroupSel {
    /// The part it names.
    pub group: GroupRef,
}

/// How a constraint names a part of the asset.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(untagged, deny_unknown_fields)]
pub enum GroupRef {
    /// `"LeftArm"`: every OBJ `g`/`o`, glTF node or mesh of this name.
    Name(String),
    /// `{"node": "Arm"}` or `{"node": 3}`.
    Node {
        /// The node.
        node: NameOrIndex,
    },
    /// `{"mesh": "Body"}` or `{"mesh": 0}`.
    Mesh {
        /// The mesh.
        mesh: NameOrIndex,
    },
    /// `{"primitive": [mesh, k]}`: primitive `k` of the mesh.
    Primitive {
        /// The mesh and the primitive's index in it.
        primitive: (NameOrIndex, usize),
    },
}

/// The vertex set `{"joint": …, "with_children": …}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSel {
    /// The joint: its node's name, or its index in the skin's joint list.
    pub joint: NameOrIndex,
    /// Also the regions of the joint's descendants.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub with_children: bool,
}

/// A handle's rotation: axis–angle in degrees, or a unit quaternion
/// `[x, y, z, w]` (`[w, x, y, z]` only under the name `quaternion_wxyz`).
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
    /// `{"quaternion": [x, y, z, w]}`.
    Quaternion {
        /// `[x, y, z, w]`.
        quaternion: [f64; 4],
    },
    /// `{"quaternion_wxyz": [w, x, y, z]}`.
    QuaternionWxyz {
        /// `[w, x, y, z]`.
        quaternion_wxyz: [f64; 4],
    },
}

/// What an installed constraint set does that its user should know (the
/// set is valid): a session's `warnings`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ConstraintWarning {
    /// Which warning, with its details (`code` on the wire).
    #[serde(flatten)]
    pub kind: WarningKind,
    /// What it means, for people.
    pub message: String,
}

/// The kinds of [`ConstraintWarning`], tagged by their `code`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "code", rename_all = "snake_case")]
pub enum WarningKind {
    /// Nothing is fixed: the mesh moves rigidly with its one handle.
    NothingFixed,
    /// A connected part holds no constrained vertex: it stays at rest.
    UnconstrainedComponent {
        /// The part's index.
        component: u32,
        /// Its vertex count.
        vertices: usize,
    },
    /// Constrained vertices cut off from the rest of their region.
    StrayVertices {
        /// How many.
        count: usize,
        /// The first of them (at most a few listed).
        vertices: Vec<u32>,
    },
    /// A warning this build does not know (a newer server's).
    #[serde(other)]
    Other,
}
