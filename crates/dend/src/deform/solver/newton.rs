//! Newton steps on the energy reduced over the rotations and area
//! targets, with a line search on the energy: every iteration of a
//! hierarchy's coarsest level, and the rest of a slow sequence on a small
//! mesh ([`Deformer::takes_newton_step`]).
//!
//! The local/global iteration converges slowly where a far part must turn
//! as a whole: at fixed rotations the global step resists the turn, so
//! each iteration takes a share of it, at every resolution (the coarsest
//! level of a 10k-vertex camel took 120 iterations from rest). On a small
//! mesh or level (the coarsest level of a hierarchy, under
//! [`coarse::MIN_VERTICES`](crate::deform::coarse::MIN_VERTICES)
//! vertices, or any of at most [`NEWTON_MAX_VERTICES`]) a step of
//! Newton's method is affordable: the matrix
//! `H = Q ⊗ I₃ − Σ_e J_eᵀ C_e⁻¹ J_e` (`elastic/hessian.rs`), assembled
//! and factored at every iteration: the reduced energy's Hessian where it
//! is positive definite (it factors), else its convex model, each
//! element's curvature cut to its positive semi-definite part (only the
//! elements whose curvature is indefinite are computed again for it).
//! Its pattern does not depend on the rotations, so it is analysed once
//! per constraint set ([`NewtonPattern`], `solver/newton_pattern.rs`):
//! the blocks of `Q`'s pattern and of the elements' supports, ordered by
//! AMD on the block graph (each vertex's three coordinates stay together,
//! as one supernode column block), with the plan that sums the elements'
//! blocks into it; each iteration computes the elements' blocks and sums
//! them in place (both in parallel), and runs the numeric factorisation
//! only. With `r = g(R, P) − Q Y` the
//! residual at the pose's best rotations (`−½` the reduced energy's
//! gradient, by the envelope theorem),
//!
//! ```text
//! H_UU Δ = r_U,    Y ← Y + α Δ,   α the first of 1, ½, ¼, ⅛ that lowers E
//! ```
//!
//! where a trial `Y + αΔ` does not lower `E`, the local/global map applied
//! to it (its rotations, then one global step from them) is tried before
//! the next length ([`Deformer::global_step_from_trial`]); where no length
//! lowers it with the exact Hessian, the convex model's step is tried the
//! same way; and where none lowers it, or `H` does not factor, the plain
//! local/global step is taken: so the energy never grows, as on every
//! other level. The convergence test is every level's: the plain step's
//! largest vertex move (computed at each iteration with the cached factor
//! of `Q_UU`).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::cholesky::LltRef;
use faer::{Conj, MatMut, Par};

use super::local_global::Flat;
use super::newton_state::{NewtonPattern, NEWTON_COST};
use super::Deformer;
use crate::deform::elastic::hessian::Curvature;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::factor::Factor;
use crate::mesh::Real;

/// The line search's step lengths, tried in order.
const STEPS: [Real; 4] = [1.0, 0.5, 0.25, 0.125];

/// How many Newton iterations after the exact Hessian failed to factor
/// take the convex model directly.
const CONVEX_AFTER_FAILURE: usize = 2;

/// The fewest local/global iterations a sequence runs before it may
/// switch to Newton steps ([`Deformer::takes_newton_step`]): an edit that
/// converges in fewer never pays a Newton iteration's cost.
pub(super) const NEWTON_AFTER: usize = 20;

/// The iterations over which a sequence's rate of convergence is measured
/// ([`Deformer::takes_newton_step`]).
const RATE_WINDOW: usize = 5;

/// A sequence switches to Newton steps when the local/global iterations it
/// still needs at its measured rate exceed this many: about the cost of
/// the 4–6 Newton iterations that converge it ([`NEWTON_COST`] each).
const NEWTON_SWITCH: Real = 5.0 * NEWTON_COST;

/// The most vertices of a mesh whose slow sequences switch to Newton
/// steps: a Newton iteration costs about [`NEWTON_COST`] local/global
/// iterations on meshes of 800–1100 vertices, and more above (its factor
/// fills faster than the global step's).
pub(super) const NEWTON_MAX_VERTICES: usize = 2000;

impl Deformer {
    /// Whether this iteration takes a Newton step: on the coarsest level of
    /// a hierarchy always, and on a small mesh once its sequence has run
    /// [`NEWTON_AFTER`] iterations and its rate of convergence predicts
    /// more than [`NEWTON_SWITCH`] more (it then takes them to the end of
    /// the sequence: Newton's method converges fast only over consecutive
    /// steps).
    pub(super) fn takes_newton_step(&self) -> bool {
        self.newton || self.elastic.newton_now
    }

    /// Records an iteration's update `max_dx` (the plain step's largest
    /// move) for [`Deformer::takes_newton_step`].
    pub(super) fn note_update(&mut self, max_dx: Real) {
        let small = self.rest.mesh.num_vertices() <= NEWTON_MAX_VERTICES;
        let tol = self.params.tol;
        let st = &mut self.elastic;
        st.sequence_iterations += 1;
        if st.recent_updates.len() > RATE_WINDOW {
            st.recent_updates.pop_front();
        }
        st.recent_updates.push_back(max_dx);
        if st.newton_now || !small || st.sequence_iterations < NEWTON_AFTER {
            return;
        }
        if let (Some(&first), true) = (
            st.recent_updates.front(),
            st.recent_updates.len() > RATE_WINDOW,
        ) {
            // the update's mean rate of decrease over the window
            let rate = (max_dx / first).powf(1.0 / RATE_WINDOW as Real);
            let remaining = if rate < 1.0 {
                (tol / max_dx).ln() / rate.ln()
            } else {
                Real::INFINITY
            };
            st.newton_now = remaining > NEWTON_SWITCH;
        }
    }

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

    /// Analyses `H`'s pattern for `factor`'s constraint set
    /// ([`NewtonPattern`]) unless it is already analysed: once per set,
    /// on the first Newton step or before any ([`Deformer::prepare_levels`]).
    pub(super) fn prepare_newton(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
    ) {
        let n = &mut self.elastic.newton;
        if n.pattern.as_ref().map(|p| p.factor_id) != Some(factor.id()) {
            n.pattern = NewtonPattern::new(factor, el, set, &self.rest.ops);
        }
    }

    /// `H`'s values at the current rotations and area targets, written
    /// into the pattern of `factor` (built on first use); `None` when the
    /// pattern could not be analysed. With `patch` (the last assembly was
    /// this iteration's [`Curvature::Full`] one, and `curvature` is
    /// [`Curvature::Projected`]) only the elements whose curvature was
    /// indefinite are computed again, and `Some(false)` says there were
    /// none (`H` is unchanged).
    pub(super) fn assemble_newton(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        curvature: Curvature,
        patch: bool,
    ) -> Option<bool> {
        self.prepare_newton(factor, (el, set));
        let st = &mut self.elastic;
        let pattern = st.newton.pattern.as_mut()?;
        if patch && !pattern.indefinite.contains(&true) {
            return Some(false);
        }
        el.coupling_blocks(
            &pattern.elements,
            &self.rest.ops,
            (&self.y, &st.rot, &st.proj),
            curvature,
            &mut pattern.blocks,
            &mut pattern.indefinite,
            patch,
        );
        pattern.gather(&factor.sys.m);
        Some(true)
    }

    /// The Newton candidate of this iteration (module docs): sets the pose
    /// (and rotations, area targets) to the first step along `Δ` whose
    /// energy is below `e` and returns that energy; `None`, with the plain
    /// step in `rhs` for the caller to take, when `H` does not factor or no
    /// step lowers the energy. `st.x_flat` holds the current unknowns.
    ///
    /// The convex model is tried where the exact Hessian's step lowers
    /// nothing, not only where it does not factor: on the camel's
    /// coarsest level, at the start of the settle after a 30 Hz gesture,
    /// the exact Hessian factored but its step moved vertices 30
    /// normalised units against the plain step's 0.0035 (a direction it
    /// barely resists), no length lowered the energy, the level's
    /// correction crawled to its cap on local/global iterations, and the
    /// settle took 61 fine iterations instead of 22–24.
    pub(super) fn newton_candidate(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        e: Real,
    ) -> Option<Real> {
        // the reduced energy's Hessian where it is positive definite (near
        // a minimum: quadratic convergence), else its convex model
        // (where the exact Hessian did not factor, it is not tried again
        // for the next `CONVEX_AFTER_FAILURE` iterations: a failed
        // factorisation costs about as much as one that succeeds)
        let skip = self.elastic.newton.convex_for > 0;
        self.elastic.newton.convex_for = self.elastic.newton.convex_for.saturating_sub(1);
        let tries: &[Curvature] = if skip {
            &[Curvature::Projected]
        } else {
            &[Curvature::Full, Curvature::Projected]
        };
        // `r_U`, which each solve below overwrites with its `Δ`, and the
        // plain step, which the caller takes where no Newton step lowers
        // the energy (the line search's global steps use its buffer)
        let st = &mut self.elastic;
        st.newton.r.clone_from(&st.newton.rhs);
        st.newton.plain.clone_from(&st.rhs);
        st.newton.rot0.clone_from(&st.rot);
        st.newton.proj0.clone_from(&st.proj);
        let stepped = self.newton_tries(factor, (el, set), e, tries, skip);
        if stepped.is_none() {
            let st = &mut self.elastic;
            st.rhs.copy_from_slice(&st.newton.plain);
        }
        stepped
    }

    /// The Newton steps of [`Deformer::newton_candidate`] with each
    /// curvature of `tries` in turn (the next where `H` does not factor or
    /// no step length lowers the energy), from `r_U` in `newton.r`.
    fn newton_tries(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        e: Real,
        tries: &[Curvature],
        skip: bool,
    ) -> Option<Real> {
        let nu = factor.sys.unknowns.len();
        for (k, &curvature) in tries.iter().enumerate() {
            if k > 0 {
                // (a line search may have moved the pose: the matrix is
                // assembled where the step starts)
                self.restore_newton_start(factor);
            }
            // after the exact Hessian, only its indefinite elements change
            let patch = curvature == Curvature::Projected && !skip;
            if !self.assemble_newton(factor, (el, set), curvature, patch)? {
                break;
            }
            let n = &mut self.elastic.newton;
            let pattern = n.pattern.as_mut()?;
            if pattern
                .refactor
                .factorise_definite(&pattern.symbolic, &pattern.h)
                .is_err()
            {
                if curvature == Curvature::Full {
                    n.convex_for = CONVEX_AFTER_FAILURE;
                }
                continue;
            }
            let llt = LltRef::new(&pattern.symbolic, pattern.refactor.values());
            let mut mem =
                MemBuffer::try_new(pattern.symbolic.solve_in_place_scratch::<Real>(1, Par::Seq))
                    .ok()?;
            n.rhs.copy_from_slice(&n.r);
            llt.solve_in_place_with_conj(
                Conj::No,
                MatMut::from_column_major_slice_mut(&mut n.rhs, 3 * nu, 1),
                Par::Seq,
                MemStack::new(&mut mem),
            );
            if n.rhs.iter().any(|v| !v.is_finite()) {
                continue;
            }
            if let Some(e_new) = self.newton_line_search(factor, (el, set), e, curvature) {
                return Some(e_new);
            }
        }
        None
    }

    /// Puts back the pose (its unknowns from `x_flat`), rotations and area
    /// targets the Newton step started from.
    fn restore_newton_start(&mut self, factor: &Factor) {
        let st = &mut self.elastic;
        st.cand.copy_from_slice(&st.x_flat);
        st.rot.copy_from_slice(&st.newton.rot0);
        st.proj.copy_from_slice(&st.newton.proj0);
        self.set_unknowns(factor, Flat::Candidate);
    }

    /// Keeps the first step along `Δ` (in `newton.rhs`) whose energy,
    /// after [`Deformer::global_step_from_trial`], is below `e`, and
    /// returns that energy; `None` where no step length lowers it.
    fn newton_line_search(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        e: Real,
        curvature: Curvature,
    ) -> Option<Real> {
        let nu = factor.sys.unknowns.len();
        for alpha in STEPS {
            let st = &mut self.elastic;
            for k in 0..nu {
                for a in 0..3 {
                    st.cand[a * nu + k] = st.x_flat[a * nu + k] + alpha * st.newton.rhs[3 * k + a];
                }
            }
            self.set_unknowns(factor, Flat::Candidate);
            let e_try = self.local_step(factor, (el, set), true, true);
            if !e_try.is_finite() {
                continue;
            }
            if e_try < e {
                tracing::debug!(?curvature, alpha, e, e_try, "newton step");
                self.elastic.swap_trial();
                return Some(e_try);
            }
            if let Some(e_g) = self.global_step_from_trial(factor, (el, set)) {
                if e_g < e {
                    tracing::debug!(?curvature, alpha, e, e_try, e_g, "newton step");
                    return Some(e_g);
                }
            }
        }
        tracing::debug!(
            ?curvature,
            e,
            "newton step: no step length lowers the energy"
        );
        None
    }

    /// The local/global map applied to a Newton trial: from the trial pose
    /// `Y'` (the unknowns in `cand`) and its best rotations and area
    /// targets (`rot_try`, `proj_try`), one global step
    /// `Y'' = Y' + Q_UU⁻¹ (g(R(Y')) − Q Y')_U`, then its own rotations.
    /// Keeps `Y''` with its rotations and returns its energy; `None` where
    /// the solve is not finite (the rotations are then those before the
    /// trial, the pose the trial's).
    ///
    /// Why: a Newton step is linear in the positions, so where a part
    /// turns as a whole (a dangling limb swinging, a twisted bar) a long
    /// step stretches it along the tangent of the turn, and its energy
    /// rises although the turn was right: the line search shortened the
    /// steps of a camel gesture's coarsest level to ½–⅛, or found none.
    /// The rotations of `Y'` carry the turn, and the global step from them
    /// places the part without the stretch: `E(Y'') ≤ E(Y', R(Y'))` (the
    /// global step minimises `E(·, R)` exactly, and the local step
    /// refits), for one more solve with the cached factor of `Q_UU` and
    /// one more local step. It is tried only where `Y'` itself does not
    /// lower the energy: taken after every trial, it left the
    /// characters' one-shots as they were but cost the survey cactus 6
    /// iterations (31 → 37) and the camel's settle 2–4.
    pub(super) fn global_step_from_trial(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
    ) -> Option<Real> {
        self.elastic.swap_trial();
        if !self.elastic_global_step(factor, (el, set)) {
            self.elastic.swap_trial();
            return None;
        }
        let st = &mut self.elastic;
        for (c, d) in st.cand.iter_mut().zip(&st.rhs) {
            *c += d;
        }
        self.set_unknowns(factor, Flat::Candidate);
        let e_g = self.local_step(factor, (el, set), true, true);
        self.elastic.swap_trial();
        e_g.is_finite().then_some(e_g)
    }
}
