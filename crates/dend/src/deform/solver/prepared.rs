//! A constraint set's levels built ahead of its first solve, on another
//! thread: [`Deformer::level_plan`] says what the deformer's levels are,
//! [`LevelPlan::build`] builds them for a constraint set (they need the
//! rest operators and the constraints, not the fine factor), and
//! [`Deformer::install_levels`] hands them to the deformer once the fine
//! factor is there.
//!
//! A deformer builds each coarse problem on first use: the preview level's
//! in the first drag's frame, the corrections' in the first correction
//! (the level's simplification the first time, its factor, the levels
//! below it and the coarsest level's Newton pattern). A server that builds
//! them beside the fine factor, as [`Deformer::build_factor`] does in one
//! call, takes that out of the first drag and the first settle of every
//! constraint set. The problems are the ones the deformer would build
//! (same level, same weights: a new set's levels start at the fine detail
//! weight, `solver/detail_fit.rs`), so the solves are the same, bit for bit.

use std::sync::Arc;

use super::levels::Levels;
use super::multilevel::{coarse_problem, coarse_problem_ahead};
use super::preview::preview_ratio;
use super::{CoarseProblem, Deformer, Preview};
use crate::deform::constraints::Constraints;
use crate::deform::factor::{Factor, FactorKey};
use crate::deform::params::Params;
use crate::deform::rest::Rest;

/// What a deformer's levels are ([`Deformer::level_plan`]): enough to
/// build them for a constraint set without the deformer.
#[derive(Clone)]
pub struct LevelPlan {
    rest: Arc<Rest>,
    params: Params,
    levels: Levels,
    /// The corrections' level: its coarse ratio and whether it is a Newton
    /// level (`multilevel.rs`).
    first: Option<(usize, bool)>,
    /// The coarse start's level where it is another one.
    start: Option<(usize, bool)>,
    /// The preview level's coarse ratio.
    preview: Option<usize>,
}

/// A constraint set's coarse problems, built ahead ([`LevelPlan::build`]).
pub struct PreparedLevels {
    /// The set's fine factor key: only that factor's deformer takes them.
    key: FactorKey,
    corrections: Option<(usize, Box<CoarseProblem>)>,
    start: Option<(usize, Box<CoarseProblem>)>,
    preview: Option<(usize, Box<CoarseProblem>)>,
}

impl PreparedLevels {
    /// Whether anything was built (a mesh or formulation without levels,
    /// or a set that does not survive on them, has none).
    pub fn is_empty(&self) -> bool {
        self.corrections.is_none() && self.start.is_none() && self.preview.is_none()
    }
}

impl LevelPlan {
    /// Builds the coarse problems `constraints` (the mesh's own indices)
    /// will need: the corrections' (with every level below it), the coarse
    /// start's where it is its own, and the preview level's.
    pub fn build(&self, constraints: &Constraints) -> PreparedLevels {
        let key = FactorKey::new(&self.rest, &self.params, constraints);
        let internal = self.rest.internal_constraints(constraints);
        let ahead = |f: (usize, bool)| {
            let p =
                coarse_problem_ahead(&self.rest, &self.params, f, &internal, self.levels, false);
            Some((f.0, p?))
        };
        let (corrections, start) = (self.first.and_then(ahead), self.start.and_then(ahead));
        let preview = self.preview.and_then(|ratio| {
            let p = coarse_problem(
                &self.rest,
                &self.params,
                (ratio, false),
                &internal,
                super::preview::PREVIEW_LEVELS,
            )?;
            Some((ratio, Box::new(p)))
        });
        PreparedLevels {
            key,
            corrections,
            start,
            preview,
        }
    }
}

impl Deformer {
    /// What this deformer's levels are, to build them for a constraint set
    /// elsewhere ([`LevelPlan::build`], then [`Deformer::install_levels`]).
    pub fn level_plan(&self) -> LevelPlan {
        let used = self.levels_used();
        let separate = self.separate_start();
        LevelPlan {
            rest: self.rest.clone(),
            params: self.params,
            levels: self.levels,
            first: self.first_level().filter(|_| used),
            start: self.start_level().filter(|_| used && separate),
            preview: preview_ratio(self.rest.mesh.num_vertices(), &self.params),
        }
    }

    /// Takes the coarse problems built ahead for `factor`'s constraint set
    /// ([`LevelPlan::build`] of this deformer's [`Deformer::level_plan`]):
    /// each one whose slot does not hold that set's problem yet. Returns
    /// false, taking nothing, for another constrained set's factor.
    ///
    /// The detail weight's fit (`solver/detail_fit.rs`) is left as it is:
    /// the set's first correction switches it to the set, as without
    /// prepared levels. Where the levels now take a weight other than the
    /// fine one (the last set's corrections found them too stiff), that
    /// first correction builds the set's problems anew at the fine weight,
    /// also as without them: the prepared corrections' and coarse start's
    /// are not taken then (the preview, always at the fine weight, is).
    pub fn install_levels(&mut self, prepared: PreparedLevels, factor: &Factor) -> bool {
        if prepared.key != *factor.key() {
            return false;
        }
        let id = factor.id();
        let fine_weight = self.detail_fit.scale() == 1.0;
        for (slot, p) in [
            (&mut self.coarse, prepared.corrections),
            (&mut self.start_coarse, prepared.start),
        ] {
            if let Some((ratio, p)) = p.filter(|_| fine_weight) {
                if slot.as_ref().is_none_or(|(k, _)| *k != (id, ratio)) {
                    *slot = Some(((id, ratio), Some(p)));
                }
            }
        }
        if let Some((ratio, p)) = prepared.preview {
            // (a pending preview's pose and rotations are the next step's
            // start: it keeps its problem)
            let free = self
                .preview
                .as_ref()
                .is_none_or(|pv| pv.key != (id, ratio) && !pv.pending);
            if free {
                let n = self.rest.mesh.num_vertices();
                self.preview = Some(Box::new(Preview::new((id, ratio), Some(p), n)));
            }
        }
        true
    }
}
