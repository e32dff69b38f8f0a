//! The per-set state of the Galerkin coarse corrections
//! (`solver/galerkin.rs`): pure data a [`Deformer`] holds, in a leaf below
//! the steps.
//!
//! [`Deformer`]: super::Deformer

use dend_linalg::cholesky::Refactor;
use faer::dyn_stack::MemBuffer;
use faer::sparse::linalg::cholesky::SymbolicCholesky;
use nalgebra::Vector3;

use crate::deform::elastic::hessian::blocks::Elements;
use crate::deform::elastic::hessian::galerkin::RigidSpace;
use crate::mesh::Real;

/// The per-set state of the Galerkin corrections.
pub(super) struct GalerkinState {
    /// The fine factor (constraint set) it was built for.
    pub(super) factor_id: u64,
    /// The aggregates and `G`'s block pattern.
    pub(super) space: RigidSpace,
    /// The Newton matrix's elements (supports, unknowns).
    pub(super) elements: Elements,
    /// `Q' = Q − Σ_t w_t A_tᵀ A_t` on the unknowns (the part of `H` that
    /// does not depend on the pose, `ElasticOps::without_area`).
    pub(super) q: sprs::CsMat<Real>,
    /// `G = Pᵀ H P` at the last assembly (`6 × aggregates` square).
    pub(super) g: sprs::CsMat<Real>,
    /// `G`'s symbolic Cholesky factorisation and numeric factor.
    pub(super) symbolic: SymbolicCholesky<usize>,
    pub(super) refactor: Refactor,
    /// Each weight's lever arm `y_k − c_a` at the last assembly (indexed
    /// like the space's weights).
    pub(super) lever: Vec<Vector3<Real>>,
    /// Each aggregate's centroid at the last assembly.
    pub(super) centre: Vec<Vector3<Real>>,
    /// `Pᵀ r`, then `δ`.
    pub(super) rhs: Vec<Real>,
    /// The coarse solve's scratch.
    pub(super) mem: MemBuffer,
    /// Corrections since `G` was assembled (`None`: never).
    pub(super) age: Option<usize>,
}
