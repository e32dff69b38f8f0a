//! The Newton iteration's memory ([`NewtonState`], [`NewtonPattern`])
//! and its cost, which the elastic state holds and counts and
//! `newton.rs` works on: a leaf below both.

use dend_linalg::cholesky::Refactor;
use faer::sparse::linalg::cholesky::SymbolicCholesky;
use nalgebra::{Matrix3, UnitQuaternion};

use crate::deform::elastic::hessian::blocks::Elements;
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
    /// `r_U`, kept for a second solve (with the convex model).
    pub(super) r: Vec<Real>,
    /// The rotations and area targets of the pose the step starts from,
    /// restored (with the pose) before the convex model is assembled
    /// there after the exact Hessian's line search moved them.
    pub(super) rot0: Vec<UnitQuaternion<Real>>,
    pub(super) proj0: Vec<[Real; 6]>,
    /// The iteration's plain step, column-major as the elastic state's
    /// `rhs`, kept while the line search's global steps use that buffer.
    pub(super) plain: Vec<Real>,
    /// Newton iterations left that take the convex model without trying
    /// the exact Hessian first (it did not factor lately).
    pub(super) convex_for: usize,
}

/// The structure of `H` for one constraint set: its 3×3 block pattern,
/// the scalar matrix whose values each iteration overwrites, its symbolic
/// Cholesky factorisation, and its elements' blocks with the plan that
/// sums them into it (`solver/newton_pattern.rs`).
pub(super) struct NewtonPattern {
    /// The factor it belongs to.
    pub(super) factor_id: u64,
    /// Block row `k`'s first block: its blocks (CSR over block rows,
    /// symmetric) are `ptr[k]..ptr[k + 1]`, their block columns every
    /// third column of `h`'s row `3k`.
    pub(super) ptr: Vec<usize>,
    /// `H`, `3|U| × 3|U|`, CSR; row `3k + r` holds block row `k`'s blocks'
    /// row `r`, three entries per block.
    pub(super) h: sprs::CsMat<Real>,
    pub(super) symbolic: SymbolicCholesky<usize>,
    /// The numeric factorisation's plan and buffer for `h`'s pattern.
    pub(super) refactor: Refactor,
    /// The elements whose blocks make `H` beside `Q`.
    pub(super) elements: Elements,
    /// Their blocks at the last assembly.
    pub(super) blocks: Vec<Matrix3<Real>>,
    /// Whether each element's curvature was indefinite at the last
    /// assembly.
    pub(super) indefinite: Vec<bool>,
    /// How the blocks and `Q` sum into `h`.
    pub(super) gather: Gather,
}

/// Where each block of `H` gathers its values from.
#[derive(Debug)]
pub(super) struct Gather {
    /// The element blocks of each block of `H` (indexed as `cols`), CSR;
    /// an index into the elements' buffer, with its highest bit set for a
    /// block added transposed.
    pub(super) src_ptr: Vec<usize>,
    pub(super) src: Vec<u32>,
    /// The index in `Q_UU`'s values of each block's diagonal entry, or
    /// `u32::MAX`.
    pub(super) q: Vec<u32>,
    /// Block rows where a task of the gather starts (and `|U|` last).
    pub(super) tasks: Vec<usize>,
}
