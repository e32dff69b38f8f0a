//! Energies, constraints, the factor cache and the DEND iteration
//! (design.md §3–9). Pure and synchronous: no I/O, no async.
//!
//! ```text
//!   Rest::new(mesh)                      operators + STEP 1 μ      once per mesh
//!   FactorCache::get_or_build(rest, params, constraints)
//!                                        assemble, analyse, factor once per constraint set
//!   Deformer::step(factor, constraints, max_iters)
//!                                        STEP 2 + one 3-RHS solve  per iteration
//! ```
//!
//! The objective (design.md §4.1), with `W = diag(√A_i)` and `R` the free rows:
//! `|| W R (A X' - P T δ) ||² + λ1 || S X' - C ||² + λ2 || W R (L X' - δ̂) ||²`
//! where, in the default [`Mode`], `P T δ` is the rest Laplacian rotated per
//! vertex by the local rotations `T_i` and mapped through the energy's
//! pre-operator (`A = P L`); in [`Mode::Paper`] and with the linear detail term
//! it is the unrotated `A X` (the paper's `A (X' - X)`).

mod anderson;
mod coarse;
mod constraints;
mod detail;
mod elastic;
mod energy;
mod error;
mod factor;
mod parallel;
mod params;
mod rest;
mod rotation;
mod solver;
mod square;
mod stacked;
mod system;
mod warnings;

pub use constraints::{
    names_groups, resolve_groups, select, BoxSel, Constraints, ConstraintsSpec, HandleGroup,
    HandleSpec, RigidTransform, RotationSpec, SphereSel, VertexSet,
};
pub use dend_linalg::ordering::{FillOrdering, NESTED_DISSECTION_MIN_UNKNOWNS};
pub use detail::{local_rotations, Mu, RingWeights};
pub use elastic::{ElasticOps, ElasticSet};
pub use energy::{energy_matrix, Energy};
pub use error::DeformError;
pub use factor::cache::FactorCache;
pub use factor::{
    BuildStage, Factor, FactorKey, FactorPrecision, FactorTimings, SolveOptions, SolverChoice,
};
pub use params::{
    Corrections, DetailTerm, ElasticParams, Formulation, FormulationParams, Mode, PaperParams,
    Params, ParamsSpec, Preset, DEFAULT_AREA, DEFAULT_BENDING, DEFAULT_COARSE_RATIO,
    DEFAULT_CORRECTION_PERIOD, DEFAULT_LAPLACIAN, DEFAULT_STRETCH, ELASTICA_COARSE_RATIO,
    ELASTICA_CORRECTION_PERIOD, ELASTICA_LAPLACIAN, ELASTICA_STRETCH,
};
pub use rest::{Rest, VertexOrdering};
pub use rotation::{best_rotation, fit_rotation, fit_rotation_quat, rotation_from_covariance};
pub use solver::level_minima::{level_minima, level_minima_with_detail, LevelMinima, LevelMinimum};
pub use solver::multilevel::{COARSE_MAX_ITERS, CORRECTION_MAX_ITERS};
pub use solver::prepared::{LevelPlan, PreparedLevels};
pub use solver::preview::{
    PreviewReport, PREVIEW_ITERATIONS, PREVIEW_MIN_VERTICES, PREVIEW_PASSES, PREVIEW_VERTICES,
};
pub use solver::{Deformer, Galerkin, Levels, StepReport};
pub use warnings::{ConstraintWarning, STRAY_LISTED};
