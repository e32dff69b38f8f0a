//! The two-level start of an elastic sequence from the rest pose
//! (`deform::coarse`): solve the restricted problem on the coarse mesh,
//! take its rotations to the fine mesh, then iterate on the fine mesh as
//! after [`Deformer::propagate_rotations`].

use std::sync::Arc;
use std::time::Instant;

use nalgebra::UnitQuaternion;

use super::Deformer;
use crate::deform::coarse::CoarseLevel;
use crate::deform::constraints::Constraints;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::factor::Factor;
use crate::mesh::Real;

/// Iteration cap of the coarse solve (the prototype's camel limb needed
/// 135; a coarse solve that hits the cap still gives its rotations).
pub const COARSE_MAX_ITERS: usize = 300;

/// How many levels a sequence from the rest pose uses.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Levels {
    /// The fine mesh only: first rotations from the handles' rotations
    /// spread by harmonic weights.
    One,
    /// A coarse solve first where the mesh has a coarse level and the
    /// constraint set survives on it (`deform::coarse`); else as `One`.
    #[default]
    Two,
}

/// The coarse factor of the fine factor `factor_id` (`None`: the set does
/// not survive restriction or the coarse factorisation failed; then there
/// is no coarse start for that set).
pub(super) type CoarseFactor = (u64, Option<Arc<Factor>>);

/// What the coarse start did.
#[derive(Debug, Clone, Copy)]
pub(super) struct CoarseRun {
    /// Coarse iterations.
    pub iterations: usize,
    /// Wall time of the level (on first use), the factor (on a new
    /// constraint set), the coarse solve and the prolongation, ms.
    pub ms: Real,
}

impl Deformer {
    /// The rotations of the elastic iteration's current pose, `#V` (the
    /// identity before the first step).
    pub(crate) fn rotations(&self) -> &[UnitQuaternion<Real>] {
        &self.elastic.rot
    }

    /// Sets the rotations of the vertices with `set.fit` (and the area
    /// targets) from a coarse solve (module docs). Returns `None`, with
    /// nothing changed, when there is no coarse start for this mesh or set.
    pub(super) fn coarse_start(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        constraints: &Constraints,
    ) -> Option<CoarseRun> {
        if self.levels == Levels::One {
            return None;
        }
        let t0 = Instant::now();
        let level: Arc<CoarseLevel> = self.rest.coarse()?.clone();
        let coarse_constraints = level.restrict(constraints)?;
        let params = self.params;
        let coarse_factor = match &self.coarse_factor {
            Some((id, f)) if *id == factor.id() => f.clone(),
            _ => {
                let f = Factor::build(&level.rest, &params, &coarse_constraints)
                    .ok()
                    .map(Arc::new);
                self.coarse_factor = Some((factor.id(), f.clone()));
                f
            }
        }?;
        // the fine tolerance in coarse mean edge lengths
        let mut coarse_params = params;
        coarse_params.tol = params.tol * self.rest.ops.scale / level.rest.ops.scale;
        let mut coarse = Deformer::new(level.rest.clone(), coarse_params);
        let report = coarse
            .step(&coarse_factor, &coarse_constraints, COARSE_MAX_ITERS)
            .ok()?;
        if !report.objective.is_finite() || coarse.rotations().len() != level.num_vertices() {
            return None;
        }
        let st = &mut self.elastic;
        level.prolongate_rotations(&self.rest, coarse.rotations(), &set.fit, &mut st.rot);
        el.rotated_rest_projections(&self.rest.ops.positions, &st.rot, &mut st.proj);
        Some(CoarseRun {
            iterations: report.iterations,
            ms: t0.elapsed().as_secs_f64() * 1e3,
        })
    }
}
