//! The stages of a factor build, reported as they start: a leaf below the
//! factor (`mod.rs`) and its backend, which both report them.

/// A stage of a factor build, reported as it starts
/// ([`Factor::build_reporting`](super::Factor::build_reporting); the editor shows it while a large mesh's
/// factor builds).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BuildStage {
    /// Assembling the normal matrix (eq. (24): with its symbolic analysis
    /// at the same time).
    Assembly,
    /// The sparse Cholesky's symbolic analysis (ordering, elimination tree).
    Symbolic,
    /// The numeric factorisation.
    Numeric,
}
