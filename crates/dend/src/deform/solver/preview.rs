//! Coarse previews of a drag ([`Deformer::preview`]): while a
//! person drags faster than the full mesh can follow, a frame can show the
//! solve of a coarse level of about [`PREVIEW_VERTICES`] vertices instead,
//! prolongated to every vertex with its detail; the full mesh refines from
//! that pose when the drag pauses (the next [`Deformer::step`] starts from
//! it).
//!
//! The coarse problem is the restricted one of the coarse corrections
//! (`solver/multilevel.rs`): the same energy and constraints on the coarse
//! mesh, warm-started across the drags of a gesture. Its pose reaches the
//! fine vertices as a linear blend of the coarse vertices' rigid motions
//! (Magnenat-Thalmann et al. 1988's skinning, with the coarse vertices as
//! bones and the smoothed-aggregation prolongation `P = Sᵏ P₀` of
//! `coarse/transfer.rs` as weights):
//!
//! ```text
//! y_i = Σ_c P_ic (y_c + R_c (x_i − x_c)) = M_i x_i + t_i,
//! M_i = Σ_c P_ic R_c,   t_i = Σ_c P_ic (y_c − R_c x_c)
//! ```
//!
//! (`x` the rest positions, `y_c`, `R_c` the coarse pose and rotations).
//! Rows of `P` sum to one, so a rigid motion of the whole mesh is
//! reproduced exactly, and the fine rest detail `x_i − x_c` turns with the
//! surface around it. Hard-constrained vertices are put on their targets.

use std::time::Instant;

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::levels::Levels;
use super::multilevel::{coarse_params, coarse_problem};
use super::{CoarseProblem, Deformer, Motion, Preview};
use crate::deform::constraints::Constraints;
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::error::DeformError;
use crate::deform::factor::Factor;
use crate::deform::params::{DetailTerm, Params};
use crate::mesh::{Point, Real};

/// The vertex count a preview level aims at: its iteration costs about
/// what a 4,000-vertex mesh's does, whatever the mesh's size.
pub const PREVIEW_VERTICES: usize = 4000;

/// Meshes with fewer vertices have no preview (their own iteration is
/// already about as cheap as a preview's).
pub const PREVIEW_MIN_VERTICES: usize = 3 * PREVIEW_VERTICES;

/// Coarse iterations per preview frame.
pub const PREVIEW_ITERATIONS: usize = 3;

/// Passes of 1-ring averaging of the blended rigid motions (`k` in
/// `P = Sᵏ P₀`).
pub const PREVIEW_PASSES: usize = 3;

/// The levels below the preview level and their detail weight: a single
/// level's iteration (as with two levels), since a drag's preview answers
/// in a few of its iterations, which a correction or a Newton step would
/// make several times longer (feline drag→frame p50 34 → 65 ms with the
/// hierarchy's); and the fine detail weight, since a preview shows its
/// level's own solve.
pub(super) const PREVIEW_LEVELS: (Levels, Real) = (Levels::Two, 1.0);

impl Preview {
    /// A preview of the fine factor and level `key` with the coarse
    /// problem `problem`, for a mesh of `n` vertices, following no gesture
    /// yet.
    pub(super) fn new(key: (u64, usize), problem: Option<Box<CoarseProblem>>, n: usize) -> Self {
        Preview {
            key,
            problem,
            following: false,
            pending: false,
            pose: Vec::new(),
            pose_user: Vec::new(),
            blend: vec![(Matrix3::identity(), Vector3::zeros()); n],
            next: vec![(Matrix3::identity(), Vector3::zeros()); n],
        }
    }
}

/// What one [`Deformer::preview`] did.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PreviewReport {
    /// Coarse iterations run.
    pub iterations: usize,
    /// Whether the coarse problem converged for these targets (more
    /// previews would not change the picture).
    pub converged: bool,
    /// Vertices of the preview level.
    pub coarse_vertices: usize,
    /// Wall time, ms (the level and its factor when first needed, the
    /// coarse iterations and the prolongation).
    pub ms: Real,
    /// That work in fine iterations (`StepReport::coarse_work`).
    pub work: Real,
}

/// The ratio of the preview level of a mesh of `n` vertices solved with
/// `params` (at least the corrections' ratio), `None` without previews
/// (the paper formulations, the linear detail term, a mesh under
/// [`PREVIEW_MIN_VERTICES`]).
pub(super) fn preview_ratio(n: usize, params: &Params) -> Option<usize> {
    let e = params.elastic()?;
    (params.detail == DetailTerm::Nonlinear && n >= PREVIEW_MIN_VERTICES)
        .then(|| e.coarse_ratio.max(n / PREVIEW_VERTICES))
}

impl crate::deform::rest::Rest {
    /// Builds the preview level of sessions with `params` now (a server
    /// calls it in the background when a session opens, so that the first
    /// preview does not pay for the simplification); `false` when they
    /// have none (a mesh under [`PREVIEW_MIN_VERTICES`], the paper
    /// formulations).
    pub fn prepare_preview_level(&self, params: &Params) -> bool {
        preview_ratio(self.mesh.num_vertices(), params)
            .is_some_and(|ratio| self.coarse_at_most(ratio).is_some())
    }
}

impl Deformer {
    /// Whether this deformer can preview (the elastic formulation with the
    /// nonlinear detail term, on a mesh of at least
    /// [`PREVIEW_MIN_VERTICES`] vertices); a constraint set that does not
    /// survive on the preview level still has none ([`Deformer::preview`]
    /// returns `None`).
    pub fn can_preview(&self) -> bool {
        preview_ratio(self.rest.mesh.num_vertices(), &self.params).is_some()
    }

    /// Runs up to `max_iters` iterations of the coarse preview problem
    /// towards `constraints`' targets and prolongates its pose to every
    /// vertex (module docs): [`Deformer::shown_pose`] returns it, and the
    /// next [`Deformer::step`] starts from it. The fine pose is not
    /// changed. `None` when there is no preview ([`Deformer::can_preview`],
    /// or the set does not survive on the preview level).
    ///
    /// `factor` must be the fine factor of `constraints`' set (it keys the
    /// preview's coarse problem).
    pub fn preview(
        &mut self,
        factor: &Factor,
        constraints: &Constraints,
        max_iters: usize,
    ) -> Result<Option<PreviewReport>, DeformError> {
        let rest = self.rest.clone();
        let constraints = &*rest.internal_constraints(constraints);
        self.check_factor(factor, constraints)?;
        let n = self.rest.mesh.num_vertices();
        let Some(ratio) = preview_ratio(n, &self.params) else {
            return Ok(None);
        };
        let t0 = Instant::now();
        let key = (factor.id(), ratio);
        let mut pv = match self.preview.take() {
            Some(p) if p.key == key => p,
            _ => {
                let problem = coarse_problem(
                    &self.rest,
                    &self.params,
                    (key.1, false),
                    constraints,
                    PREVIEW_LEVELS,
                );
                Box::new(Preview::new(key, problem.map(Box::new), n))
            }
        };
        let out = self.preview_with(&mut pv, constraints, max_iters);
        self.preview = Some(pv);
        Ok(out.map(
            |(iterations, converged, coarse_vertices, work)| PreviewReport {
                iterations,
                converged,
                coarse_vertices,
                ms: t0.elapsed().as_secs_f64() * 1e3,
                work,
            },
        ))
    }

    /// [`Deformer::preview`] with its state `pv`: (coarse iterations,
    /// converged, coarse vertices, work in fine iterations), or `None`
    /// without a coarse problem.
    fn preview_with(
        &self,
        pv: &mut Preview,
        constraints: &Constraints,
        max_iters: usize,
    ) -> Option<(usize, bool, usize, Real)> {
        let p = pv.problem.as_deref_mut()?;
        let cc = p.level.restrict(constraints)?;
        if !pv.following {
            // the gesture's first preview starts from the fine state: the
            // rest pose's start (handle rotations spread by harmonic
            // weights) or the fine pose with its rotations, so that the
            // handles' change of rotation turns the coarse rotations
            p.deformer.params = coarse_params(&self.rest, &self.params, &p.level);
            if self.elastic.starts_from_rest() {
                p.deformer.reset();
            } else {
                let injected: Vec<Point> = p
                    .level
                    .fine_of
                    .iter()
                    .map(|&v| self.pose[v as usize])
                    .collect();
                p.deformer.set_pose(injected).ok()?;
                if self.elastic.rot.len() == self.pose.len() {
                    let rot = p
                        .level
                        .fine_of
                        .iter()
                        .map(|&v| self.elastic.rot[v as usize])
                        .collect();
                    p.deformer
                        .elastic
                        .warm_from(rot, self.elastic.handle_rot.clone());
                }
            }
            pv.following = true;
        }
        let report = p.deformer.step(&p.factor, &cc, max_iters).ok()?;
        if !report.objective.is_finite() {
            pv.following = false;
            return None;
        }
        prolongate_rigid(
            &self.rest.mesh,
            &p.level.fine_of,
            &p.level.near,
            p.deformer.pose(),
            p.deformer.rotations(),
            (&mut pv.blend, &mut pv.next),
            &mut pv.pose,
        );
        if p.factor.sys.lambda1 == 0.0 {
            for (&v, &at) in constraints.fixed.iter().zip(&constraints.fixed_at) {
                pv.pose[v as usize] = at;
            }
            for h in &constraints.handles {
                for (v, at) in h.target_positions() {
                    pv.pose[v as usize] = at;
                }
            }
        }
        if let Some(order) = self.rest.vertex_order() {
            order.to_user(&pv.pose, &mut pv.pose_user);
        }
        pv.pending = true;
        Some((
            report.iterations,
            report.converged,
            p.level.num_vertices(),
            (report.iterations as Real + report.coarse_work) * p.level.share(),
        ))
    }

    /// The pose a frame shows: the last preview's when it is newer than
    /// the fine pose ([`Deformer::preview`]), else [`Deformer::pose`].
    pub fn shown_pose(&self) -> &[Point] {
        match &self.preview {
            Some(p) if p.pending && self.rest.vertex_order().is_some() => &p.pose_user,
            Some(p) if p.pending => &p.pose,
            _ => self.pose(),
        }
    }

    /// Whether [`Deformer::shown_pose`] is a preview's.
    pub fn shows_preview(&self) -> bool {
        self.preview.as_ref().is_some_and(|p| p.pending)
    }

    /// At the start of a fine sequence after previews: the fine rotations
    /// of the vertices with `set.fit` become the preview level's,
    /// prolongated as a coarse start's are (`CoarseLevel::prolongate_rotations`),
    /// with their area targets; the fine pose keeps its free vertices, and
    /// the first global step brings them to those rotations (the cascadic
    /// start of `solver/multilevel.rs`, from the gesture's last preview).
    /// Returns whether there was a preview to adopt; the next preview
    /// injects the fine state again.
    pub(super) fn adopt_preview(&mut self, el: &ElasticOps, set: &ElasticSet) -> bool {
        let Some(pv) = self.preview.as_deref_mut() else {
            return false;
        };
        pv.following = false;
        if !std::mem::take(&mut pv.pending) {
            return false;
        }
        let Some(p) = pv.problem.as_deref() else {
            return false;
        };
        let st = &mut self.elastic;
        if st.rot.len() != self.pose.len() {
            return false;
        }
        p.level
            .prolongate_rotations(&self.rest, p.deformer.rotations(), &set.fit, &mut st.rot);
        el.rotated_rest_projections(&self.rest.ops.positions, &st.rot, &mut st.proj);
        true
    }

    /// Forgets a pending preview (the pose was set from outside).
    pub(super) fn drop_preview(&mut self) {
        if let Some(pv) = self.preview.as_deref_mut() {
            pv.pending = false;
            pv.following = false;
        }
    }
}

/// The linear blend of the coarse vertices' rigid motions (module docs):
/// `blend` starts as each fine vertex's nearest coarse vertex's motion
/// (`P₀`), [`PREVIEW_PASSES`] closed 1-ring averages make it `P`, and
/// `out_i = M_i x_i + t_i`. Unreferenced vertices stay at rest.
fn prolongate_rigid(
    mesh: &crate::mesh::Mesh,
    fine_of: &[u32],
    near: &[u32],
    coarse_pose: &[Point],
    coarse_rot: &[nalgebra::UnitQuaternion<Real>],
    (blend, next): (&mut Vec<Motion>, &mut Vec<Motion>),
    out: &mut Vec<Point>,
) {
    let rest = mesh.positions();
    let motion: Vec<Motion> = coarse_pose
        .iter()
        .zip(coarse_rot)
        .zip(fine_of)
        .map(|((y, q), &v)| {
            let r = q.to_rotation_matrix().into_inner();
            (r, Vector3::from(*y) - r * Vector3::from(rest[v as usize]))
        })
        .collect();
    blend.par_iter_mut().zip(near).for_each(|(b, &c)| {
        *b = if c == u32::MAX {
            (Matrix3::identity(), Vector3::zeros())
        } else {
            motion[c as usize]
        };
    });
    let topo = mesh.topology();
    for _ in 0..PREVIEW_PASSES {
        let src: &[Motion] = blend;
        next.par_iter_mut().enumerate().for_each(|(i, o)| {
            let ring = topo.ring(i);
            let (mut m, mut t) = src[i];
            for &j in ring {
                m += src[j as usize].0;
                t += src[j as usize].1;
            }
            let w = 1.0 / (ring.len() + 1) as Real;
            *o = (m * w, t * w);
        });
        std::mem::swap(blend, next);
    }
    out.clear();
    out.extend(
        blend
            .iter()
            .zip(rest)
            .map(|((m, t), x)| -> Point { (m * Vector3::from(*x) + t).into() }),
    );
}

#[cfg(test)]
#[path = "preview_tests.rs"]
mod tests;
