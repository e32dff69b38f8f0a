//! The fine half of a coarse correction (`solver/multilevel.rs` holds the
//! coarse half): the correction's outcome folded into the sequence's
//! report and schedule, the fine residual and linear term the coarse
//! problem is built from, and the rotation field applied to the fine pose
//! with an energy test.

use nalgebra::Vector3;

use super::local_global::Flat;
use super::multilevel::Correction;
use super::{Deformer, StepReport};
use crate::deform::constraints::Constraints;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::factor::Factor;
use crate::deform::params::Corrections;
use crate::mesh::{Point, Real};

impl Deformer {
    /// A coarse correction (`solver/multilevel.rs`) of the pose with energy
    /// `e`; returns the energy after it. Corrections stop for the sequence
    /// once one gains less than the fine iterations since the last one
    /// (`ElasticParams::corrections`: or once one gains nothing).
    pub(super) fn correct(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        constraints: &Constraints,
        mut e: Real,
        report: &mut StepReport,
    ) -> Real {
        let gain_before = self.elastic.e_mark - e;
        let on_newton_level =
            self.galerkin_mode.is_none() && !self.elastic.on_hierarchy && self.separate_start();
        let outcome = if let Some(g) = self.galerkin_mode {
            self.galerkin_correction(factor, (el, set), e, g)
        } else {
            self.coarse_correction(factor, (el, set), constraints, e)
        };
        let dropped = matches!(outcome, Correction::Dropped(_));
        let (gain, run) = match outcome {
            Correction::Kept(e_new, run) => {
                let gain = e - e_new;
                e = e_new;
                // the Anderson history is kept: its pairs are secants of the
                // same fixed-point map, and restarting it after a correction
                // cost iterations (camel limb 45 against 40, dino limb 26
                // against 22, armadillo limb 19 against 17)
                (gain, run)
            }
            Correction::Dropped(run) => (0.0, run),
            Correction::Unavailable(run) => (Real::NEG_INFINITY, run),
            Correction::Interrupted(run) => {
                // nothing changed: the correction is tried again after the
                // next iteration
                report.coarse_iterations += run.iterations;
                report.coarse_ms += run.ms;
                report.coarse_work += run.work;
                report.interrupted = true;
                return e;
            }
        };
        report.coarse_iterations += run.iterations;
        report.coarse_ms += run.ms;
        report.coarse_work += run.work;
        tracing::debug!(
            vertices = self.rest.mesh.num_vertices(),
            after = report.iterations,
            gain,
            gain_before,
            coarse_iterations = run.iterations,
            work = run.work,
            "coarse correction"
        );
        let st = &mut self.elastic;
        st.since_correction = 0;
        st.corrections = match self.params.elastic().map(|e| e.corrections) {
            Some(Corrections::WhileFaster) => gain >= gain_before,
            Some(Corrections::WhileGaining) => gain > 0.0,
            None => false,
        };
        if on_newton_level && dropped {
            // a Newton level's correction that gains nothing (its Newton
            // step far from where the level's model holds) hands the
            // sequence's corrections to the hierarchy, which go on: after a
            // closed-loop gesture on camel_9770 the settle otherwise ended
            // its corrections there and crawled to the 100-iteration cap
            st.on_hierarchy = true;
            st.corrections = true;
        }
        st.e_mark = e;
        e
    }

    /// `r = g(R, P) − Q Y` (plus the linear term) at the current pose,
    /// rotations and area targets, `#V`.
    pub(super) fn residual_now(&mut self, el: &ElasticOps, set: &ElasticSet) -> &[Point] {
        let st = &mut self.elastic;
        el.residual(
            set,
            &self.rest.ops,
            &self.y,
            &st.rot,
            &st.proj,
            (&mut st.t, &mut st.rm),
            &mut st.res,
        );
        if !st.linear.is_empty() {
            for (r, s) in st.res.iter_mut().zip(&st.linear) {
                for k in 0..3 {
                    r[k] += s[k];
                }
            }
        }
        &st.res
    }

    /// Adds the linear term `−2⟨s, Y⟩` to the objective (empty `s`: none);
    /// the next step continues from the current pose and rotations.
    pub(super) fn set_linear_term(&mut self, s: Vec<Point>) {
        let st = &mut self.elastic;
        st.linear = s;
        st.chain = None;
    }

    /// The fine half of a coarse correction: turns the rotations by the
    /// rotation vectors `w` (`R_i ← exp(w_i) R_i`, area targets with their
    /// first vertex), takes one global step `D` from them and keeps
    /// `Y + αD` for the first `α ∈ {1, ½, ¼}` whose energy (rotations
    /// refitted) is below `e`. Returns that energy, or `None` with the pose
    /// and rotations unchanged.
    pub(super) fn apply_rotation_correction(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        w: &[Vector3<Real>],
        e: Real,
    ) -> Option<Real> {
        let nu = factor.sys.unknowns.len();
        let st = &mut self.elastic;
        st.rot_try.copy_from_slice(&st.rot);
        st.proj_try.copy_from_slice(&st.proj);
        self.turn_rotations((el, set), w);
        let finite = self.elastic_global_step(factor, (el, set));
        let st = &mut self.elastic;
        st.swap_trial();
        if !finite {
            return None;
        }
        for (k, &u) in factor.sys.unknowns.iter().enumerate() {
            let p = self.y[u as usize];
            st.x_flat[k] = p[0];
            st.x_flat[nu + k] = p[1];
            st.x_flat[2 * nu + k] = p[2];
        }
        self.line_search_rhs(factor, (el, set), e)
    }

    /// Keeps `x + αD` (the current unknowns in `x_flat`, the step `D` in
    /// `rhs`) for the first `α ∈ {1, ½, ¼}` whose energy (rotations
    /// refitted) is below `e` and returns that energy; `None`, with the
    /// pose unchanged.
    pub(super) fn line_search_rhs(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        e: Real,
    ) -> Option<Real> {
        for alpha in [1.0, 0.5, 0.25] {
            let st = &mut self.elastic;
            for (c, (x, d)) in st.cand.iter_mut().zip(st.x_flat.iter().zip(&st.rhs)) {
                *c = x + alpha * d;
            }
            self.set_unknowns(factor, Flat::Candidate);
            let e_try = self.local_step(factor, (el, set), true, true);
            if e_try.is_finite() && e_try < e {
                self.elastic.swap_trial();
                return Some(e_try);
            }
        }
        let st = &mut self.elastic;
        st.cand.copy_from_slice(&st.x_flat);
        self.set_unknowns(factor, Flat::Candidate);
        None
    }
}
