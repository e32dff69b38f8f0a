//! Why a glTF file could not be read.

use thiserror::Error;

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
