//! The factor cache (design.md §4.4): one sparse Cholesky factor of the normal
//! matrix `M` per (rest mesh, energy, λs, mode, constrained vertex set),
//! reused for every drag and every iteration.
//!
//! Symbolic analysis (fill-reducing ordering: AMD, or METIS nested
//! dissection on large systems; supernodal structure) and
//! numeric factorisation use faer's sparse Cholesky, the fastest well-kept
//! Rust implementation measured for this matrix (see README).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use faer::dyn_stack::{MemStack, StackReq};
use faer::sparse::linalg::cholesky::{LltRef, SymbolicCholeskyRaw};
use faer::{Conj, MatMut, Par};

use crate::deform::constraints::Constraints;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::energy::Energy;
use crate::deform::error::DeformError;
use crate::deform::params::{Formulation, FormulationParams, Mode, Params};
use crate::deform::rest::Rest;
use crate::deform::square::{self, Square};
use crate::deform::system::{Prepared, System};
use crate::mesh::{Point, Real};
use dend_linalg::cg::Cg;
use dend_linalg::cholesky::analyse;
use dend_linalg::trisolve;

mod backend;
pub(super) mod cache;
mod options;
mod stage;

#[cfg(test)]
pub(super) mod tests;

use crate::deform::elastic::elastic_system;
use backend::{symbolic_flops, Backend, Values};
pub use options::{FactorPrecision, SolveOptions, SolverChoice};
pub use stage::BuildStage;

/// What a factor depends on, and nothing else: two equal keys give the same
/// matrix `M`. Handle *targets* are not part of it.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct FactorKey {
    pub(crate) rest_id: u64,
    energy: (u8, u64, u64),
    lambda1: u64,
    lambda2: u64,
    formulation: FormulationKey,
    constrained: Vec<u32>,
}

/// The part of a [`FactorKey`] that its formulation's own parameters
/// make: the elastic weights that shape `Q` (not the coarse-level
/// schedule), or a paper formulation and its mode.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
enum FormulationKey {
    Elastic {
        stretch: u64,
        bending: u64,
        area: u64,
        laplacian: u64,
    },
    Paper(Formulation, Mode),
}

impl FactorKey {
    /// The key of `params` and the constrained set of `constraints` on `rest`.
    pub fn new(rest: &Rest, params: &Params, constraints: &Constraints) -> Self {
        Self::of_internal(rest, params, &rest.internal_constraints(constraints))
    }

    /// [`FactorKey::new`] for constraints already in the solver's vertex
    /// order ([`Rest::vertex_order`]).
    pub(crate) fn of_internal(rest: &Rest, params: &Params, constraints: &Constraints) -> Self {
        FactorKey {
            rest_id: rest.id(),
            energy: params.energy.key(),
            lambda1: params.lambda1.to_bits(),
            lambda2: params.lambda2.to_bits(),
            formulation: match params.elastic() {
                Some(e) => FormulationKey::Elastic {
                    stretch: e.stretch.to_bits(),
                    bending: e.bending.to_bits(),
                    area: e.area.to_bits(),
                    laplacian: e.laplacian.to_bits(),
                },
                None => FormulationKey::Paper(params.formulation.kind(), params.mode()),
            },
            constrained: constraints.constrained(),
        }
    }
}

/// How long each stage of a factor build took.
#[derive(Debug, Clone, Copy, Default)]
pub struct FactorTimings {
    /// Energy matrix, stacked rows and `M = JᵀJ`.
    pub assembly: Duration,
    /// Fill-reducing ordering and symbolic factorisation.
    pub symbolic: Duration,
    /// Numeric Cholesky factorisation.
    pub numeric: Duration,
}

static NEXT_FACTOR_ID: AtomicU64 = AtomicU64::new(1);

/// One factorised constraint set: the stacked rows, the rest-state target
/// `A X`, and the Cholesky factor of `M`. Immutable and shareable.
pub struct Factor {
    /// Process-unique id (a deformer's cached evaluation refers to it).
    id: u64,
    key: FactorKey,
    pub(crate) sys: System,
    pub(crate) energy: Energy,
    /// The eq. (23) operators when built for [`Formulation::Square`]
    /// (then `sys` holds no stacked rows and `sys.m` is its SPD `N`).
    pub(crate) square: Option<Square>,
    /// `A X` on the normalised rest positions, `#V×3` (empty for the
    /// elastic formulation).
    pub(crate) ax: Vec<Point>,
    /// The elastic formulation's operators and system
    /// ([`Formulation::Elastic`]; then `sys.m` is `Q_UU`).
    pub(crate) elastic: Option<(Arc<ElasticOps>, ElasticSet)>,
    /// How `M X = B` is solved.
    backend: Backend,
    cg_iterations: AtomicU64,
    timings: FactorTimings,
}

impl std::fmt::Debug for Factor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Factor")
            .field("unknowns", &self.sys.unknowns.len())
            .field("factor_nnz", &self.factor_nnz())
            .field("timings", &self.timings)
            .finish()
    }
}

impl Factor {
    /// Assembles and factorises `M` for `constraints`' constrained set.
    ///
    /// Errors: a connected component without any constrained vertex
    /// ([`DeformError::Unconstrained`]); `M` not positive definite
    /// ([`DeformError::NotPositiveDefinite`], with the pivot); allocation
    /// failure ([`DeformError::OutOfMemory`]).
    pub fn build(
        rest: &Rest,
        params: &Params,
        constraints: &Constraints,
    ) -> Result<Factor, DeformError> {
        Self::build_with(rest, params, constraints, &SolveOptions::default())
    }

    /// [`Factor::build`] with a solver choice and factor memory budget: with
    /// CG (chosen, or [`SolverChoice::Auto`] over budget) `M` is assembled
    /// but not factorised, and every solve runs preconditioned CG.
    pub fn build_with(
        rest: &Rest,
        params: &Params,
        constraints: &Constraints,
        options: &SolveOptions,
    ) -> Result<Factor, DeformError> {
        Self::build_reporting(rest, params, constraints, options, &|_| {})
    }

    /// [`Factor::build_with`] calling `progress` as each [`BuildStage`]
    /// starts, in order (stages a build does not have are skipped: a CG
    /// solver has no numeric factorisation; eq. (24)'s symbolic analysis
    /// runs inside [`BuildStage::Assembly`], at the same time).
    pub fn build_reporting(
        rest: &Rest,
        params: &Params,
        constraints: &Constraints,
        options: &SolveOptions,
        progress: &dyn Fn(BuildStage),
    ) -> Result<Factor, DeformError> {
        params.validate()?;
        let constraints = rest.internal_constraints(constraints);
        let key = FactorKey::of_internal(rest, params, &constraints);
        check_components(&rest.mesh, &key.constrained)?;
        let t0 = Instant::now();
        progress(BuildStage::Assembly);
        let assembled = assemble(rest, params, &key.constrained, options)?;
        let t1 = Instant::now();
        let Assembled {
            sys,
            square,
            ax,
            elastic,
            analysed,
        } = assembled;
        let single_ok = square.is_none() && elastic.is_none();
        let built = Backend::build(
            &sys,
            params.formulation.kind(),
            square.as_ref(),
            single_ok,
            options,
            analysed,
            progress,
        )?;
        Ok(Factor {
            id: NEXT_FACTOR_ID.fetch_add(1, Ordering::Relaxed),
            key,
            sys,
            energy: params.energy,
            square,
            ax,
            elastic,
            backend: built.backend,
            cg_iterations: AtomicU64::new(0),
            timings: FactorTimings {
                assembly: t1 - t0,
                symbolic: built.symbolic,
                numeric: built.numeric,
            },
        })
    }

    /// Whether the factor is supernodal (then its solves use
    /// [`trisolve`]; small systems get faer's simplicial factor, solved by
    /// [`trisolve::simplicial`]).
    pub fn is_supernodal(&self) -> bool {
        matches!(
            self.backend.symbolic().map(|s| s.raw()),
            Some(SymbolicCholeskyRaw::Supernodal(_))
        )
    }

    /// The symbolic Cholesky factorisation (none for CG or LU).
    #[cfg(test)]
    pub(crate) fn symbolic(
        &self,
    ) -> Option<&faer::sparse::linalg::cholesky::SymbolicCholesky<usize>> {
        self.backend.symbolic()
    }

    /// A process-unique id of this factor.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// The key this factor was built for.
    pub fn key(&self) -> &FactorKey {
        &self.key
    }

    /// Stage timings of the build.
    pub fn timings(&self) -> FactorTimings {
        self.timings
    }

    /// Number of unknowns (free vertices, or all vertices with soft constraints).
    pub fn num_unknowns(&self) -> usize {
        self.sys.unknowns.len()
    }

    /// Nonzeros of the Cholesky factor (0 when solved by CG).
    pub fn factor_nnz(&self) -> usize {
        self.backend.factor_nnz()
    }

    /// Bytes of the Cholesky factor: values (8 or 4 per nonzero, see
    /// [`FactorPrecision`]) and its row indices.
    pub fn factor_bytes(&self) -> usize {
        self.backend.factor_bytes()
    }

    /// Floating-point operations of the numeric factorisation, counting a
    /// multiply-add as two: `Σ_j c_j²` over the factor's columns, `c_j` the
    /// nonzeros of column `j` on and below the diagonal (George & Liu 1981,
    /// §2.2). 0 for a simplicial factor or CG.
    pub fn factor_flops(&self) -> f64 {
        self.backend.symbolic().map_or(0.0, symbolic_flops)
    }

    /// Whether solves run preconditioned CG instead of a Cholesky factor.
    pub fn uses_cg(&self) -> bool {
        matches!(self.backend, Backend::Cg(_))
    }

    /// CG iterations run so far by all solves with this factor (0 for a
    /// Cholesky factor).
    pub fn cg_iterations(&self) -> u64 {
        self.cg_iterations.load(Ordering::Relaxed)
    }

    /// Approximate heap bytes held: factor values and indices, `M`.
    pub fn memory_bytes(&self) -> usize {
        let csr = |m: &sprs::CsMat<Real>| m.nnz() * 16 + (m.rows() + 1) * 8;
        let backend = match &self.backend {
            Backend::Supernodal { plan, .. } => plan.as_ref().map_or(0, |p| p.memory_bytes()),
            Backend::Cg(_) => self.sys.unknowns.len() * 8,
            _ => 0,
        };
        self.factor_bytes()
            + backend
            + csr(&self.sys.m)
            + self.ax.len() * 24
            + self.sys.col_of.len() * 4
            + self.square.as_ref().map_or(0, Square::memory_bytes)
            // the constraint set's Q and row masks (the ElasticOps are the
            // rest mesh's, shared)
            + self
                .elastic
                .as_ref()
                .map_or(0, |(_, set)| csr(&set.q) + 2 * set.free.len())
    }

    /// Scratch needed by [`Factor::solve_in_place`] for `k` right-hand sides.
    pub(crate) fn solve_scratch(&self, k: usize) -> StackReq {
        match &self.backend {
            Backend::Supernodal { symbolic, plan, .. } => match symbolic.raw() {
                SymbolicCholeskyRaw::Supernodal(sn) => trisolve::scratch(sn, plan.as_ref()),
                SymbolicCholeskyRaw::Simplicial(_) => unreachable!("a supernodal backend"),
            },
            Backend::Simplicial { symbolic, .. } => match symbolic.raw() {
                SymbolicCholeskyRaw::Simplicial(simp) => trisolve::simplicial::scratch(simp),
                SymbolicCholeskyRaw::Supernodal(_) => unreachable!("a simplicial backend"),
            },
            // eq. (23)'s preconditioner: faer's solve
            Backend::Gmres { symbolic, .. } => symbolic.solve_in_place_scratch::<Real>(k, Par::Seq),
            Backend::Cg(_) => Cg::scratch(self.sys.unknowns.len()),
            Backend::Empty | Backend::Lu(_) => StackReq::EMPTY, // LU allocates its own
        }
    }

    /// Solves `M X = B` in place for a column-major `|U| × k` block `b`.
    pub(crate) fn solve_in_place(&self, b: MatMut<'_, Real>, stack: &mut MemStack) {
        match &self.backend {
            Backend::Empty => {}
            Backend::Gmres { symbolic, values } => {
                let k_uu = self.square.as_ref().and_then(|q| q.k_uu.as_ref());
                let k_uu = k_uu.expect("a GMRES backend has eq. (23)'s K_UU");
                // eq. (23): GMRES on the exact K_UU, preconditioned by N's Cholesky
                let llt = LltRef::new(symbolic, values);
                let mut b = b;
                for j in 0..b.ncols() {
                    let mut col: Vec<Real> = (0..b.nrows()).map(|i| b[(i, j)]).collect();
                    let precond = |v: &mut [Real]| {
                        let m = MatMut::from_column_major_slice_mut(v, v.len(), 1);
                        llt.solve_in_place_with_conj(Conj::No, m, Par::Seq, stack);
                    };
                    square::gmres(k_uu, &mut col, precond, 1e-6, 60);
                    for (i, v) in col.into_iter().enumerate() {
                        b[(i, j)] = v;
                    }
                }
            }
            Backend::Supernodal {
                symbolic,
                values,
                plan,
            } => {
                let SymbolicCholeskyRaw::Supernodal(sn) = symbolic.raw() else {
                    unreachable!("a supernodal backend")
                };
                let (perm, plan) = (symbolic.perm(), plan.as_ref());
                match values {
                    Values::Single(v) => trisolve::solve_in_place(sn, perm, v, plan, b, stack),
                    Values::Double(v) => trisolve::solve_in_place(sn, perm, v, plan, b, stack),
                }
            }
            Backend::Simplicial { symbolic, values } => {
                let SymbolicCholeskyRaw::Simplicial(simp) = symbolic.raw() else {
                    unreachable!("a simplicial backend")
                };
                trisolve::simplicial::solve_in_place(simp, symbolic.perm(), values, b, stack)
            }
            Backend::Lu(lu) => {
                use faer::linalg::solvers::SolveCore;
                lu.solve_in_place_with_conj(Conj::No, b);
            }
            Backend::Cg(cg) => {
                let stats = cg.solve_in_place(&self.sys.m, b, stack);
                self.cg_iterations
                    .fetch_add(stats.iterations as u64, Ordering::Relaxed);
            }
        }
    }
}

/// Errors unless every connected component of `mesh` has a vertex of
/// `constrained` (else `M` is singular), and every index is a vertex.
fn check_components(mesh: &crate::mesh::Mesh, constrained: &[u32]) -> Result<(), DeformError> {
    let mut pinned = vec![false; mesh.topology().num_components()];
    for &c in constrained {
        if c as usize >= mesh.num_vertices() {
            return Err(DeformError::UnknownVertex {
                index: c as u64,
                vertices: mesh.num_vertices(),
            });
        }
        if let Some(k) = mesh.topology().component(c as usize) {
            pinned[k as usize] = true;
        }
    }
    if let Some(k) = pinned.iter().position(|&p| !p) {
        let vertex = (0..mesh.num_vertices())
            .find(|&v| mesh.topology().component(v) == Some(k as u32))
            .unwrap_or(0) as u32;
        return Err(DeformError::Unconstrained {
            component: k,
            vertex,
        });
    }
    Ok(())
}

/// `M` assembled for a formulation, with what the factor keeps beside it.
struct Assembled {
    sys: System,
    square: Option<Square>,
    ax: Vec<Point>,
    elastic: Option<(Arc<ElasticOps>, ElasticSet)>,
    /// The symbolic analysis, when run beside `M`'s values.
    analysed: Option<backend::Analysed>,
}

/// Assembles `M` (eq. (24), (23) or the elastic `Q_UU`). For eq. (24) `M`'s
/// pattern comes first, then its values and the symbolic analysis (which
/// needs the pattern only) at the same time.
fn assemble(
    rest: &Rest,
    params: &Params,
    constrained: &[u32],
    options: &SolveOptions,
) -> Result<Assembled, DeformError> {
    let ops = rest.operators();
    let mut analysed = None;
    let mut elastic = None;
    let (sys, square, ax) = match &params.formulation {
        FormulationParams::LeastSquares(_) => {
            let energy = rest.energy(params.energy);
            let prep = Prepared::new(ops, &energy.a, params, constrained, rest.active());
            let values = if options.solver != SolverChoice::Cg && prep.num_unknowns() > 0 {
                let (values, symbolic) = rayon::join(
                    || prep.values(),
                    || {
                        let t = Instant::now();
                        let (col_ptr, row_idx) = prep.pattern();
                        (analyse(col_ptr, row_idx, options.ordering), t.elapsed())
                    },
                );
                analysed = Some(symbolic);
                values
            } else {
                prep.values()
            };
            (prep.into_system(values), None, energy.ax.clone())
        }
        FormulationParams::Square(_) | FormulationParams::SquareLu(_) => {
            let (sys, sq, ax) = square::assemble(ops, params, constrained, rest.active())?;
            (sys, Some(sq), ax)
        }
        FormulationParams::Elastic(weights) => {
            let el = rest.elastic(params, weights);
            let set = el.system(ops, constrained);
            let sys = elastic_system(&set, params, constrained, rest.active());
            elastic = Some((el, set));
            (sys, None, Vec::new())
        }
    };
    Ok(Assembled {
        sys,
        square,
        ax,
        elastic,
        analysed,
    })
}
