//! Why a mesh was rejected ([`crate::mesh::Mesh::new`]).

use thiserror::Error;

use super::point::Point;

/// Why a mesh was rejected. Each variant names the first offending element.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MeshError {
    /// The mesh has no triangles. Fix: give at least one face.
    #[error("mesh is empty: it has {vertices} vertices and no triangles")]
    Empty {
        /// Number of vertices given.
        vertices: usize,
    },
    /// More vertices or faces than `u32` indices can address.
    #[error("mesh too large: {count} {what} (at most {max})")]
    TooLarge {
        /// "vertices" or "triangles".
        what: &'static str,
        /// How many were given.
        count: usize,
        /// The largest supported count.
        max: usize,
    },
    /// A pose with another vertex count than the mesh.
    #[error("pose has {got} vertices, the mesh has {expected}")]
    VertexCountMismatch {
        /// The mesh's vertex count.
        expected: usize,
        /// The pose's.
        got: usize,
    },
    /// A coordinate is NaN or infinite. Fix: clean the file.
    #[error("vertex {vertex} has a non-finite coordinate {value:?}")]
    NonFinite {
        /// The vertex index.
        vertex: usize,
        /// The coordinates as read.
        value: Point,
    },
    /// A face refers to a vertex that does not exist.
    #[error("triangle {face} refers to vertex {index}, but the mesh has {vertices} vertices")]
    IndexOutOfRange {
        /// The face index.
        face: usize,
        /// The bad vertex index.
        index: u64,
        /// The number of vertices.
        vertices: usize,
    },
    /// A face uses the same vertex twice.
    #[error("triangle {face} repeats a vertex: {tri:?}")]
    RepeatedIndex {
        /// The face index.
        face: usize,
        /// Its vertex indices.
        tri: [u32; 3],
    },
    /// A face has zero area (its corners are collinear or coincide).
    #[error("triangle {face} {tri:?} has zero area")]
    ZeroArea {
        /// The face index.
        face: usize,
        /// Its vertex indices.
        tri: [u32; 3],
    },
    /// An edge is shared by three or more faces.
    #[error("edge ({a}, {b}) is non-manifold: shared by {faces} triangles")]
    NonManifoldEdge {
        /// One end of the edge.
        a: u32,
        /// The other end.
        b: u32,
        /// How many faces share it.
        faces: usize,
    },
    /// Two faces traverse a shared edge in the same direction.
    #[error(
        "inconsistent orientation: triangles {face_a} and {face_b} both traverse edge {a} -> {b}"
    )]
    InconsistentOrientation {
        /// First face.
        face_a: usize,
        /// Second face.
        face_b: usize,
        /// Edge start.
        a: u32,
        /// Edge end.
        b: u32,
    },
    /// A vertex's incident faces form more than one fan (a "bow tie").
    #[error("vertex {vertex} is non-manifold: its incident triangles form {fans} separate fans")]
    NonManifoldVertex {
        /// The vertex index.
        vertex: u32,
        /// How many fans meet there (at least 2).
        fans: usize,
    },
}
