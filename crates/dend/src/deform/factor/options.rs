//! How a factor is built and stored: the solve back end, the memory
//! budget, the ordering and the precision.

use crate::mesh::Real;
use dend_linalg::ordering::FillOrdering;

/// How [`Factor::build_with`] solves `M`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SolverChoice {
    /// Sparse Cholesky, whatever its size.
    Direct,
    /// Jacobi-preconditioned conjugate gradient, no factorisation (the
    /// paper's method; slow on large meshes).
    Cg,
    /// Cholesky when its estimated size fits the budget, CG otherwise.
    #[default]
    Auto,
}

/// Options of [`Factor::build_with`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveOptions {
    /// Direct, CG, or automatic.
    pub solver: SolverChoice,
    /// [`SolverChoice::Auto`] falls back to CG when the Cholesky factor
    /// would exceed this ([`estimated_factor_bytes`]: its values in the
    /// chosen [`FactorPrecision`] and its row indices).
    pub factor_budget_bytes: usize,
    /// CG relative residual tolerance per solve.
    pub cg_tol: Real,
    /// CG iteration cap per column and solve.
    pub cg_max_iters: usize,
    /// Fill-reducing ordering of the Cholesky factor.
    pub ordering: FillOrdering,
    /// Precision the factor is stored in after the (double-precision)
    /// numeric factorisation.
    pub precision: FactorPrecision,
}

/// How a Cholesky factor is stored between solves.
///
/// The factorisation always runs in `f64`. Each DEND iteration solves for
/// an *update* from a residual computed in `f64` (design.md §4.5), so a factor
/// rounded to `f32` changes the step of an iteration by the solve's
/// relative error (measured 1e-5 to 2e-4 on the benchmark meshes), not the
/// fixed point the iteration converges to. Single precision halves the
/// factor's memory and the bytes each solve streams (an iteration 0–25 %
/// faster), but on eth_hand_14k its inexact steps made the safeguard
/// reject more candidates (100 iterations took 1.5x as long), so it is an
/// option for memory-bound servers, not the default (docs/performance.md).
/// Only supernodal eq. (24) factors are rounded; simplicial (small) factors
/// and the eq. (23) preconditioner stay in `f64`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FactorPrecision {
    /// `f64` values.
    #[default]
    Double,
    /// `f32` values, `f64` arithmetic in the solves.
    Single,
}

impl std::str::FromStr for FactorPrecision {
    type Err = String;

    /// `double` or `single`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "double" => Ok(FactorPrecision::Double),
            "single" => Ok(FactorPrecision::Single),
            _ => Err(format!("unknown factor precision {s:?} (double or single)")),
        }
    }
}

impl std::fmt::Display for FactorPrecision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            FactorPrecision::Double => "double",
            FactorPrecision::Single => "single",
        })
    }
}

impl Default for SolveOptions {
    /// Auto, a 2 GiB factor budget, CG tolerance `1e-4` (the paper's),
    /// at most 5000 CG iterations per column, [`FillOrdering::Auto`],
    /// [`FactorPrecision::Double`].
    fn default() -> Self {
        SolveOptions {
            solver: SolverChoice::Auto,
            factor_budget_bytes: 2 << 30,
            cg_tol: 1e-4,
            cg_max_iters: 5000,
            ordering: FillOrdering::Auto,
            precision: FactorPrecision::Double,
        }
    }
}
