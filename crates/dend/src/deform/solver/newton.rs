//! The coarsest level's iteration: Gauss–Newton steps on the energy
//! reduced over the rotations, with a line search on the energy.
//!
//! The local/global iteration converges slowly where a far part must turn
//! as a whole: at fixed rotations the global step resists the turn, so
//! each iteration takes a share of it, at every resolution (the coarsest
//! level of a 10k-vertex camel took 120 iterations from rest). On the
//! coarsest level of a hierarchy (under
//! [`coarse::MIN_VERTICES`](crate::deform::coarse::MIN_VERTICES)
//! vertices) a step of Newton's method is affordable: the matrix
//! `H = Q ⊗ I₃ − Σ_e J_eᵀ C_e⁻¹ J_e` (`elastic/hessian.rs`), assembled
//! and factored (faer's sparse Cholesky; its symbolic analysis once per
//! constraint set) at every iteration. With `r = g(R, P) − Q Y` the
//! residual at the pose's best rotations (`−½` the reduced energy's
//! gradient, by the envelope theorem),
//!
//! ```text
//! H_UU Δ = r_U,    Y ← Y + α Δ,   α the first of 1, ½, ¼, ⅛ that lowers E
//! ```
//!
//! and where none lowers it, or `H` does not factor, the plain
//! local/global step is taken: so the energy never grows, as on every
//! other level. The convergence test is every level's: the plain step's
//! largest vertex move (computed at each iteration with the cached factor
//! of `Q_UU`).

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMat, Triplet};
use faer::{MatMut, Side};

use super::Deformer;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::factor::Factor;
use crate::mesh::Real;

/// The line search's step lengths, tried in order.
const STEPS: [Real; 4] = [1.0, 0.5, 0.25, 0.125];

/// What a Newton iteration costs in iterations of the same level's
/// local/global step (assembly and numeric factorisation of the `3|U|`
/// matrix, the solve and the line search's local steps), for the work
/// measure [`StepReport::coarse_work`](crate::deform::StepReport::coarse_work).
pub(super) const NEWTON_COST: Real = 4.0;

/// The Newton iteration's memory: the symbolic factorisation of `H`'s
/// pattern for one factor, the triplets and the right-hand side.
#[derive(Default)]
pub(super) struct NewtonState {
    symbolic: Option<(u64, SymbolicLlt<usize>)>,
    triplets: Vec<Triplet<usize, usize, Real>>,
    /// `r_U`, then `Δ`, interleaved (`3u + k`).
    pub(super) rhs: Vec<Real>,
}

impl Deformer {
    /// Keeps `r_U` (the global step's right-hand side, column-major in
    /// `rhs`) for the Newton step of this iteration.
    pub(super) fn keep_newton_rhs(&mut self, nu: usize) {
        let st = &mut self.elastic;
        let n = &mut st.newton;
        n.rhs.resize(3 * nu, 0.0);
        for k in 0..nu {
            for a in 0..3 {
                n.rhs[3 * k + a] = st.rhs[a * nu + k];
            }
        }
    }

    /// The Newton candidate of this iteration (module docs): sets the pose
    /// (and rotations, area targets) to the first step along `Δ` whose
    /// energy is below `e` and returns that energy; `None`, with the pose
    /// unchanged, when `H` does not factor or no step lowers the energy.
    /// `st.x_flat` holds the current unknowns.
    pub(super) fn newton_candidate(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        e: Real,
    ) -> Option<Real> {
        let sys = &factor.sys;
        let nu = sys.unknowns.len();
        let st = &mut self.elastic;
        let n = &mut st.newton;
        n.triplets.clear();
        for (r, row) in sys.m.outer_iterator().enumerate() {
            for (c, &v) in row.iter() {
                for a in 0..3 {
                    n.triplets.push(Triplet::new(3 * r + a, 3 * c + a, v));
                }
            }
        }
        el.rotation_coupling(
            set,
            &self.rest.ops,
            &st.rot,
            &st.proj,
            &sys.col_of,
            &mut n.triplets,
        );
        let h =
            SparseColMat::<usize, Real>::try_new_from_triplets(3 * nu, 3 * nu, &n.triplets).ok()?;
        let symbolic = match &n.symbolic {
            Some((id, s)) if *id == factor.id() => s.clone(),
            _ => {
                let s = SymbolicLlt::try_new(h.symbolic(), Side::Lower).ok()?;
                n.symbolic = Some((factor.id(), s.clone()));
                s
            }
        };
        let llt = Llt::try_new_with_symbolic(symbolic, h.as_ref(), Side::Lower).ok()?;
        llt.solve_in_place(MatMut::from_column_major_slice_mut(&mut n.rhs, 3 * nu, 1));
        if n.rhs.iter().any(|v| !v.is_finite()) {
            return None;
        }
        for alpha in STEPS {
            let st = &mut self.elastic;
            for k in 0..nu {
                for a in 0..3 {
                    st.cand[a * nu + k] = st.x_flat[a * nu + k] + alpha * st.newton.rhs[3 * k + a];
                }
            }
            self.set_unknowns(factor, super::local_global::Flat::Candidate);
            let e_try = self.local_step(factor, (el, set), true, true);
            if e_try.is_finite() && e_try < e {
                let st = &mut self.elastic;
                std::mem::swap(&mut st.rot, &mut st.rot_try);
                std::mem::swap(&mut st.proj, &mut st.proj_try);
                return Some(e_try);
            }
        }
        None
    }
}
