//! How a factor solves `M X = B`: one [`Backend`] per way, chosen once when
//! the factor is built (by the formulation, the solver choice, the memory
//! budget and the symbolic structure), and the build of each.

use std::time::{Duration, Instant};

use faer::sparse::linalg::cholesky::{SymbolicCholesky, SymbolicCholeskyRaw};
use faer::sparse::linalg::solvers::Lu;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};

use super::options::{FactorPrecision, SolveOptions, SolverChoice};
use super::stage::BuildStage;
use crate::deform::error::DeformError;
use crate::deform::params::Formulation;
use crate::deform::square::Square;
use crate::deform::system::System;
use crate::mesh::Real;
use dend_linalg::cg::Cg;
use dend_linalg::cholesky::{self, analyse, csr_arrays};
use dend_linalg::trisolve;
use dend_linalg::LinalgError;

/// The solve of a factor.
pub(super) enum Backend {
    /// No unknowns: every vertex is constrained, nothing to solve.
    Empty,
    /// Preconditioned CG on `M` (chosen, or [`SolverChoice::Auto`] over the
    /// factor memory budget): `M` is assembled, not factorised.
    Cg(Cg),
    /// The sparse LU of eq. (23)'s exact `K_UU` ([`Formulation::SquareLu`]).
    Lu(Box<Lu<usize, Real>>),
    /// A simplicial Cholesky factor (small systems), solved by
    /// [`trisolve::simplicial`].
    Simplicial {
        /// Its structure.
        symbolic: SymbolicCholesky<usize>,
        /// Its values.
        values: Vec<Real>,
    },
    /// A supernodal Cholesky factor, solved by [`trisolve`].
    Supernodal {
        /// Its structure.
        symbolic: SymbolicCholesky<usize>,
        /// Its values, in double or ([`FactorPrecision::Single`]) single
        /// precision.
        values: Values,
        /// The two-thread split of the solves (large factors, 2+ threads).
        plan: Option<trisolve::SolvePlan>,
    },
    /// eq. (23): GMRES on the exact `K_UU`, preconditioned by the Cholesky
    /// factor of its SPD `N` (simplicial or supernodal, solved by faer in
    /// `f64`).
    Gmres {
        /// The preconditioner's structure.
        symbolic: SymbolicCholesky<usize>,
        /// Its values.
        values: Vec<Real>,
    },
}

/// A supernodal factor's values.
pub(super) enum Values {
    /// `f64`.
    Double(Vec<Real>),
    /// Rounded to `f32` (half the memory).
    Single(Vec<f32>),
}

/// A backend and how long its symbolic and numeric stages took.
pub(super) struct Built {
    pub(super) backend: Backend,
    pub(super) symbolic: Duration,
    pub(super) numeric: Duration,
}

/// The symbolic analysis run beside the assembly (least squares), with its
/// time.
pub(super) type Analysed = (Result<SymbolicCholesky<usize>, LinalgError>, Duration);

impl Backend {
    /// Builds the solve of `sys.m`. `square` is eq. (23)'s operators (square
    /// formulations), `single_ok` whether the formulation allows an `f32`
    /// factor, `analysed` a symbolic analysis already run; `progress` is
    /// told as the symbolic and numeric stages start.
    pub(super) fn build(
        sys: &System,
        formulation: Formulation,
        square: Option<&Square>,
        single_ok: bool,
        options: &SolveOptions,
        analysed: Option<Analysed>,
        progress: &dyn Fn(BuildStage),
    ) -> Result<Built, DeformError> {
        let n = sys.unknowns.len();
        let built = |backend, symbolic, numeric| Built {
            backend,
            symbolic,
            numeric,
        };
        if n == 0 {
            return Ok(built(Backend::Empty, Duration::ZERO, Duration::ZERO));
        }
        let k_uu = square.and_then(|s| s.k_uu.as_ref());
        if let (Formulation::SquareLu, Some(k_uu)) = (formulation, k_uu) {
            let t = Instant::now();
            let mat = to_faer(k_uu, n);
            let t2 = Instant::now();
            progress(BuildStage::Numeric);
            let lu = mat
                .sp_lu()
                .map_err(|_| DeformError::NotPositiveDefinite { pivot: 0 })?;
            return Ok(built(Backend::Lu(Box::new(lu)), t2 - t, t2.elapsed()));
        }
        let cg = || Backend::Cg(Cg::new(&sys.m, options.cg_tol, options.cg_max_iters));
        if options.solver == SolverChoice::Cg {
            return Ok(built(cg(), Duration::ZERO, Duration::ZERO));
        }
        let (symbolic, symbolic_time) = match analysed {
            Some((symbolic, time)) => (symbolic?, time),
            None => {
                progress(BuildStage::Symbolic);
                let t = Instant::now();
                let (col_ptr, row_idx) = csr_arrays(&sys.m);
                let symbolic = analyse(&col_ptr, row_idx, options.ordering)?;
                (symbolic, t.elapsed())
            }
        };
        if options.solver == SolverChoice::Auto
            && estimated_factor_bytes(&symbolic, options.precision) > options.factor_budget_bytes
        {
            return Ok(built(cg(), symbolic_time, Duration::ZERO));
        }
        progress(BuildStage::Numeric);
        let t = Instant::now();
        let values = cholesky::factorise(&symbolic, &sys.m)?;
        let single = single_ok && options.precision == FactorPrecision::Single;
        let backend = Backend::cholesky(symbolic, values, k_uu.is_some(), single);
        Ok(built(backend, symbolic_time, t.elapsed()))
    }

    /// A Cholesky factor's backend: eq. (23)'s preconditioner when
    /// `preconditions_gmres`, else by its structure. A supernodal factor is
    /// solved by `trisolve` (on two threads if there are; in `f32` if
    /// `single`); the preconditioner always by faer in `f64`.
    fn cholesky(
        symbolic: SymbolicCholesky<usize>,
        values: Vec<Real>,
        preconditions_gmres: bool,
        single: bool,
    ) -> Backend {
        if preconditions_gmres {
            return Backend::Gmres { symbolic, values };
        }
        let plan = match symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(sn) => {
                Some(two_threads_available().then(|| trisolve::SolvePlan::new(sn)))
            }
            SymbolicCholeskyRaw::Simplicial(_) => None,
        };
        match plan {
            Some(plan) => Backend::Supernodal {
                symbolic,
                values: if single {
                    Values::Single(values.iter().map(|&v| v as f32).collect())
                } else {
                    Values::Double(values)
                },
                plan: plan.flatten(),
            },
            None => Backend::Simplicial { symbolic, values },
        }
    }

    /// The symbolic Cholesky factorisation (none for CG, LU or no unknowns).
    pub(super) fn symbolic(&self) -> Option<&SymbolicCholesky<usize>> {
        match self {
            Backend::Simplicial { symbolic, .. }
            | Backend::Supernodal { symbolic, .. }
            | Backend::Gmres { symbolic, .. } => Some(symbolic),
            Backend::Empty | Backend::Cg(_) | Backend::Lu(_) => None,
        }
    }

    /// Nonzeros of the Cholesky factor (0 without one).
    pub(super) fn factor_nnz(&self) -> usize {
        match self {
            Backend::Simplicial { values, .. } | Backend::Gmres { values, .. } => values.len(),
            Backend::Supernodal { values, .. } => match values {
                Values::Double(v) => v.len(),
                Values::Single(v) => v.len(),
            },
            Backend::Empty | Backend::Cg(_) | Backend::Lu(_) => 0,
        }
    }

    /// Bytes of the Cholesky factor: values (8 or 4 per nonzero, see
    /// [`FactorPrecision`]) and its row indices.
    pub(super) fn factor_bytes(&self) -> usize {
        let value_bytes = match self {
            Backend::Supernodal {
                values: Values::Single(v),
                ..
            } => v.len() * 4,
            _ => self.factor_nnz() * 8,
        };
        let indices = match self.symbolic().map(|s| s.raw()) {
            Some(SymbolicCholeskyRaw::Supernodal(sn)) => sn.row_idx().len() * 8,
            Some(SymbolicCholeskyRaw::Simplicial(_)) => self.factor_nnz() * 8,
            None => 0,
        };
        value_bytes + indices
    }
}

/// eq. (23)'s `K_UU` as a faer matrix, for its sparse LU.
fn to_faer(k_uu: &sprs::CsMat<Real>, n: usize) -> SparseColMat<usize, Real> {
    let csc = k_uu.to_csc();
    let (p, i, v) = (csc.indptr(), csc.indices(), csc.data());
    let col_ptr: Vec<usize> = (0..=n).map(|j| p.index(j)).collect();
    let sym = SymbolicSparseColMat::new_unsorted_checked(n, n, col_ptr, None, i.to_vec());
    SparseColMat::new(sym, v.to_vec())
}

/// Bytes a factor with this symbolic structure will hold: 8 (or 4, single
/// precision, supernodal only) per value, plus the row indices (one per
/// value for a simplicial factor, one per supernode row otherwise).
pub(crate) fn estimated_factor_bytes(
    symbolic: &SymbolicCholesky<usize>,
    precision: FactorPrecision,
) -> usize {
    let values = symbolic.len_val();
    match symbolic.raw() {
        SymbolicCholeskyRaw::Supernodal(sn) => {
            let value_bytes = match precision {
                FactorPrecision::Double => 8,
                FactorPrecision::Single => 4,
            };
            values
                .saturating_mul(value_bytes)
                .saturating_add(sn.row_idx().len().saturating_mul(8))
        }
        SymbolicCholeskyRaw::Simplicial(_) => values.saturating_mul(16),
    }
}

/// Floating-point operations of the numeric factorisation of a supernodal
/// factor ([`super::Factor::factor_flops`]); 0 for a simplicial one.
pub(super) fn symbolic_flops(symbolic: &SymbolicCholesky<usize>) -> f64 {
    let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
        return 0.0;
    };
    let (begin, end, cpr) = (
        sn.supernode_begin(),
        sn.supernode_end(),
        sn.col_ptr_for_row_idx(),
    );
    (0..sn.n_supernodes())
        .map(|s| {
            let w = end[s] - begin[s];
            let below = cpr[s + 1] - cpr[s];
            (0..w)
                .map(|k| ((w - k + below) as f64).powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// Whether a supernodal factor is analysed for two-thread sweeps: where
/// the machine has two cores, also when the factor is built inside a
/// one-thread pool (a server's solve that runs beside others), so that
/// the session's later solves, alone, use both. On one thread the plan's
/// sweeps run one after the other, with the same result.
fn two_threads_available() -> bool {
    rayon::current_num_threads() > 1
        || std::thread::available_parallelism().is_ok_and(|n| n.get() > 1)
}
