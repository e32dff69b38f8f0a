//! The error every deform module returns ([`DeformError`]), in a file of its
//! own so that each of them imports it from here and none goes through
//! `deform/mod.rs`, which re-exports their items (docs/architecture.md,
//! "Layering").

use thiserror::Error;

use crate::mesh::MeshError;

/// Why a deformation could not be set up or run. Every variant is a user
/// error with a fix, except `OutOfMemory`.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum DeformError {
    /// A parameter is NaN, negative or out of range.
    #[error("invalid parameter {name} = {value}")]
    InvalidParam {
        /// Parameter name.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A vertex index does not exist.
    #[error("unknown vertex {index}: the mesh has {vertices} vertices")]
    UnknownVertex {
        /// The index.
        index: u64,
        /// Vertex count.
        vertices: usize,
    },
    /// A handle selects no vertex.
    #[error("handle {name:?} selects no vertex")]
    EmptyHandle {
        /// Handle name.
        name: String,
    },
    /// Two handles share a name.
    #[error("two handles are named {name:?}")]
    DuplicateHandle {
        /// Handle name.
        name: String,
    },
    /// A vertex is in two sets (fixed and a handle, or two handles).
    #[error("vertex {vertex} of handle {handle:?} is already fixed or in another handle")]
    OverlappingSets {
        /// The vertex.
        vertex: u32,
        /// The handle that claimed it second.
        handle: String,
    },
    /// Neither fixed vertices nor handles.
    #[error("no constraints: give fixed vertices or at least one handle")]
    NoConstraints,
    /// A connected component has no constrained vertex: the system is
    /// rank-deficient (the component could float freely).
    #[error("connected component {component} (e.g. vertex {vertex}) has no fixed or handle vertex: the system is rank-deficient")]
    Unconstrained {
        /// Component label.
        component: usize,
        /// A vertex in it.
        vertex: u32,
    },
    /// The normal matrix is not positive definite (numerically singular).
    #[error("the system matrix is not positive definite (pivot {pivot}): constraints leave it rank-deficient")]
    NotPositiveDefinite {
        /// The failing pivot (in the permuted order).
        pivot: usize,
    },
    /// Allocation failed.
    #[error("out of memory during {what}")]
    OutOfMemory {
        /// The stage.
        what: &'static str,
    },
    /// NaN or infinity in an input.
    #[error("non-finite value in {what}")]
    NonFinite {
        /// Which input.
        what: &'static str,
    },
    /// A transform that is not a rotation.
    #[error("invalid transform: {reason}")]
    InvalidTransform {
        /// Why.
        reason: &'static str,
    },
    /// Explicit handle positions of the wrong count.
    #[error("handle {handle:?} has {expected} vertices but {got} positions")]
    PositionsMismatch {
        /// Handle name.
        handle: String,
        /// Vertex count.
        expected: usize,
        /// Positions given.
        got: usize,
    },
    /// A pose of the wrong length.
    #[error("pose has {got} vertices, expected {expected}")]
    PoseLength {
        /// Expected count.
        expected: usize,
        /// Given count.
        got: usize,
    },
    /// The factor was built for another constraint set, mesh or parameters.
    #[error("factor does not match this constraint set or these parameters")]
    FactorMismatch,
    /// A constraint names a group (`{"group": …}`) the asset does not have,
    /// or the mesh has no asset groups at all. Fix: use one of the listed
    /// names (`dend info`, `GET /v1/meshes/{id}` list them).
    #[error("unknown group {group}: {}", crate::mesh::asset::groups::describe_available(.available))]
    UnknownGroup {
        /// The group as the constraint named it.
        group: String,
        /// The asset's parts (`g "LeftArm"`, `node 1 "Arm"`, `primitive [0, 1]`, …).
        available: Vec<String>,
    },
    /// A constraint selects a joint (`{"joint": …}`) and the asset has no
    /// usable skin, or not that joint. Fix: use one of the joints
    /// `GET /v1/meshes/{id}` lists, or mend the skin as the error says.
    #[error(transparent)]
    Rig(#[from] crate::rig::RigError),
    /// A combination of parameters the chosen formulation does not have.
    #[error("unsupported: {what}")]
    Unsupported {
        /// What, and what to use instead.
        what: &'static str,
    },
    /// The mesh was rejected.
    #[error(transparent)]
    Mesh(#[from] MeshError),
}

impl From<dend_linalg::LinalgError> for DeformError {
    fn from(e: dend_linalg::LinalgError) -> Self {
        match e {
            dend_linalg::LinalgError::NotPositiveDefinite { pivot } => {
                Self::NotPositiveDefinite { pivot }
            }
            dend_linalg::LinalgError::OutOfMemory { what } => Self::OutOfMemory { what },
        }
    }
}
