//! How many levels an elastic sequence uses ([`Levels`]) and what a coarse
//! run did ([`CoarseRun`]): pure data a [`Deformer`] holds and
//! `multilevel.rs` works with, in a leaf below both.
//!
//! [`Deformer`]: super::Deformer

use crate::mesh::Real;

/// How many levels an elastic sequence uses.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Levels {
    /// The fine mesh only: first rotations from the handles' rotations
    /// spread by harmonic weights, no corrections.
    One,
    /// The coarse level where the mesh has one and the constraint set
    /// survives on it (`deform::coarse`): a coarse start from the rest pose
    /// and coarse corrections (module docs); else as `One`. The coarse
    /// problem is solved on its own level only.
    Two,
    /// A hierarchy: as `Two`, and the coarse problem is solved the same way
    /// on a level of its own, down to a level under
    /// [`coarse::MIN_VERTICES`](crate::deform::coarse::MIN_VERTICES),
    /// whose iteration takes Newton steps (`solver/newton.rs`); a
    /// correction's solve on a level above that one runs
    /// [`CYCLE_ITERS`](super::multilevel::CYCLE_ITERS) iterations (a
    /// cycle), not to convergence.
    ///
    /// The default: with the characters' coarse ratio 4 it does less work
    /// than `Two` at ratio 3 on every character, one-shot and settle
    /// (`drag_sim --path arc`, in fine iterations: camel 47.0 and 45.7
    /// against 77.4 and 83.0, feline 39.3 and 43.2 against 118.7 and
    /// 105.7, armadillo 104.0 and 112.6 against 150.0 and 127.0;
    /// docs/performance.md).
    #[default]
    Many,
}

/// Coarse corrections in the Galerkin coarse space of the fine energy
/// (`solver/galerkin.rs`) instead of the coarse problems of
/// `solver/multilevel.rs`: each one Newton step of the fine reduced
/// energy restricted to the blended rigid motions of aggregates of
/// vertices. The coarse start of a sequence from rest is the hierarchy's
/// either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Galerkin {
    /// How many coarse levels the aggregates span: the fine vertices
    /// nearest each vertex of the `depth`-th coarse level (about
    /// `coarse_ratio^depth` vertices each; the last level of a mesh with
    /// fewer), at least 1.
    pub depth: usize,
    /// Corrections that reuse one assembly and factorisation of the
    /// coarse matrix (and its lever arms) before it is assembled again at
    /// the current pose, at least 1. A correction whose reused matrix
    /// gives no descent is tried again with a fresh one.
    pub lag: usize,
    /// Fine iterations between two corrections, at least 1.
    pub period: usize,
    /// Passes of smoothing of the aggregates' weights across their
    /// borders (`solver/galerkin.rs`): 0 moves each aggregate rigidly,
    /// each pass blends the motions of neighbouring aggregates over one
    /// more ring of vertices.
    pub smooth: usize,
}

impl Default for Galerkin {
    /// Aggregates of two levels (about 16 vertices at coarse ratio 4), a
    /// correction after every fine iteration, the matrix assembled every
    /// sixth, the weights smoothed once (on the arc gesture of
    /// `drag_sim`, settles in 9, 10 and 38 iterations on camel_9770,
    /// feline_50k and armadillo_43k against 13, 19 and 57 unsmoothed:
    /// docs/performance.md).
    fn default() -> Self {
        Galerkin {
            depth: 2,
            lag: 6,
            period: 1,
            smooth: 1,
        }
    }
}

/// What a coarse start or correction did.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct CoarseRun {
    /// Coarse iterations.
    pub iterations: usize,
    /// Wall time (level and coarse factor when first needed, coarse solve,
    /// transfers and the fine steps of a correction), ms.
    pub ms: Real,
    /// The work in fine iterations ([`StepReport::coarse_work`]).
    ///
    /// [`StepReport::coarse_work`]: crate::deform::StepReport::coarse_work
    pub work: Real,
}
