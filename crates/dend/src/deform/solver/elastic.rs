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
//! [`Formulation::Elastic`]: crate::deform::Formulation::Elastic

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::MatMut;
use nalgebra::UnitQuaternion;

use super::{Deformer, StepReport};
use crate::deform::anderson::Anderson;
use crate::deform::constraints::Constraints;
use crate::deform::elastic::{laplacian, ElasticOps, ElasticSet};
use crate::deform::factor::Factor;
use crate::deform::params::DetailTerm;
use crate::deform::DeformError;
use crate::mesh::{Point, Real};

/// The elastic iteration's memory, sized once per constraint set.
#[derive(Default)]
pub(super) struct State {
    /// `R(Y)` of the current pose (and the candidate's, while tried).
    rot: Vec<UnitQuaternion<Real>>,
    rot_try: Vec<UnitQuaternion<Real>>,
    /// The area projections `P_t` (and the candidate's).
    proj: Vec<[Real; 6]>,
    proj_try: Vec<[Real; 6]>,
    /// `L Y`.
    ly: Vec<Point>,
    /// `R_i δ_i` scratch and the residual `g(R) − Q Y`, `#V`.
    t: Vec<Point>,
    res: Vec<Point>,
    /// Right-hand side / update, column-major `|U| × 3`.
    rhs: Vec<Real>,
    /// Flat `3|U|` current iterate and Anderson candidate.
    x_flat: Vec<Real>,
    cand: Vec<Real>,
    anderson: Anderson,
    mem: Option<MemBuffer>,
    sized_for: (u64, usize),
    /// The energy of the current pose and the factor it was computed with,
    /// when the next call may continue the sequence.
    chain: Option<(u64, Real)>,
}

impl State {
    /// Forgets the continued sequence (the pose or parameters changed).
    pub(super) fn invalidate(&mut self) {
        self.chain = None;
    }

    /// Back to the rest state's rotations (reset): identity, and the
    /// projections rebuilt on the next step.
    pub(super) fn reset(&mut self) {
        self.chain = None;
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
        let n = self.y.len();
        let nu = factor.sys.unknowns.len();
        let window = self.params.anderson;
        let st = &mut self.elastic;
        if st.rot.len() != n {
            st.rot = vec![UnitQuaternion::identity(); n];
            st.rot_try = vec![UnitQuaternion::identity(); n];
            st.ly = vec![[0.0; 3]; n];
            st.t = vec![[0.0; 3]; n];
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
            st.anderson = Anderson::new(window, 3 * nu);
            st.mem = Some(MemBuffer::new(factor.solve_scratch(3)));
            st.sized_for = (factor.id(), window);
            st.chain = None;
        }
        let fit = self.params.detail == DetailTerm::Nonlinear;
        let chain = st
            .chain
            .take()
            .filter(|&(id, _)| id == factor.id() && !moved);
        let mut e = match chain {
            Some((_, e)) => e,
            None => {
                // a new sequence starts from the rotations of the last pose
                // (the identity at rest): the first global step then moves
                // every vertex with its constraints (a translation of all
                // of them is exact after one iteration)
                st.anderson.reset();
                self.local_step(factor, (el, set), false, false)
            }
        };
        let mut report = StepReport {
            iterations: 0,
            last_update: 0.0,
            converged: false,
            diverged: false,
            objective: e,
            initial_objective: e,
        };
        if nu == 0 {
            report.converged = true;
            self.sync_pose();
            return Ok(report);
        }
        let accelerate = fit && window > 0;
        for _ in 0..max_iters {
            // 1. global step: Δ = Q_UU⁻¹ (g(R) − Q Y)_U
            self.global_rhs(factor, (el, set));
            let st = &mut self.elastic;
            {
                let b = MatMut::from_column_major_slice_mut(&mut st.rhs, nu, 3);
                let mem = st.mem.as_mut().expect("sized above");
                factor.solve_in_place(b, MemStack::new(mem));
            }
            if st.rhs.iter().any(|v| !v.is_finite()) {
                report.diverged = true;
                break;
            }
            let max_dx = (0..nu)
                .map(|k| {
                    let r = &st.rhs;
                    (r[k] * r[k] + r[nu + k] * r[nu + k] + r[2 * nu + k] * r[2 * nu + k]).sqrt()
                })
                .fold(0.0, Real::max);
            for (k, &u) in factor.sys.unknowns.iter().enumerate() {
                let p = self.y[u as usize];
                st.x_flat[k] = p[0];
                st.x_flat[nu + k] = p[1];
                st.x_flat[2 * nu + k] = p[2];
            }
            // 2.–4. accelerated candidate, kept only if the energy falls
            let mut accepted = false;
            if accelerate && st.anderson.step(&st.x_flat, &st.rhs, &mut st.cand) {
                self.set_unknowns(factor, Flat::Candidate);
                let e_aa = self.local_step(factor, (el, set), fit, true);
                if e_aa.is_finite() && e_aa < e {
                    let st = &mut self.elastic;
                    std::mem::swap(&mut st.rot, &mut st.rot_try);
                    std::mem::swap(&mut st.proj, &mut st.proj_try);
                    e = e_aa;
                    accepted = true;
                }
            }
            if !accepted {
                self.set_unknowns(factor, Flat::PlainStep);
                e = self.local_step(factor, (el, set), fit, false);
            }
            report.iterations += 1;
            report.last_update = max_dx;
            if !fit || max_dx < self.params.tol {
                report.converged = true;
                break;
            }
        }
        report.objective = e;
        self.elastic.chain = Some((factor.id(), e));
        self.sync_pose();
        Ok(report)
    }

    /// The local step on the current pose (`L Y`, then the rotations; into
    /// `rot_try` when `trial`, warm-started from `rot`), returning
    /// `E(Y, R)` plus the soft-constraint term. Without `fit` (the linear
    /// detail term) the rotations stay the identity.
    fn local_step(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        fit: bool,
        trial: bool,
    ) -> Real {
        let ops = &self.rest.ops;
        let st = &mut self.elastic;
        laplacian(ops, &self.y, &mut st.ly);
        let (rot, proj) = if trial {
            st.rot_try.copy_from_slice(&st.rot);
            st.proj_try.copy_from_slice(&st.proj);
            (&mut st.rot_try, &mut st.proj_try)
        } else {
            (&mut st.rot, &mut st.proj)
        };
        let mut e = el.local_step(set, ops, &self.y, &st.ly, rot, proj, fit);
        let lambda1 = factor.sys.lambda1;
        if lambda1 > 0.0 {
            for &(v, p) in &self.scratch.targets {
                let y = self.y[v as usize];
                let d2: Real = (0..3).map(|k| (y[k] - p[k]).powi(2)).sum();
                e += lambda1 * d2;
            }
        }
        e
    }

    /// `rhs = (g(R) − Q Y)_U` (+ `λ1 (C − Y)` on constrained unknowns).
    fn global_rhs(&mut self, factor: &Factor, (el, set): (&ElasticOps, &ElasticSet)) {
        let ops = &self.rest.ops;
        let st = &mut self.elastic;
        el.residual(set, ops, &self.y, &st.rot, &st.proj, &mut st.t, &mut st.res);
        let sys = &factor.sys;
        let nu = sys.unknowns.len();
        for (k, &u) in sys.unknowns.iter().enumerate() {
            let r = st.res[u as usize];
            st.rhs[k] = r[0];
            st.rhs[nu + k] = r[1];
            st.rhs[2 * nu + k] = r[2];
        }
        if sys.lambda1 > 0.0 {
            for &(v, p) in &self.scratch.targets {
                let k = sys.col_of[v as usize];
                if k == u32::MAX {
                    continue;
                }
                let y = self.y[v as usize];
                for d in 0..3 {
                    st.rhs[d * nu + k as usize] += sys.lambda1 * (p[d] - y[d]);
                }
            }
        }
    }

    /// Writes the unknowns of `Y` from the Anderson candidate or from the
    /// plain step `x + Δ`.
    fn set_unknowns(&mut self, factor: &Factor, from: Flat) {
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
enum Flat {
    Candidate,
    PlainStep,
}
