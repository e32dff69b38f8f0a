//! The elastic formulation's iteration ([`Formulation::Elastic`], see
//! `deform::elastic` for the objective `E(Y, R)`): alternating exact
//! minimisers, accelerated with a safeguard.
//!
//! One iteration, from the pose `Y` and its best rotations `R = R(Y)`:
//! 1. **global step**: `Δ_U = Q_UU⁻¹ (g(R) − Q Y)_U` with the cached
//!    factor; `G(Y) = Y + Δ` minimises `E(·, R)` exactly;
//! 2. **acceleration**: Anderson's extrapolation of the map `G` from the
//!    last `m` iterates (Peng et al. 2018);
//! 3. **local step** on the candidate: `R_i = argmax tr(R_iᵀ M_i)`, exact
//!    per vertex, which also gives `E(candidate, R(candidate))`;
//! 4. **safeguard**: the accelerated candidate is kept only if its energy
//!    is below the current one; otherwise the plain `G(Y)` is taken (and
//!    step 3 runs on it). `E(G(Y), R(G(Y))) ≤ E(G(Y), R) ≤ E(Y, R)`, so
//!    the energy never grows (up to rounding).
//!
//! Convergence: the plain step's largest vertex move `max_i |Δ_i|` below
//! `tol` mean edge lengths. The Anderson history, the rotations and the
//! energy carry over between calls on unchanged targets (a settle loop of
//! one-iteration frames is one iteration sequence), and restart when the
//! targets or the pose change.
//!
//! A sequence from the rest pose starts from the rotations of the same
//! problem solved on a coarse mesh (`solver/multilevel.rs`, `deform::coarse`)
//! where the mesh has one and the constraint set survives on it, else from
//! the handles' rotations spread by harmonic weights.
//!
//! [`Formulation::Elastic`]: crate::deform::Formulation::Elastic

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::MatMut;
use nalgebra::UnitQuaternion;

use super::levels::{CoarseRun, Levels};
use super::state::{Start, State};
use super::{Deformer, StepReport};
use crate::deform::anderson::Anderson;
use crate::deform::constraints::Constraints;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::error::DeformError;
use crate::deform::factor::Factor;
use crate::deform::params::DetailTerm;
use crate::deform::stacked::mul_l;
use crate::mesh::Real;

/// How far (mean edge lengths) a target may be from its vertex's rest
/// position and still count as the rest position
/// ([`Deformer::targets_at_rest`]): rounding, not a move.
const REST_TARGET_TOLERANCE: Real = 1e-9;

/// The relative growth of an iteration's update over the last one's that
/// counts towards [`Deformer::drift_limit`]: above rounding, far below the
/// 1–4 % a drifting solve grows by per iteration.
const DRIFT_MARGIN: Real = 1e-6;

/// Newton candidates in a row that lower nothing (the plain step is taken
/// each time) after which a sequence takes no more Newton steps. Near a
/// pose where the energy buckles (the survey bar twisted 135°, its
/// 1521-vertex level's start), the Hessian factors but its step raises
/// the energy at every length tried: 250 such iterations, each paying for
/// a factorisation, ran to the 300-iteration cap of the coarse start
/// (1.46 s of the edit's precomputation against 0.22 s); the local/global
/// iterations alone go on lowering it.
pub(super) const NEWTON_GIVE_UP: usize = 3;

impl State {
    /// Whether the next sequence starts from the rest pose.
    pub(super) fn starts_from_rest(&self) -> bool {
        self.start == Start::Rest
    }

    /// Forgets the continued sequence (the pose or parameters changed):
    /// the next step refits the rotations.
    pub(super) fn invalidate(&mut self) {
        self.chain = None;
        self.start = Start::Refit;
    }

    /// Continues from a pose set with `set_pose` with these rotations and
    /// the handles' rotations it was solved for (a coarse preview's first
    /// step from the fine state): the next step turns them by the
    /// handles' change of rotation.
    pub(super) fn warm_from(
        &mut self,
        rot: Vec<UnitQuaternion<Real>>,
        handle_rot: Vec<UnitQuaternion<Real>>,
    ) {
        self.chain = None;
        self.start = Start::Warm;
        self.rot_try = rot.clone();
        self.rot = rot;
        self.handle_rot = handle_rot;
        // recomputed from the rotations when the iteration is sized
        self.proj.clear();
    }

    /// Takes the trial rotations and area targets (`rot_try`, `proj_try`)
    /// as the current ones, and the current ones as the trial's.
    pub(super) fn swap_trial(&mut self) {
        std::mem::swap(&mut self.rot, &mut self.rot_try);
        std::mem::swap(&mut self.proj, &mut self.proj_try);
    }

    /// Back to the rest pose: identity rotations, propagated again on the
    /// next step.
    pub(super) fn reset(&mut self) {
        self.chain = None;
        self.start = Start::Rest;
        self.handle_rot.clear();
        self.rot.fill(UnitQuaternion::identity());
        self.proj.clear();
    }
}

impl Deformer {
    /// [`Deformer::step`] for the elastic formulation (module docs).
    pub(super) fn step_elastic(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        constraints: &Constraints,
        max_iters: usize,
    ) -> Result<StepReport, DeformError> {
        let moved = self.load_targets(factor, constraints)?;
        // (the factor's key, checked above, has the elastic weights)
        let Some(&weights) = self.params.elastic() else {
            return Err(DeformError::FactorMismatch);
        };
        let nu = factor.sys.unknowns.len();
        self.size_state(factor, el);
        // from the rest pose towards the rest positions (a new session's
        // first constraint set, anchored where the mesh is): the rest pose
        // is the minimum (every term is zero there), so one plain
        // iteration confirms it (a session times it) with no coarse start
        // or propagation built for it, and the next step still starts
        // from the rest pose
        let at_rest =
            self.elastic.starts_from_rest() && !self.shows_preview() && self.targets_at_rest();
        let max_iters = if at_rest {
            self.elastic.start = Start::Warm;
            max_iters.min(1)
        } else {
            max_iters
        };
        let fit = self.params.detail == DetailTerm::Nonlinear;
        let chain = self
            .elastic
            .chain
            .take()
            .filter(|&(id, _)| id == factor.id() && !moved && !self.shows_preview());
        let (mut e, coarse) = match chain {
            Some((_, e)) => (e, None),
            None => {
                let st = &mut self.elastic;
                st.sequence_iterations = 0;
                st.recent_updates.clear();
                st.newton_now = false;
                st.newton_failures = 0;
                self.start_sequence(factor, (el, set), constraints, moved && !at_rest)
            }
        };
        let st = &mut self.elastic;
        st.handle_rot.clear();
        st.handle_rot
            .extend(constraints.handles.iter().map(|h| h.target.rotation));
        let mut report = StepReport {
            iterations: 0,
            last_update: 0.0,
            converged: false,
            diverged: false,
            objective: e,
            initial_objective: e,
            coarse_iterations: coarse.map_or(0, |c| c.iterations),
            coarse_ms: coarse.map_or(0.0, |c| c.ms),
            coarse_work: coarse.map_or(0.0, |c| c.work),
            interrupted: false,
        };
        if nu == 0 {
            report.converged = true;
            self.sync_pose(factor);
            return Ok(report);
        }
        let accelerate = fit && self.params.anderson > 0;
        for _ in 0..max_iters {
            // (interrupted: stop where the state is a whole iteration's)
            if report.iterations > 0 && self.interrupted() {
                report.interrupted = true;
                break;
            }
            // 1. global step: Δ = Q_UU⁻¹ (g(R) − Q Y)_U
            self.global_rhs(factor, (el, set));
            let newton =
                fit && self.takes_newton_step() && self.elastic.newton_failures < NEWTON_GIVE_UP;
            if newton {
                self.keep_newton_rhs(nu);
            }
            if self.interrupted() {
                report.interrupted = true;
                break;
            }
            let st = &mut self.elastic;
            {
                let b = MatMut::from_column_major_slice_mut(&mut st.rhs, nu, 3);
                let mem = st.mem.as_mut().expect("sized above");
                factor.solve_in_place(b, MemStack::new(mem));
            }
            if self.interrupted() {
                report.interrupted = true;
                break;
            }
            let st = &mut self.elastic;
            if st.rhs.iter().any(|v| !v.is_finite()) {
                report.diverged = true;
                break;
            }
            let (max_dx, max_at) = (0..nu)
                .map(|k| {
                    let r = &st.rhs;
                    (r[k] * r[k] + r[nu + k] * r[nu + k] + r[2 * nu + k] * r[2 * nu + k]).sqrt()
                })
                .enumerate()
                .fold(
                    (0.0, 0),
                    |(m, at), (k, d)| if d > m { (d, k) } else { (m, at) },
                );
            for (k, &u) in factor.sys.unknowns.iter().enumerate() {
                let p = self.y[u as usize];
                st.x_flat[k] = p[0];
                st.x_flat[nu + k] = p[1];
                st.x_flat[2 * nu + k] = p[2];
            }
            // 2.–4. accelerated candidate, kept only if the energy falls
            let mut accepted = false;
            // a converged plain step is taken as it is: the pose returned is
            // the one the convergence test measured
            let accelerate = accelerate && max_dx >= self.params.tol && !newton;
            if newton && max_dx >= self.params.tol {
                if let Some(e_n) = self.newton_candidate(factor, (el, set), e) {
                    e = e_n;
                    accepted = true;
                    self.elastic.newton_failures = 0;
                } else {
                    self.elastic.newton_failures += 1;
                }
                report.coarse_work += super::newton_state::NEWTON_COST - 1.0;
            }
            let st = &mut self.elastic;
            if accelerate {
                dend_linalg::sparse::mul_columns::<3>(&factor.sys.m, &st.rhs, &mut st.mf);
            }
            if accelerate
                && st
                    .anderson
                    .step_in_metric(&st.x_flat, &st.rhs, Some(&st.mf), &mut st.cand)
            {
                self.set_unknowns(factor, Flat::Candidate);
                let e_aa = self.local_step(factor, (el, set), fit, true);
                if e_aa.is_finite() && e_aa < e {
                    self.elastic.swap_trial();
                    e = e_aa;
                    accepted = true;
                }
            }
            if !accepted {
                self.set_unknowns(factor, Flat::PlainStep);
                e = self.local_step(factor, (el, set), fit, false);
            }
            report.iterations += 1;
            tracing::trace!(
                vertices = self.y.len(),
                iteration = report.iterations,
                update = max_dx / self.params.tol,
                at = ?self
                    .rest
                    .ops
                    .denormalise(self.rest.ops.positions[factor.sys.unknowns[max_at] as usize]),
                energy = e,
                accepted,
                "iteration"
            );
            self.note_update(max_dx);
            report.last_update = max_dx;
            if !fit || max_dx < self.params.tol {
                report.converged = true;
                break;
            }
            let st = &mut self.elastic;
            // (grown by more than rounding: a renumbered mesh's updates
            // differ in their last bits)
            st.grew = if max_dx > st.last_update * (1.0 + DRIFT_MARGIN) {
                st.grew + 1
            } else {
                0
            };
            st.last_update = max_dx;
            if self.drift_limit.is_some_and(|k| st.grew >= k) {
                // drifting, not converging (`multilevel::CORRECTION_DRIFT`)
                break;
            }
            if st.e_mark.is_nan() {
                // the first global step moves the constrained vertices'
                // neighbours: the gains of corrections are compared with
                // the fine iterations after it
                st.e_mark = e;
            }
            let period = self.correction_period(weights.correction_period);
            let st = &mut self.elastic;
            if st.corrections {
                st.since_correction += 1;
                if st.since_correction >= period && !self.corrections_held {
                    e = self.correct(factor, (el, set), constraints, e, &mut report);
                }
            }
        }
        report.objective = e;
        // (at rest the next step starts from the rest pose again)
        self.elastic.chain = (!at_rest).then_some((factor.id(), e));
        if at_rest {
            self.elastic.start = Start::Rest;
        }
        self.sync_pose(factor);
        Ok(report)
    }

    /// Sizes the iteration's memory for this mesh, its area elements and
    /// `factor`'s unknowns and Anderson window (a new factor forgets the
    /// continued sequence).
    fn size_state(&mut self, factor: &Factor, el: &ElasticOps) {
        let n = self.y.len();
        let nu = factor.sys.unknowns.len();
        let window = self.params.anderson;
        let st = &mut self.elastic;
        if st.ly.len() != n {
            if st.rot.len() != n {
                // (rotations set before the first step are kept: `warm_from`)
                st.rot = vec![UnitQuaternion::identity(); n];
            }
            st.rot_try = st.rot.clone();
            st.ly = vec![[0.0; 3]; n];
            st.t = vec![[0.0; 3]; n];
            st.rm = vec![[0.0; 4]; n];
            st.res = vec![[0.0; 3]; n];
            st.proj = Vec::new();
        }
        if st.proj.len() != el.num_area_elements() {
            st.proj = vec![[0.0; 6]; el.num_area_elements()];
            st.proj_try = st.proj.clone();
            // consistent with the rotations before any local step
            el.rotated_rest_projections(&self.rest.ops.positions, &st.rot, &mut st.proj);
        }
        if st.sized_for != (factor.id(), window) || st.mem.is_none() {
            st.rhs = vec![0.0; 3 * nu];
            st.x_flat = vec![0.0; 3 * nu];
            st.cand = vec![0.0; 3 * nu];
            st.mf = vec![0.0; 3 * nu];
            st.anderson = Anderson::new(window, 3 * nu);
            st.mem = Some(MemBuffer::new(factor.solve_scratch(3)));
            st.sized_for = (factor.id(), window);
            st.chain = None;
        }
    }

    /// The first rotations and energy of a new iteration sequence
    /// ([`Start`]): from the rest pose the coarse start or the handles'
    /// rotations spread over the free vertices (the first global step then
    /// moves every vertex with its constraints: a translation or a common
    /// rotation of all of them is exact after one iteration); a replaced
    /// pose refits; a solved pose with new targets turns by the handles'
    /// change of rotation. Resets the acceleration and the corrections'
    /// schedule (drags count to their first correction like any sequence:
    /// taking it in the frame that answers a drag put a coarse solve into
    /// every such frame, camel drag→frame p50 7.5 → 65 ms).
    fn start_sequence(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        constraints: &Constraints,
        moved: bool,
    ) -> (Real, Option<CoarseRun>) {
        let fit = self.params.detail == DetailTerm::Nonlinear;
        // the coarse levels' detail weight, once their first corrections
        // have measured it (`solver/detail_fit.rs`)
        if self.detail_fit.decide() {
            self.drop_coarse_problems();
        }
        let st = &mut self.elastic;
        st.anderson.reset();
        st.corrections = fit && self.levels != Levels::One;
        st.since_correction = 0;
        st.e_mark = Real::NAN;
        st.last_update = Real::INFINITY;
        st.grew = 0;
        let start = std::mem::replace(&mut st.start, Start::Warm);
        st.on_hierarchy = start == Start::Rest;
        // constrained vertices whose rotation is not fitted carry their
        // handle's rotation (the fixed ones the identity)
        for &v in &constraints.fixed {
            if !set.fit[v as usize] {
                st.rot[v as usize] = UnitQuaternion::identity();
            }
        }
        for h in &constraints.handles {
            for &v in &h.vertices {
                if !set.fit[v as usize] {
                    st.rot[v as usize] = h.target.rotation;
                }
            }
        }
        if fit && self.adopt_preview(el, set) {
            // a sequence from a preview's pose is one from a pose, whatever
            // the fine pose was before it
            self.elastic.on_hierarchy = false;
            return (self.local_step(factor, (el, set), false, false), None);
        }
        match start {
            Start::Rest if fit => {
                // a held coarse start (`Deformer::hold_coarse_start`):
                // the handles' rotations spread harmonically instead
                let coarse = if self.coarse_start_held {
                    None
                } else {
                    self.coarse_start(factor, (el, set), constraints)
                };
                if coarse.is_none() {
                    self.propagate_rotations(factor, (el, set), constraints);
                }
                (self.local_step(factor, (el, set), false, false), coarse)
            }
            Start::Refit if fit => (self.local_step(factor, (el, set), true, false), None),
            Start::Warm if fit && moved => {
                self.propagate_rotation_change(factor, (el, set), constraints);
                (self.local_step(factor, (el, set), false, false), None)
            }
            _ => (self.local_step(factor, (el, set), false, false), None),
        }
    }

    /// Whether every loaded target ([`Deformer::load_targets`]) is its
    /// vertex's rest position, to [`REST_TARGET_TOLERANCE`] mean edge
    /// lengths (a target anchored at the rest pose went through its
    /// handle's identity transform and may differ by rounding).
    fn targets_at_rest(&self) -> bool {
        let rest = &self.rest.ops.positions;
        self.scratch.targets.iter().all(|&(v, t)| {
            let r = rest[v as usize];
            (0..3).all(|k| (t[k] - r[k]).abs() <= REST_TARGET_TOLERANCE)
        })
    }

    /// The local step on the current pose (`L Y`, then the rotations; into
    /// `rot_try` when `trial`, warm-started from `rot`), returning
    /// `E(Y, R)` plus the soft-constraint term. Without `fit` (the linear
    /// detail term) the rotations stay the identity.
    pub(super) fn local_step(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        fit: bool,
        trial: bool,
    ) -> Real {
        let ops = &self.rest.ops;
        let st = &mut self.elastic;
        mul_l(ops, &self.y, &mut st.ly);
        let (warm, rot, proj) = if trial {
            if !fit {
                // (fitting writes every projection)
                st.proj_try.copy_from_slice(&st.proj);
            }
            (Some(&st.rot[..]), &mut st.rot_try, &mut st.proj_try)
        } else {
            (None, &mut st.rot, &mut st.proj)
        };
        let e = el.local_step_from(set, ops, (&self.y, &st.ly), (warm, rot), proj, fit);
        let linear: Real = st
            .linear
            .iter()
            .zip(&self.y)
            .map(|(s, y)| s[0] * y[0] + s[1] * y[1] + s[2] * y[2])
            .sum();
        e - 2.0 * linear + factor.sys.soft_energy(&self.scratch.targets, &self.y)
    }

    /// The fine iterations between two corrections: the Galerkin mode's,
    /// else `elastic` (the elastic weights' `correction_period`).
    pub(super) fn correction_period(&self, elastic: usize) -> usize {
        self.galerkin_mode.map_or(elastic, |g| g.period)
    }

    /// `rhs = (g(R) − Q Y)_U` (+ `λ1 (C − Y)` on constrained unknowns).
    pub(super) fn global_rhs(&mut self, factor: &Factor, (el, set): (&ElasticOps, &ElasticSet)) {
        let ops = &self.rest.ops;
        let st = &mut self.elastic;
        el.residual(
            set,
            ops,
            &self.y,
            &st.rot,
            &st.proj,
            (&mut st.t, &mut st.rm),
            &mut st.res,
        );
        let sys = &factor.sys;
        let nu = sys.unknowns.len();
        if !st.linear.is_empty() {
            for (r, s) in st.res.iter_mut().zip(&st.linear) {
                for k in 0..3 {
                    r[k] += s[k];
                }
            }
        }
        for (k, &u) in sys.unknowns.iter().enumerate() {
            let r = st.res[u as usize];
            st.rhs[k] = r[0];
            st.rhs[nu + k] = r[1];
            st.rhs[2 * nu + k] = r[2];
        }
        sys.add_soft_rhs(&self.scratch.targets, &self.y, &mut st.rhs);
    }

    /// The global step from the current rotations and area targets,
    /// `rhs = Δ = Q_UU⁻¹ (g(R) − Q Y)_U`; whether it is finite.
    pub(super) fn elastic_global_step(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
    ) -> bool {
        self.global_rhs(factor, (el, set));
        let nu = factor.sys.unknowns.len();
        let st = &mut self.elastic;
        let b = MatMut::from_column_major_slice_mut(&mut st.rhs, nu, 3);
        let mem = st.mem.as_mut().expect("sized before the step");
        factor.solve_in_place(b, MemStack::new(mem));
        st.rhs.iter().all(|v| v.is_finite())
    }

    /// Writes the unknowns of `Y` from the Anderson candidate or from the
    /// plain step `x + Δ`.
    pub(super) fn set_unknowns(&mut self, factor: &Factor, from: Flat) {
        let st = &self.elastic;
        let nu = factor.sys.unknowns.len();
        for (k, &u) in factor.sys.unknowns.iter().enumerate() {
            self.y[u as usize] = match from {
                Flat::Candidate => [st.cand[k], st.cand[nu + k], st.cand[2 * nu + k]],
                Flat::PlainStep => [
                    st.x_flat[k] + st.rhs[k],
                    st.x_flat[nu + k] + st.rhs[nu + k],
                    st.x_flat[2 * nu + k] + st.rhs[2 * nu + k],
                ],
            };
        }
    }
}

/// Where [`Deformer::set_unknowns`] reads the new unknowns.
#[derive(Clone, Copy)]
pub(super) enum Flat {
    Candidate,
    PlainStep,
}
