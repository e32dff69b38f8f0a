//! Named parts of an asset, and constraints that select vertices by them.
//!
//! A file names parts of its surface: OBJ `g` groups (a `g` line with
//! several names puts the faces after it in each) and `o` objects; glTF
//! nodes, meshes and primitives. Each part is a set of asset triangles
//! ([`Part`]). A constraints vertex set may name a part instead of listing
//! indices (`api/constraints.schema.json`):
//!
//! | JSON | selects |
//! |---|---|
//! | `{"group": "LeftArm"}` | every part with this name: OBJ `g` and `o` names, glTF node and mesh names (their union) |
//! | `{"group": {"node": "Arm"}}`, `{"group": {"node": 3}}` | the glTF node (by name or index) that places a mesh in the scene: its own mesh's triangles (not its children's) |
//! | `{"group": {"mesh": "Body"}}`, `{"group": {"mesh": 0}}` | the glTF mesh, by name or index |
//! | `{"group": {"primitive": [0, 1]}}`, `{"group": {"primitive": ["Body", 1]}}` | primitive 1 of mesh 0 (or of the mesh named Body) |
//!
//! **Resolution.** A part selects the welded vertices of its asset
//! triangles: a welded vertex belongs to the part when any asset triangle of
//! the part has a corner on it, so a seam vertex shared by two groups
//! belongs to both. Vertices no solver triangle uses (unreferenced, or only
//! in degenerate triangles) are never selected, as with boxes and spheres.
//! A name no part has is [`DeformError::UnknownGroup`](crate::deform::DeformError::UnknownGroup), which lists the
//! parts the asset has. Group selectors are resolved against the asset
//! *before* the constraints are resolved on the mesh
//! ([`Asset::resolve_groups`](super::Asset::resolve_groups) turns them into
//! index lists); the server does so when constraints are posted, and stores
//! the index lists.

use std::fmt;
use std::ops::Range;

use serde::{Deserialize, Serialize};

use crate::mesh::io::gltf::PrimitivePart;
use crate::mesh::Mesh;

/// What kind of part.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GroupKind {
    /// An OBJ `g` group name.
    G,
    /// An OBJ `o` object name.
    O,
    /// A glTF node that places a mesh.
    Node,
    /// A glTF mesh.
    Mesh,
    /// A glTF primitive (of a mesh).
    Primitive,
}

impl GroupKind {
    /// `g`, `o`, `node`, `mesh` or `primitive` (as serialised).
    pub fn name(self) -> &'static str {
        match self {
            GroupKind::G => "g",
            GroupKind::O => "o",
            GroupKind::Node => "node",
            GroupKind::Mesh => "mesh",
            GroupKind::Primitive => "primitive",
        }
    }
}

/// A named part of an asset: its asset triangles, as ranges in file order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Part {
    /// Its kind.
    pub kind: GroupKind,
    /// Its name (a primitive's is its mesh's).
    pub name: Option<String>,
    /// The glTF node or mesh index (a primitive's mesh).
    pub index: Option<usize>,
    /// A primitive's index in its mesh.
    pub primitive: Option<usize>,
    /// Asset triangles, as ranges of [`super::Asset::triangles`].
    pub ranges: Vec<Range<usize>>,
}

impl Part {
    /// An OBJ part named `name`, without triangles yet.
    pub(crate) fn named(kind: GroupKind, name: &str) -> Self {
        Part {
            kind,
            name: Some(name.to_owned()),
            index: None,
            primitive: None,
            ranges: Vec::new(),
        }
    }

    /// Adds triangles `r`, merged with the last range when they follow it.
    pub(crate) fn push(&mut self, r: Range<usize>) {
        match self.ranges.last_mut() {
            Some(last) if last.end == r.start => last.end = r.end,
            _ => self.ranges.push(r),
        }
    }

    pub(super) fn triangles(&self) -> usize {
        self.ranges.iter().map(|r| r.len()).sum()
    }

    pub(super) fn matches(&self, g: &GroupRef) -> bool {
        let is = |k: &NameOrIndex| match k {
            NameOrIndex::Index(i) => self.index == Some(*i),
            NameOrIndex::Name(n) => self.name.as_deref() == Some(n.as_str()),
        };
        match (g, self.kind) {
            (
                GroupRef::Name(n),
                GroupKind::G | GroupKind::O | GroupKind::Node | GroupKind::Mesh,
            ) => self.name.as_deref() == Some(n.as_str()),
            (GroupRef::Node { node }, GroupKind::Node) => is(node),
            (GroupRef::Mesh { mesh }, GroupKind::Mesh) => is(mesh),
            (GroupRef::Primitive { primitive: (m, p) }, GroupKind::Primitive) => {
                is(m) && self.primitive == Some(*p)
            }
            _ => false,
        }
    }
}

/// How a part is named in messages and listings: `g "LeftArm"`,
/// `o "Body"`, `node 1 "Arm"`, `mesh 0 "Body"`, `primitive [0, 1]`.
fn label(
    kind: GroupKind,
    name: Option<&str>,
    index: Option<usize>,
    primitive: Option<usize>,
) -> String {
    let i = index.unwrap_or(0);
    let mut s = match kind {
        GroupKind::Primitive => return format!("primitive [{i}, {}]", primitive.unwrap_or(0)),
        GroupKind::G | GroupKind::O => kind.name().to_owned(),
        GroupKind::Node | GroupKind::Mesh => format!("{} {i}", kind.name()),
    };
    if let Some(n) = name {
        s.push_str(&format!(" {n:?}"));
    }
    s
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let l = label(self.kind, self.name.as_deref(), self.index, self.primitive);
        f.write_str(&l)
    }
}

impl fmt::Display for GroupInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let l = label(self.kind, self.name.as_deref(), self.index, self.primitive);
        write!(f, "{l} ({} vertices)", self.vertices)
    }
}

/// The parts of a glTF scene: one per node, per mesh and per primitive,
/// each kind in index order.
pub(crate) fn gltf_parts(prims: &[PrimitivePart]) -> Vec<Part> {
    let mut nodes: Vec<Part> = Vec::new();
    let mut meshes: Vec<Part> = Vec::new();
    let mut out = Vec::new();
    for p in prims {
        let r = p.triangles.clone();
        for (list, kind, index, name) in [
            (&mut nodes, GroupKind::Node, p.node, &p.node_name),
            (&mut meshes, GroupKind::Mesh, p.mesh, &p.mesh_name),
        ] {
            match list.iter_mut().find(|q| q.index == Some(index)) {
                Some(q) => q.push(r.clone()),
                None => list.push(Part {
                    kind,
                    name: name.clone(),
                    index: Some(index),
                    primitive: None,
                    ranges: vec![r.clone()],
                }),
            }
        }
        out.push(Part {
            kind: GroupKind::Primitive,
            name: p.mesh_name.clone(),
            index: Some(p.mesh),
            primitive: Some(p.primitive),
            ranges: vec![r],
        });
    }
    // listed by index (the scene is traversed depth first, last root first)
    nodes.sort_by_key(|p| p.index);
    meshes.sort_by_key(|p| p.index);
    out.sort_by_key(|p| (p.index, p.primitive));
    nodes.extend(meshes);
    nodes.extend(out);
    nodes
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

impl fmt::Display for NameOrIndex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NameOrIndex::Index(i) => write!(f, "{i}"),
            NameOrIndex::Name(n) => write!(f, "{n:?}"),
        }
    }
}

/// The vertex set `{"group": …}` (no other key).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroupSel {
    /// The part it names.
    pub group: GroupRef,
}

/// How a constraint names a part: the value of `{"group": …}` (see the
/// module documentation).
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

impl fmt::Display for GroupRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            GroupRef::Name(n) => write!(f, "{n:?}"),
            GroupRef::Node { node } => write!(f, "node {node}"),
            GroupRef::Mesh { mesh } => write!(f, "mesh {mesh}"),
            GroupRef::Primitive { primitive: (m, p) } => write!(f, "primitive [{m}, {p}]"),
        }
    }
}

/// The list in [`DeformError::UnknownGroup`](crate::deform::DeformError::UnknownGroup)'s message.
pub fn describe_available(available: &[String]) -> String {
    const SHOWN: usize = 40;
    if available.is_empty() {
        return "the mesh has no named groups (they come from glTF nodes, meshes and \
                primitives and OBJ g/o lines of an asset file)"
            .into();
    }
    let mut s = format!(
        "the asset has {}",
        available[..available.len().min(SHOWN)].join(", ")
    );
    if available.len() > SHOWN {
        s.push_str(&format!(" and {} more", available.len() - SHOWN));
    }
    s
}

/// A part as `dend info` and `GET /v1/meshes/{id}` list it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct GroupInfo {
    /// `g`, `o`, `node`, `mesh` or `primitive`.
    pub kind: GroupKind,
    /// Its name, if it has one (a primitive's is its mesh's).
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
    /// Welded (solver) vertices it selects.
    pub vertices: usize,
}

/// The welded vertices of `parts` (sorted, without unreferenced ones).
pub(super) fn welded_vertices<'a>(
    parts: impl IntoIterator<Item = &'a Part>,
    triangles: &[[u32; 3]],
    to_welded: &[u32],
    mesh: &Mesh,
) -> Vec<u32> {
    let mut seen = vec![false; mesh.num_vertices()];
    for part in parts {
        for r in &part.ranges {
            for t in &triangles[r.clone()] {
                for &a in t {
                    if let Some(&w) = to_welded.get(a as usize) {
                        seen[w as usize] = true;
                    }
                }
            }
        }
    }
    (0..mesh.num_vertices() as u32)
        .filter(|&v| seen[v as usize] && !mesh.topology().ring(v as usize).is_empty())
        .collect()
}
