//! The Newton iteration's memory ([`NewtonState`], [`NewtonPattern`])
//! and its cost, which the elastic state holds and counts and
//! `newton.rs` works on: a leaf below both.

use faer::sparse::linalg::cholesky::SymbolicCholesky;

use crate::mesh::Real;

/// What a Newton iteration costs in iterations of the same level's
/// local/global step (assembly and numeric factorisation of the `3|U|`
/// matrix, the solve and the line search's local steps), for the work
/// measure [`StepReport::coarse_work`](crate::deform::StepReport::coarse_work).
/// Timed on the camel's coarsest level (1087 vertices, 857 unknowns): a
/// Newton iteration took about 8 of its local/global iterations
/// (docs/performance.md, "The Newton matrix assembled in place").
pub(super) const NEWTON_COST: Real = 8.0;

/// The Newton iteration's memory: the pattern of `H` for one factor, and
/// the right-hand side.
#[derive(Default)]
pub(super) struct NewtonState {
    pub(super) pattern: Option<NewtonPattern>,
    /// `r_U`, then `Δ`, interleaved (`3u + k`).
    pub(super) rhs: Vec<Real>,
    /// Newton iterations left that take the convex model without trying
    /// the exact Hessian first (it did not factor lately).
    pub(super) convex_for: usize,
}

/// The structure of `H` for one constraint set: its 3×3 block pattern,
/// the scalar matrix whose values each iteration overwrites, and its
/// symbolic Cholesky factorisation.
pub(super) struct NewtonPattern {
    /// The factor it belongs to.
    pub(super) factor_id: u64,
    /// Block rows (CSR; symmetric, so also the block columns): the sorted
    /// block columns of block row `k` are `cols[ptr[k]..ptr[k + 1]]`.
    pub(super) ptr: Vec<usize>,
    pub(super) cols: Vec<u32>,
    /// `H`, `3|U| × 3|U|`, CSR; row `3k + r` holds block row `k`'s blocks'
    /// row `r`, three entries per block.
    pub(super) h: sprs::CsMat<Real>,
    pub(super) symbolic: SymbolicCholesky<usize>,
}
