//! The coarse level of the elastic solver's two-level start (design.md §7):
//! a coarse mesh whose vertices are a subset of the fine ones, the
//! restriction of a constraint set to it and the prolongation of its
//! rotations back to the fine mesh.
//!
//! The slow mode of the elastic iteration on a character mesh is a far
//! free part swinging as a whole (a leg about its hip): the local/global
//! iteration moves it by a little each step, at every resolution. A
//! *cascadic* start (Bornemann & Deuflhard 1996) solves the same problem
//! on a mesh with about `#V / r` vertices first (`r` the coarse ratio: 3
//! by default, 8 for the `elastica` preset) — each of its iterations
//! costs about `1/r` of a fine one — and starts the fine iteration from its
//! rotations. The energy's weights are dimensionless (elastic/mod.rs), so
//! the coarse [`Rest`] normalises itself and the same [`Params`] apply; the
//! coarse tolerance is the fine one in fine mean edge lengths (a looser
//! coarse solve gives a worse start: prototype FINDINGS2, 22:58).
//!
//! Only the rest mesh decides the level ([`CoarseLevel::new`], cached by
//! [`Rest::coarse`]); the constraint set decides whether it is usable
//! ([`CoarseLevel::restrict`]). The coarse mesh has `#V / r` vertices, but
//! never fewer than [`MIN_COARSE_VERTICES`] (a hand of 1502 vertices
//! simplified to 189 started its fine iteration worse in the prototype;
//! at 500 vertices, ratio 3, the hand's limb edit takes 18 iterations
//! instead of 48); a mesh under [`MIN_VERTICES`] (ratio below 2) has no
//! coarse level.
//!
//! [`Params`]: crate::deform::Params

mod nearest;
mod simplify;
mod transfer;

use std::sync::Arc;

use nalgebra::UnitQuaternion;

pub use super::rest::CoarseLevel;
pub use simplify::coarse_mesh;
pub use transfer::{PROLONGATION_PASSES, RESTRICTION_PASSES};

use super::constraints::{Constraints, HandleGroup};
use super::rest::{cached, Rest};
use crate::mesh::{Point, Real};

/// Fine vertex count from which a mesh gets a coarse level
/// (`2 ×` [`MIN_COARSE_VERTICES`]).
pub const MIN_VERTICES: usize = 2 * MIN_COARSE_VERTICES;

/// Fewest vertices of a coarse mesh.
pub const MIN_COARSE_VERTICES: usize = 500;

/// Fine vertices per coarse vertex, at most, of the level built with the rest (the elastica preset's ratio)
/// (meshes of `ratio × 500` vertices or more; smaller meshes use
/// `#V / 500`).
pub const RATIO: usize = crate::deform::params::ELASTICA_COARSE_RATIO;

/// The simplification ratio of a mesh with `n >= MIN_VERTICES` vertices:
/// `clamp(n / MIN_COARSE_VERTICES, 2, max_ratio)`, `max_ratio` being
/// [`RATIO`] by default ([`ElasticParams::coarse_ratio`]).
///
/// [`ElasticParams::coarse_ratio`]: crate::deform::ElasticParams::coarse_ratio
pub fn ratio_at_most(n: usize, max_ratio: usize) -> usize {
    (n / MIN_COARSE_VERTICES).clamp(2, max_ratio.max(2))
}

/// Smallest number of coarse vertices a constraint group (each handle,
/// the fixed set) must keep for the coarse problem to stand for the fine
/// one.
pub const MIN_GROUP: usize = 3;

/// Passes of 1-ring averaging of the prolongated rotations (the nearest
/// coarse vertex's rotation alone is piecewise constant, a high-frequency
/// error the fine iteration then spends iterations on).
pub const SMOOTHING_PASSES: usize = 3;

/// The coarse levels a [`Rest`] keeps (its cache is in `rest.rs`, the
/// levels are built here).
impl Rest {
    /// The coarse level of this mesh (`deform::coarse`), built on first
    /// call (about the cost of one `Rest::new` of the fine mesh and a
    /// simplification) and kept; `None` for meshes under
    /// `coarse::MIN_VERTICES` vertices or whose simplification failed.
    pub(crate) fn coarse(&self) -> Option<Arc<CoarseLevel>> {
        self.coarse_at_most(RATIO)
    }

    /// [`Rest::coarse`] simplified at most `max_ratio` times
    /// ([`ElasticParams::coarse_ratio`]); levels are kept by their actual ratio,
    /// so small meshes share one.
    ///
    /// [`ElasticParams::coarse_ratio`]: crate::deform::ElasticParams::coarse_ratio
    pub(crate) fn coarse_at_most(&self, max_ratio: usize) -> Option<Arc<CoarseLevel>> {
        let ratio = ratio_at_most(self.mesh.num_vertices(), max_ratio);
        cached(&self.coarse, ratio, || {
            CoarseLevel::new(self, ratio).map(Arc::new)
        })
    }

    /// Builds the coarse level now if the mesh has one (it is otherwise
    /// built by the first elastic step that needs it), returning whether
    /// it has one. A server calls this in the background when a mesh is
    /// opened, so that the first settle of a session does not pay for it.
    pub fn prepare_coarse_level(&self) -> bool {
        self.coarse().is_some()
    }

    /// [`Rest::prepare_coarse_level`] for `params`' coarse ratio
    /// ([`ElasticParams::coarse_ratio`]; a server calls it when a session
    /// opens), and the levels of the hierarchy below it (each level's own
    /// coarse level, as [`Levels::Many`](crate::deform::Levels::Many)
    /// solves on them); `false` for the paper formulations, which have no
    /// coarse level.
    pub fn prepare_coarse_level_for(&self, params: &crate::deform::params::Params) -> bool {
        let Some(ratio) = params.elastic().map(|e| e.coarse_ratio) else {
            return false;
        };
        let Some(mut level) = self.coarse_at_most(ratio) else {
            return false;
        };
        while let Some(below) = level.rest.coarse_at_most(ratio) {
            level = below;
        }
        true
    }
}

impl CoarseLevel {
    /// The coarse level of `rest` simplified `ratio` times (see
    /// [`ratio_at_most`]), or `None` when the mesh is small
    /// (< [`MIN_VERTICES`]) or its simplification is not a valid mesh.
    pub fn new(rest: &Rest, ratio: usize) -> Option<CoarseLevel> {
        // simplified in the mesh's own order: meshoptimizer's collapses
        // depend on the vertex order, and the solve on the coarse mesh
        // they give (renumbered for locality, igea_134k's one-shot edit
        // took 82 fine iterations instead of 29), so a renumbering of
        // the fine mesh (`mesh::order`) changes only the maps below
        let mesh = rest.mesh();
        let n = mesh.num_vertices();
        if n < MIN_VERTICES {
            return None;
        }
        let mut normalised = Vec::new();
        let normalised = match rest.vertex_order() {
            Some(order) => {
                order.to_user(&rest.ops.positions, &mut normalised);
                &normalised
            }
            None => &rest.ops.positions,
        };
        let (coarse, mut fine_of) = coarse_mesh(mesh, normalised, ratio)?;
        let rest_c = Rest::coarse_level(coarse).ok()?;
        let mut near = nearest::nearest_sources(mesh.topology(), normalised, &fine_of);
        if let Some(order) = rest.vertex_order() {
            for v in &mut fine_of {
                *v = order.internal(*v);
            }
            near = (0..n as u32)
                .map(|i| near[order.user(i) as usize])
                .collect();
        }
        let mut coarse_of = vec![u32::MAX; n];
        for (c, &v) in fine_of.iter().enumerate() {
            coarse_of[v as usize] = c as u32;
        }
        Some(CoarseLevel {
            rest: std::sync::Arc::new(rest_c),
            fine_of,
            coarse_of,
            near,
        })
    }

    /// Coarse vertex count.
    pub fn num_vertices(&self) -> usize {
        self.fine_of.len()
    }

    /// The coarse vertex count over the fine one: what a coarse iteration
    /// costs in fine iterations (the work measure of
    /// [`StepReport::coarse_work`]).
    ///
    /// [`StepReport::coarse_work`]: crate::deform::StepReport::coarse_work
    pub fn share(&self) -> Real {
        self.fine_of.len() as Real / self.coarse_of.len().max(1) as Real
    }

    /// `constraints` restricted to the coarse vertices: the same groups
    /// with their coarse members, positions (`fixed_at`, handle bases) and
    /// targets carried over. `None` when a group keeps fewer than
    /// [`MIN_GROUP`] coarse vertices (then there is no coarse problem).
    pub fn restrict(&self, constraints: &Constraints) -> Option<Constraints> {
        let (fixed, fixed_at) = self.keep_coarse(&constraints.fixed, &constraints.fixed_at);
        if !constraints.fixed.is_empty() && fixed.len() < MIN_GROUP {
            return None;
        }
        let mut handles = Vec::with_capacity(constraints.handles.len());
        for h in &constraints.handles {
            let (vertices, base) = self.keep_coarse(&h.vertices, &h.base);
            if vertices.len() < MIN_GROUP {
                return None;
            }
            handles.push(HandleGroup {
                name: h.name.clone(),
                vertices,
                base,
                rest_centroid: h.rest_centroid,
                target: h.target,
            });
        }
        Some(Constraints {
            fixed,
            fixed_at,
            handles,
        })
    }

    /// The fine `vertices` that are coarse vertices, as coarse indices
    /// (sorted: a renumbered fine mesh's coarse vertices keep the mesh's
    /// own order, `fine_of` is then not increasing), with their
    /// `positions`.
    fn keep_coarse(&self, vertices: &[u32], positions: &[Point]) -> (Vec<u32>, Vec<Point>) {
        let mut kept: Vec<(u32, Point)> = vertices
            .iter()
            .zip(positions)
            .filter_map(|(&v, &p)| {
                let c = self.coarse_of[v as usize];
                (c != u32::MAX).then_some((c, p))
            })
            .collect();
        kept.sort_unstable_by_key(|&(c, _)| c);
        kept.into_iter().unzip()
    }

    /// The fine rotations of the vertices where `fit` is set, from the
    /// coarse rotations `coarse`: each takes its nearest coarse vertex's
    /// (`R_i = R^c_{near(i)}`), then [`SMOOTHING_PASSES`] passes of
    /// 1-ring averaging over the fine mesh (`q_i ← normalise(q_i + Σ_j
    /// ±q_j)`, each `q_j` sign-aligned to `q_i`; a chordal mean of nearby
    /// rotations) smooth the piecewise-constant field. Vertices without
    /// `fit` keep their rotation and take part in the averages.
    pub fn prolongate_rotations(
        &self,
        fine: &Rest,
        coarse: &[UnitQuaternion<Real>],
        fit: &[bool],
        rot: &mut [UnitQuaternion<Real>],
    ) {
        for (i, q) in rot.iter_mut().enumerate() {
            let c = self.near[i];
            if fit[i] && c != u32::MAX {
                *q = coarse[c as usize];
            }
        }
        let topo = fine.mesh.topology();
        let mut next = rot.to_vec();
        for _ in 0..SMOOTHING_PASSES {
            for (i, out) in next.iter_mut().enumerate() {
                if !fit[i] || self.near[i] == u32::MAX {
                    *out = rot[i];
                    continue;
                }
                let qi = rot[i].into_inner().coords;
                let mut acc = qi;
                for &j in topo.ring(i) {
                    let qj = rot[j as usize].into_inner().coords;
                    acc += if qj.dot(&qi) < 0.0 { -qj } else { qj };
                }
                *out = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(acc));
            }
            rot.copy_from_slice(&next);
        }
    }
}

#[cfg(test)]
mod tests;
