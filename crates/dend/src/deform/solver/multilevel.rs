//! The coarse level of the elastic iteration (`deform::coarse`): the start
//! of a sequence from the rest pose and the corrections during any
//! sequence.
//!
//! - **Start** (cascadic): solve the restricted problem on the coarse mesh,
//!   take its rotations to the fine mesh, then iterate on the fine mesh as
//!   after [`Deformer::propagate_rotations`].
//! - **Corrections** (a full approximation scheme, Brandt 1977, in rotation
//!   space; prototype FINDINGS2): every [`ElasticParams::correction_period`] fine
//!   iterations of a sequence (a drag's too, never in the frame that
//!   answers it), with `r_f = g_f − Q_f Y` the fine residual (`−½ ∇E_f`),
//!   the fine pose is injected into the coarse mesh (its vertices are fine
//!   vertices), `Y_c⁰`, with fitted rotations `R_c⁰` and residual `r_c⁰`,
//!   and the coarse problem is solved with the linear term that makes
//!   `Y_c⁰` stand for the fine state:
//!
//!   ```text
//!   min E_c(Y_c) − 2⟨s, Y_c⟩,   s = (h_f / h_c) Pᵀ r_f − r_c⁰   (0 on constrained)
//!   ```
//!
//!   (`h` the mean edge lengths of the levels' normalised units, `P` the
//!   smoothed aggregation of `coarse/transfer.rs`; at a fine minimum
//!   `r_f = 0` and `Y_c⁰` solves it, so a converged pose is a fixed point).
//!   The change of the coarse rotations `ΔR_c = R_c R_c⁰ᵀ` goes back as a
//!   smooth field of rotation vectors, `R_i ← exp((P log ΔR_c)_i) R_i`,
//!   the area targets turn with their first vertex, and one fine global
//!   step from those rotations gives the correction `D`. It is kept at the
//!   first `α ∈ {1, ½, ¼}` where `E_f(Y + αD)` is below the current energy
//!   (so the objective still never grows), else dropped. Corrections stop
//!   for the sequence once one gains less than the fine iterations before
//!   it did ([`Corrections::WhileFaster`], the `elastica` preset's; with
//!   [`Corrections::WhileGaining`], the default, once one gains nothing). A coarse solve
//!   that reaches [`CORRECTION_MAX_ITERS`] still gives its rotations (the
//!   energy test above keeps or drops them, as for any correction), and
//!   marks the coarse problem slow: its later corrections stop their
//!   coarse solve once it stalls ([`CORRECTION_STALL`]). A coarse solve
//!   whose update grows [`CORRECTION_DRIFT`] iterations in a row is
//!   drifting, not converging, and stops there too.
//! - **A Newton level** (opt-in, [`Deformer::set_newton_level`]): the
//!   corrections of a sequence that does not start from the rest pose run
//!   on a second coarse problem, a level of about an eighth of the
//!   vertices with no levels below it, as one Newton step each (the same
//!   linear term `s`, the same rotation field back); the start from rest
//!   and its sequence's corrections stay the hierarchy's
//!   ([`NEWTON_LEVEL_MAX_VERTICES`], `Deformer::start_level`).
//! - **A coarser hierarchy for the sequences from a pose** (the default
//!   where the Newton level is off or the mesh has none): a drag's and a
//!   settle's corrections, and those of a sequence from a preview's pose,
//!   run on a second hierarchy whose levels each have about a sixteenth of
//!   the vertices of the one above ([`WARM_COARSE_RATIO`]); the start from
//!   rest and its sequence's corrections stay on the hierarchy at the
//!   coarse ratio.
//! - **No level too large to pay its way**: on a mesh so large that the
//!   hierarchy's first level would keep more than
//!   [`START_LEVEL_MAX_VERTICES`], the start and its sequence begin
//!   further down the hierarchy ([`start_level_ratio`]), and the
//!   sequences from a pose never correct on a finer level than that.
//!
//! [`ElasticParams::correction_period`]: crate::deform::ElasticParams::correction_period
//! [`Corrections::WhileFaster`]: crate::deform::Corrections::WhileFaster
//! [`Corrections::WhileGaining`]: crate::deform::Corrections::WhileGaining

use std::sync::Arc;
use std::time::Instant;

use nalgebra::{UnitQuaternion, Vector3};

use super::detail_fit::DetailFit;
use super::levels::{CoarseRun, Levels};
use super::{CoarseProblem, CoarseSlot, Deformer, SolvedStart};
use crate::deform::coarse::{CoarseLevel, PROLONGATION_PASSES, RESTRICTION_PASSES};
use crate::deform::constraints::{Constraints, RigidTransform};
use crate::deform::elastic::{ElasticOps, ElasticSet};
use crate::deform::error::DeformError;
use crate::deform::factor::Factor;
use crate::deform::params::{DetailTerm, Formulation, Params};
use crate::deform::rest::Rest;
use crate::mesh::{Point, Real};

/// Iteration cap of the coarse solve of a start (the prototype's camel
/// limb needed 135; a coarse solve that hits the cap still gives its
/// rotations).
pub const COARSE_MAX_ITERS: usize = 300;

/// A coarse level of a hierarchy with fewer vertices than this solves its
/// start on its own, not from the levels below it: a start cascaded from
/// the coarsest level (under 1000 vertices) can settle into another basin
/// of the energy, having lost the features that decide it. The survey
/// bumpy plane (40,401 vertices, levels down to about 500) reached
/// objective 30.44 from the full cascade, 27.82 with this rule (two
/// levels: 28.18); the feline's, the armadillo's and the camel's work
/// moved by under 4 % on the one-shot (docs/performance.md).
pub const START_CASCADE_MIN_VERTICES: usize = 2000;

/// Iteration cap of a correction's coarse solve. A solve that reaches it
/// still gives its rotations, kept only if they lower the fine energy like
/// any correction's. The settle after a drag gesture starts far from the
/// minimum (the gesture's frames ran one iteration per drag), and its
/// first correction rarely converges within the cap: when such a
/// correction was skipped and ended the corrections, the settle crawled
/// (60 drags along a turning arc: camel 100 iterations without
/// converging; armadillo the same, 1.4 % above the one-shot objective and
/// 14 % of the diagonal away from its pose; feline not converged either);
/// taken, they settle in 18, 35 and 27 iterations, within 0.03 % of the
/// one-shot objective (`examples/drag_sim.rs`). A cap of 300 instead of
/// taking them converged the camel and the armadillo too, but spent 300
/// coarse iterations on rejected corrections elsewhere (the creature's
/// settle 0.16 → 0.34 s) and not the feline.
pub const CORRECTION_MAX_ITERS: usize = 100;

/// Once a coarse problem is slow (a correction's coarse solve reached
/// [`CORRECTION_MAX_ITERS`]), a correction's coarse solve runs in chunks
/// of [`CORRECTION_CHUNK`] iterations and stops after a chunk that gains
/// less than this share of what the solve gained so far (a ratio of
/// energies: no unit). Survey bumpy plane: 50 → 47 iterations, 7.6 →
/// 3.6 s (`dend deform`); on meshes whose corrections converge within the
/// cap nothing changes (where it was applied to every correction, the
/// camel's settle took 27 iterations instead of 18, docs/performance.md).
pub const CORRECTION_STALL: Real = 0.05;

/// Iterations per chunk of a slow coarse problem's correction solve
/// ([`CORRECTION_STALL`]).
pub const CORRECTION_CHUNK: usize = 5;

/// A correction's coarse solve stops once its update (the largest vertex
/// move of an iteration) has grown this many iterations in a row: it is
/// drifting along a soft mode of the coarse problem, which the linear
/// term `s` pushes, instead of converging. Its rotations are then used
/// as those of a solve that reached the cap (the fine energy test keeps
/// or drops them). On hand_1502's standard edit the second correction's
/// solve had its update grow from 1.2 to 5.0 tolerances over 95
/// iterations in a row, to the [`CORRECTION_MAX_ITERS`] cap, for a
/// 0.02 % gain of the coarse energy; cut after 8 it takes 13, and the
/// edit settles in 50 ms instead of 93 (the same 16 fine iterations, a
/// lower objective). Over the posing suite the longest run of growing
/// updates in a correction solve that then converged is 6 (the same
/// edit's first correction; dino limb 4, survey bar 5): no other
/// correction changes. A ratio of updates: no unit.
pub const CORRECTION_DRIFT: usize = 8;

/// The iterations of a correction's coarse solve on a level of a
/// hierarchy that has a level below it ([`Levels::Many`]): a cycle
/// (Brandt's FAS V-cycle), not a converged solve. Its own corrections
/// (every `correction_period` iterations) go down a level the same way,
/// and the coarsest level takes one Newton step
/// ([`NEWTON_CORRECTION_MAX_ITERS`]). So a correction costs a bounded
/// share of a fine iteration on every level, and on the coarsest a Newton
/// step removes the slow mode (a far part turning as a whole) that the
/// local/global iteration crawls along at every resolution. Measured (`drag_sim --path arc --levels 3`, work in
/// fine iterations): converged solves on every level, feline one-shot
/// 57.8 and settle 240.7, armadillo 186.2 and 243.7; cycles of 5
/// iterations 42.2 and 76.7, 130.6 and 145.5; of 10, 50.9 and 53.8,
/// 152.4 and 137.3 (docs/performance.md).
pub const CYCLE_ITERS: usize = 10;

/// Newton iterations of a correction's solve on a hierarchy's coarsest
/// level: one. The coarse model, not how far its problem is solved,
/// limits what a correction gains (docs/performance.md), and a coarsest
/// solve converged to the tolerance (1–4 Newton iterations on the
/// characters, up to 11 on a generated saddle patch, 32–38 on the dino's
/// limb edit, where a soft mode of the 502-vertex level kept its
/// objective falling for no fine gain) gave no better fine corrections
/// than its first step, at several times the cost. Before, solves were
/// capped at 20 and a level whose solve reached the cap gave no more
/// corrections; one step instead (`drag_sim --path arc`, work in fine
/// iterations, one-shot / settle): camel_9770 46.0 / 45.7 → 44.0 / 40.5,
/// feline_50k 38.9 / 43.0 → 37.9 / 41.8, armadillo_43k 104.0 / 112.6 →
/// 101.6 / 112.6; the camel's settle after a 30 Hz gesture through the
/// server 248–273 → 106–227 ms (its corrections, cheaper, more often end
/// between a person's drags instead of being interrupted); the dino's
/// limb edit 31 → 21 iterations.
pub const NEWTON_CORRECTION_MAX_ITERS: usize = 1;

/// A fine mesh has a Newton level ([`Deformer::set_newton_level`]) when
/// its level simplified [`NEWTON_LEVEL_RATIO`] times the coarse ratio has
/// at most this many vertices: a Newton step there costs about two and a
/// half of the fine mesh's iterations (the 5,400-vertex level under
/// armadillo_43k). On larger levels (feline_50k's 6,200: the same settle
/// either way; igea_134k's 16,800) a Newton step costs more than it saves.
pub const NEWTON_LEVEL_MAX_VERTICES: usize = 6000;

/// The Newton level's simplification, in multiples of the coarse ratio (at
/// the default ratio 4 the level has an eighth of the vertices).
pub const NEWTON_LEVEL_RATIO: usize = 2;

/// The ratio of the Newton level of a fine mesh of `n` vertices under the
/// coarse ratio `ratio` (see [`NEWTON_LEVEL_MAX_VERTICES`]), or `None`
/// where the mesh keeps the hierarchy: a large mesh, or a small one whose
/// level at that ratio is the hierarchy's first level anyway.
pub fn newton_level_ratio(n: usize, ratio: usize) -> Option<usize> {
    let wanted = NEWTON_LEVEL_RATIO * ratio;
    let actual = crate::deform::coarse::ratio_at_most(n, wanted);
    (n >= crate::deform::coarse::MIN_VERTICES
        && actual > ratio.max(2)
        && n / actual <= NEWTON_LEVEL_MAX_VERTICES)
        .then_some(wanted)
}

/// The coarse ratio of the hierarchy the fine mesh's sequences from a pose
/// (a drag's, a settle's) correct on, beside the one at the coarse ratio
/// that the starts and sequences from the rest pose use: each level has
/// about a sixteenth of the vertices of the one above. After a drag the
/// pose is near its minimum, and a cheaper, coarser cycle corrects it in
/// less work; from the rest pose the coarser levels stand too far from the
/// fine problem. On the load test's arc (`drag_sim --path arc`, work in
/// fine iterations, settle): camel_9770 68.8 → 45.5, armadillo_43k 60.9 →
/// 53.8, feline_50k 44.4 → 43.1, igea_134k 100.4 → 58.5 (8.0 → 4.2 s),
/// the one-shots unchanged; the same ratio for every sequence failed the
/// posing suite's one-shots from rest (15 → 12 of 22; docs/performance.md).
pub const WARM_COARSE_RATIO: usize = 16;

/// The most vertices the first level of the hierarchy of the start from
/// rest and its sequence keeps: on a larger mesh that level is skipped for
/// the next one down ([`start_level_ratio`]). A correction's gain does not
/// grow with its level's resolution (a settle's corrections on a level of
/// half the fine vertices, solved to convergence, removed about as much of
/// the largest error as cycles on a sixteenth, at four times their time:
/// armadillo_43k 35 % against 27 % each, feline_50k 17 % against 34 %),
/// while its cost does. On igea_134k the 33,587-vertex first level of the
/// ratio-4 hierarchy made the one-shot solve of the load test's arc cost
/// 96.8 fine iterations of time against 58.2 from its 8,398-vertex level
/// (`drag_sim --path arc`, the same run; the Loop-subdivided armadillo_43k,
/// 172,966 vertices, 110.6 against 91.9; the camel_9770 subdivided twice,
/// 156,290, 50.0 against 51.0). The meshes up to 65,536 vertices keep their
/// hierarchy: feline_50k's first level (12,466 vertices) is worth its cost
/// (its one-shot 37.0 against 42.8 from a level of 8,310;
/// docs/performance.md).
pub const START_LEVEL_MAX_VERTICES: usize = 16_384;

/// The ratio of the first level of the hierarchy the start from rest of a
/// fine mesh of `n` vertices corrects on under the coarse ratio `ratio`:
/// `ratio^k` for the least `k ≥ 1` whose level keeps at most
/// [`START_LEVEL_MAX_VERTICES`].
pub fn start_level_ratio(n: usize, ratio: usize) -> usize {
    let step = ratio.max(2);
    let mut r = step;
    while n / r > START_LEVEL_MAX_VERTICES {
        r *= step;
    }
    r
}

/// The ratio of the first level of the hierarchy the sequences from a pose
/// use on a fine mesh of `n` vertices under the coarse ratio `ratio`
/// ([`WARM_COARSE_RATIO`]), or `None` where it would be the start's level
/// (a small mesh: both simplified to the fewest coarse vertices).
pub fn warm_level_ratio(n: usize, ratio: usize) -> Option<usize> {
    use crate::deform::coarse::{ratio_at_most, MIN_VERTICES};
    let wanted = WARM_COARSE_RATIO.max(ratio);
    (n >= MIN_VERTICES && ratio_at_most(n, wanted) > ratio_at_most(n, ratio)).then_some(wanted)
}

/// The parameters of the coarse problem on the level of `first`, from the
/// fine mesh's `params`: a hierarchy coarser than the coarse ratio
/// ([`warm_level_ratio`]) keeps its ratio on the levels below its first.
fn level_params(params: &Params, (ratio, newton_level): (usize, bool)) -> Params {
    match params.elastic() {
        Some(e) if !newton_level && ratio > e.coarse_ratio => {
            params.with_elastic(|e| e.coarse_ratio = ratio)
        }
        _ => *params,
    }
}

/// The parameters of the coarse problem of `level`, the level of `first`,
/// in its own units: [`level_params`] of the fine mesh's `params`, then
/// [`coarse_params`].
fn first_level_params(
    rest: &Rest,
    params: &Params,
    first: (usize, bool),
    level: &CoarseLevel,
) -> Params {
    coarse_params(rest, &level_params(params, first), level)
}

impl Levels {
    /// The levels the coarse problem's own solve uses.
    fn below(self) -> Levels {
        match self {
            Levels::One | Levels::Two => Levels::One,
            Levels::Many => Levels::Many,
        }
    }
}

/// The coarse parameters of a fine problem: the fine ones, with the fine
/// tolerance in the coarse level's mean edge lengths.
pub(super) fn coarse_params(rest: &Rest, params: &Params, level: &CoarseLevel) -> Params {
    let mut p = *params;
    p.tol = params.tol * rest.ops.scale / level.rest.ops.scale;
    p
}

/// Builds the coarse problem of `constraints`' set on the level of at
/// most `ratio` (module docs) with `params` (the fine ones, their detail
/// weight scaled: `solver/detail_fit.rs`); `newton_level`: the level takes Newton
/// steps and has no levels below it ([`newton_level_ratio`]); `detail`:
/// the scale of the detail weight of the levels below it against its own.
pub(super) fn coarse_problem(
    rest: &Arc<Rest>,
    params: &Params,
    (ratio, newton_level): (usize, bool),
    constraints: &Constraints,
    (levels, detail): (Levels, Real),
) -> Option<CoarseProblem> {
    let params = &level_params(params, (ratio, newton_level));
    let level: Arc<CoarseLevel> = rest.coarse_at_most(ratio)?;
    let cc = level.restrict(constraints)?;
    let factor = Arc::new(Factor::build(&level.rest, params, &cc).ok()?);
    let mut fine_fixed = vec![false; rest.mesh.num_vertices()];
    for v in constraints.constrained() {
        fine_fixed[v as usize] = true;
    }
    let mut coarse_fixed = vec![false; level.num_vertices()];
    for v in cc.constrained() {
        coarse_fixed[v as usize] = true;
    }
    let mut deformer = Box::new(Deformer::new(level.rest.clone(), *params));
    // (its own sequences correct on its levels below: no hierarchy beside them)
    deformer.warm_levels = false;
    // (its levels below take the detail weight's scale again)
    deformer.detail_fit = DetailFit::inherited(detail);
    // a coarse problem's own corrections are its coarse problems' (the
    // coarse start from rest converges each level's problem by them)
    deformer.set_galerkin(None);
    // the coarsest level of a hierarchy takes Newton steps, and so does a
    // fine mesh's Newton level, with no levels below it
    deformer.newton =
        levels == Levels::Many && (newton_level || level.rest.coarse_at_most(ratio).is_none());
    let levels_below = if newton_level {
        Levels::One
    } else {
        levels.below()
    };
    deformer.set_levels(levels_below);
    Some(CoarseProblem {
        levels_below,
        level,
        factor,
        deformer,
        fine_fixed,
        coarse_fixed,
        solved_start: None,
        slow: false,
    })
}

/// The coarse problem of the level `first` for the set `internal` (the
/// solver's order), with what its own solves need below it, its coarse
/// start solved where `solve` ([`Deformer::build_factor`]); `None` where the
/// set does not survive on the level or its solve failed.
pub(super) fn coarse_problem_ahead(
    rest: &Arc<Rest>,
    below: &Params,
    first: (usize, bool),
    internal: &Constraints,
    levels: Levels,
    solve: bool,
) -> Option<Box<CoarseProblem>> {
    let t0 = std::time::Instant::now();
    // (a new set's levels take the fine detail weight: `detail_fit.rs`)
    let mut p = coarse_problem(rest, below, first, internal, (levels, 1.0))?;
    let cc = p.level.restrict(internal)?;
    p.deformer.params = first_level_params(rest, below, first, &p.level);
    if solve {
        p.solved_start = Some(solve_start(&mut p, &cc, internal, t0)?);
    }
    p.prepare_below(&cc)?;
    Some(Box::new(p))
}

impl CoarseProblem {
    /// Builds what this problem's own solves need ([`Deformer::prepare_levels`]
    /// for its restricted constraints `cc`): the Newton pattern where it is
    /// the coarsest level, and the levels below it. `None` when its factor
    /// has no elastic part to analyse.
    pub(super) fn prepare_below(&mut self, cc: &Constraints) -> Option<()> {
        let factor = self.factor.clone();
        if self.deformer.newton {
            let (el, set) = factor.elastic.as_ref()?;
            self.deformer.prepare_newton(&factor, (el, set));
        }
        self.deformer.prepare_levels(&factor, cc);
        Some(())
    }
}

/// Solves the coarse start of `p` from the coarse rest pose for the
/// restricted constraints `cc` of the fine `constraints` (the deformer's
/// parameters already set), its time counted from `t0`; `None` when the
/// coarse solve failed.
pub(super) fn solve_start(
    p: &mut CoarseProblem,
    cc: &Constraints,
    constraints: &Constraints,
    t0: Instant,
) -> Option<SolvedStart> {
    let coarse = &mut p.deformer;
    coarse.reset();
    coarse.elastic.linear.clear();
    // a small level starts on its own (see `START_CASCADE_MIN_VERTICES`)
    let alone = p.level.num_vertices() < START_CASCADE_MIN_VERTICES;
    if alone {
        coarse.set_levels(Levels::One);
    }
    // the coarsest level's start takes local/global iterations, and Newton
    // steps only once they crawl (a small mesh's switch): Newton steps from
    // the rest pose, on the convex model far from a minimum, can end in
    // another basin (the survey cylinder at coarse ratio 5: objective 453
    // against 232, capped at 100 iterations, where this start converges)
    let newton = std::mem::replace(&mut coarse.newton, false);
    let report = coarse.step(&p.factor, cc, COARSE_MAX_ITERS).ok();
    coarse.newton = newton;
    if alone {
        coarse.set_levels(p.levels_below);
    }
    let report = report?;
    tracing::debug!(
        vertices = p.level.num_vertices(),
        iterations = report.iterations,
        converged = report.converged,
        coarse_work = report.coarse_work,
        "coarse start"
    );
    if !report.objective.is_finite() || coarse.rotations().len() != p.level.num_vertices() {
        return None;
    }
    Some(SolvedStart {
        targets: targets_of(constraints),
        rotations: coarse.rotations().to_vec(),
        run: CoarseRun {
            iterations: report.iterations,
            ms: t0.elapsed().as_secs_f64() * 1e3,
            work: (report.iterations as Real + report.coarse_work) * p.level.share(),
        },
    })
}

/// A slow coarse problem's correction solve (`coarse` holds its pose,
/// linear term and constraints `cc`): chunks of [`CORRECTION_CHUNK`]
/// iterations, the same iterates as one call, until it converges, reaches
/// [`CORRECTION_MAX_ITERS`], stops inside a chunk (its update drifting,
/// [`Deformer::drift_limit`]), or a chunk gains less than
/// [`CORRECTION_STALL`] of the energy the solve has gained so far. The
/// report's `iterations` count the whole solve.
pub(super) fn solve_until_stalled(
    coarse: &mut Deformer,
    factor: &Factor,
    cc: &Constraints,
) -> Option<super::StepReport> {
    let mut its = 0;
    let mut start = None;
    loop {
        let budget = CORRECTION_CHUNK.min(CORRECTION_MAX_ITERS - its);
        let mut r = coarse.step(factor, cc, budget).ok()?;
        let e0 = *start.get_or_insert(r.initial_objective);
        let before = e0 - r.initial_objective;
        let gained = e0 - r.objective;
        its += r.iterations;
        let stalled = gained - before < CORRECTION_STALL * gained;
        let done = r.converged
            || r.diverged
            || r.interrupted
            || r.iterations == 0
            || its >= CORRECTION_MAX_ITERS
            || r.iterations < budget
            || stalled;
        r.iterations = its;
        if done {
            return Some(r);
        }
    }
}

/// The handles' targets of a constraint set, in order.
fn targets_of(constraints: &Constraints) -> Vec<RigidTransform> {
    constraints.handles.iter().map(|h| h.target).collect()
}

/// The outcome of a coarse correction.
pub(super) enum Correction {
    /// The fine energy fell to this value.
    Kept(Real, CoarseRun),
    /// No step along the correction lowered the fine energy.
    Dropped(CoarseRun),
    /// No correction is possible (no coarse problem, or its solve failed
    /// or diverged).
    Unavailable(CoarseRun),
    /// The coarse solve was interrupted ([`Deformer::set_interrupt`]):
    /// nothing was applied.
    Interrupted(CoarseRun),
}

impl Deformer {
    /// The level below this deformer's mesh: its coarse ratio, and whether
    /// it is a Newton level ([`newton_level_ratio`], only below the fine
    /// mesh of a hierarchy: a coarse problem's deformer never has the
    /// option set); `None` for a formulation without levels.
    pub(super) fn first_level(&self) -> Option<(usize, bool)> {
        let ratio = self.params.elastic()?.coarse_ratio;
        if !self.fine_hierarchy() {
            return Some((ratio, false));
        }
        let n = self.rest.mesh.num_vertices();
        if self.newton_level {
            if let Some(r) = newton_level_ratio(n, ratio) {
                return Some((r, true));
            }
        }
        // (never a finer level than the start's)
        let (start, _) = self.start_level()?;
        Some((warm_level_ratio(n, start).unwrap_or(start), false))
    }

    /// The rotations of the elastic iteration's current pose, `#V` (the
    /// identity before the first step).
    pub(crate) fn rotations(&self) -> &[UnitQuaternion<Real>] {
        &self.elastic.rot
    }

    /// The level the coarse start from the rest pose and a sequence from
    /// the rest pose's corrections solve on: the hierarchy's first level
    /// ([`start_level_ratio`] on the fine mesh), also on a mesh with a
    /// Newton level. From the rest pose the Newton
    /// level's corrections fail their line search far from the minimum
    /// and its start alone lands further from it (the posing suite's
    /// armadillo_43k standard edit took 30 fine iterations instead of 19,
    /// and the survey's bumpy plane stopped in another basin; both fixed
    /// with the hierarchy's start and corrections from rest).
    pub(super) fn start_level(&self) -> Option<(usize, bool)> {
        let ratio = self.params.elastic()?.coarse_ratio;
        if !self.fine_hierarchy() {
            return Some((ratio, false));
        }
        let n = self.rest.mesh.num_vertices();
        Some((start_level_ratio(n, ratio), false))
    }

    /// Whether this deformer is a fine mesh's with a hierarchy of levels,
    /// whose levels [`Deformer::start_level`] and [`Deformer::first_level`]
    /// choose by its size; a coarse problem's deformer, or one with fewer
    /// levels, corrects on the level at its coarse ratio.
    fn fine_hierarchy(&self) -> bool {
        self.levels == Levels::Many && self.warm_levels
    }

    /// Whether the coarse start and the corrections use different coarse
    /// problems: the first level is a Newton level or the first level of
    /// the hierarchy of the sequences from a pose ([`warm_level_ratio`]).
    pub(super) fn separate_start(&self) -> bool {
        self.first_level()
            .zip(self.start_level())
            .is_some_and(|(first, start)| first != start)
    }

    /// Runs `f` with the coarse problem of `constraints`' set (built on
    /// first use for the fine `factor`): the corrections' (`start`
    /// false) or the coarse start's ([`Deformer::start_level`]), or
    /// returns `None` when there is none ([`Levels::One`], a small mesh, a
    /// set that does not survive).
    fn with_coarse<R>(
        &mut self,
        factor: &Factor,
        constraints: &Constraints,
        start: bool,
        f: impl FnOnce(&mut Deformer, &mut CoarseProblem, &Constraints) -> Option<R>,
    ) -> Option<R> {
        if self.levels == Levels::One {
            return None;
        }
        let separate = start && self.separate_start();
        let first = if separate {
            self.start_level()?
        } else {
            self.first_level()?
        };
        if self.detail_fit.with_factor(factor.id()) {
            self.drop_coarse_problems();
        }
        let key = (factor.id(), first.0);
        let below = self.detail_fit.below(&self.params);
        let detail = (self.levels, self.detail_fit.scale());
        let mut problem = match self.coarse_slot(separate).take() {
            Some((k, p)) if k == key => p,
            _ => coarse_problem(&self.rest, &below, first, constraints, detail).map(Box::new),
        };
        let out = match problem.as_deref_mut() {
            Some(p) => match p.level.restrict(constraints) {
                Some(cc) => {
                    p.deformer.params = first_level_params(&self.rest, &below, first, &p.level);
                    f(self, p, &cc)
                }
                None => None,
            },
            None => None,
        };
        *self.coarse_slot(separate) = Some((key, problem));
        out
    }

    /// Forgets the coarse problems built (their detail weight is stale:
    /// `solver/detail_fit.rs`); the next start or correction builds them again.
    pub(super) fn drop_coarse_problems(&mut self) {
        self.coarse = None;
        self.start_coarse = None;
    }

    /// Where [`Deformer::with_coarse`] keeps its coarse problem: the coarse
    /// start's own slot (`separate`) or the corrections'.
    fn coarse_slot(&mut self, separate: bool) -> &mut Option<CoarseSlot> {
        if separate {
            &mut self.start_coarse
        } else {
            &mut self.coarse
        }
    }

    /// Builds what solving `constraints`' set with `factor` needs on every
    /// level below this mesh, without solving anything: each level's
    /// coarse problem (the restricted set's factor) and the coarsest
    /// level's Newton pattern. A step builds them on first use; this
    /// moves that per-set cost (camel_9770: about 45 ms, five fine
    /// iterations) out of the first step that needs them, as the fine
    /// factor's own is. Nothing happens with [`Levels::One`], on a mesh
    /// without a coarse level, or for a set that does not survive on it.
    pub fn prepare_levels(&mut self, factor: &Factor, constraints: &Constraints) {
        if let (Some(g), Some((el, set))) = (self.galerkin_mode, factor.elastic.as_ref()) {
            // the Galerkin corrections' aggregates and symbolic analysis
            self.prepare_galerkin(factor, (el, set), g);
        }
        let rest = self.rest.clone();
        let internal = rest.internal_constraints(constraints);
        self.with_coarse(factor, &internal, false, |_, p, cc| p.prepare_below(cc));
        if self.separate_start() {
            self.with_coarse(factor, &internal, true, |_, p, cc| p.prepare_below(cc));
        }
    }

    /// Sets the rotations of the vertices with `set.fit` (and the area
    /// targets) from a coarse solve from the rest pose (module docs).
    /// Returns `None`, with nothing changed, when there is no coarse level
    /// for this mesh or set.
    pub(super) fn coarse_start(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        constraints: &Constraints,
    ) -> Option<CoarseRun> {
        let t0 = Instant::now();
        self.with_coarse(factor, constraints, true, |fine, p, cc| {
            let solved = p
                .solved_start
                .take()
                .filter(|s| targets_of(constraints) == s.targets);
            let solved = match solved {
                Some(s) => s,
                None => solve_start(p, cc, constraints, t0)?,
            };
            let st = &mut fine.elastic;
            p.level
                .prolongate_rotations(&fine.rest, &solved.rotations, &set.fit, &mut st.rot);
            el.rotated_rest_projections(&fine.rest.ops.positions, &st.rot, &mut st.proj);
            Some(solved.run)
        })
    }

    /// Whether this deformer's sequences use coarse levels: levels below
    /// the fine mesh, the elastic formulation and its nonlinear detail term.
    pub(super) fn levels_used(&self) -> bool {
        self.levels != Levels::One
            && self.params.formulation.kind() == Formulation::Elastic
            && self.params.detail == DetailTerm::Nonlinear
    }

    /// Builds `constraints`' factor ([`Factor::build`]) for this deformer's
    /// parameters, and on another thread at the same time the levels
    /// below ([`Deformer::prepare_levels`]: they need the rest operators
    /// and the constraints but not the fine factor, so the two overlap).
    /// Where the next step will start on the coarse level (a sequence from
    /// the rest pose, the elastic formulation), the coarse start is solved
    /// there too, and the first step only carries the coarse rotations
    /// over. The pose
    /// reached is the same as with [`Factor::build`] (the coarse solve is
    /// the same one, run earlier).
    pub fn build_factor(&mut self, constraints: &Constraints) -> Result<Factor, DeformError> {
        let levels_used = self.levels_used();
        let ahead = levels_used && self.elastic.starts_from_rest();
        // a new set's levels start at the fine detail weight
        self.detail_fit.restart();
        let (rest, params, levels) = (&self.rest, &self.params, self.levels);
        let (first, start_first) = (self.first_level(), self.start_level());
        let separate = self.separate_start();
        // (`Factor::build` takes the mesh's order, the coarse problem the
        // solver's)
        let internal = rest.internal_constraints(constraints);
        // the coarse problem with the levels below it, for the corrections
        let build =
            |first, solve| coarse_problem_ahead(rest, params, first, &internal, levels, solve);
        let (factor, (solved, start)) = rayon::join(
            || Factor::build(rest, params, constraints),
            || {
                if !levels_used {
                    return (None, None);
                }
                let solved = first.and_then(|f| build(f, ahead && !separate));
                let start = start_first
                    .filter(|_| separate)
                    .and_then(|f| build(f, ahead));
                (solved, start)
            },
        );
        let factor = factor?;
        if let (Some(p), Some((ratio, _))) = (solved, first) {
            self.coarse = Some(((factor.id(), ratio), Some(p)));
        }
        if let (Some(p), Some((ratio, _))) = (start, start_first) {
            self.start_coarse = Some(((factor.id(), ratio), Some(p)));
        }
        Ok(factor)
    }

    /// One coarse correction of the current pose, whose energy is `e`
    /// (module docs).
    pub(super) fn coarse_correction(
        &mut self,
        factor: &Factor,
        (el, set): (&ElasticOps, &ElasticSet),
        constraints: &Constraints,
        e: Real,
    ) -> Correction {
        let t0 = Instant::now();
        let ms = |t0: Instant| t0.elapsed().as_secs_f64() * 1e3;
        // (the fine half of a correction, its global step and energy
        // tests, counts as one fine iteration)
        let run = |(iterations, work): (usize, Real), fine: Real| CoarseRun {
            iterations,
            ms: ms(t0),
            work: work + fine,
        };
        // a sequence from the rest pose corrects on the hierarchy, one
        // from another pose (a drag's, a settle's) on the Newton level
        // where there is one (`start_level`), until a correction there
        // gains nothing (`correct`)
        let on_hierarchy = self.elastic.on_hierarchy;
        let field = self.with_coarse(factor, constraints, on_hierarchy, |fine, p, cc| {
            // r_f = g_f − Q_f Y at the current rotations
            let r_f = fine.residual_now(el, set).to_vec();
            // the fine pose injected, its rotations and residual there
            let ops = &fine.rest.ops;
            let injected: Vec<Point> = p
                .level
                .fine_of
                .iter()
                .map(|&v| ops.denormalise(fine.y[v as usize]))
                .collect();
            let coarse = &mut p.deformer;
            coarse.set_pose(injected).ok()?;
            coarse.elastic.linear.clear();
            coarse.step(&p.factor, cc, 0).ok()?;
            let (el_c, set_c) = p.factor.elastic.as_ref()?;
            let r_c0 = coarse.residual_now(el_c, set_c).to_vec();
            let rot_c0 = coarse.elastic.rot.clone();
            // s = (h_f / h_c) Pᵀ r_f − r_c⁰, zero on the constrained vertices
            let ratio = fine.rest.ops.scale / p.level.rest.ops.scale;
            let mut s = p.level.restrict_forces(
                &fine.rest,
                &r_f,
                &p.fine_fixed,
                &p.coarse_fixed,
                RESTRICTION_PASSES,
            );
            for ((s, r0), &fixed) in s.iter_mut().zip(&r_c0).zip(&p.coarse_fixed) {
                for k in 0..3 {
                    s[k] = if fixed { 0.0 } else { ratio * s[k] - r0[k] };
                }
            }
            coarse.set_linear_term(s);
            coarse.interrupt = fine.interrupt.clone();
            coarse.drift_limit = Some(CORRECTION_DRIFT);
            // the coarsest level of a hierarchy takes a Newton step; a level
            // with a level below it smooths
            let report = if coarse.newton {
                coarse.step(&p.factor, cc, NEWTON_CORRECTION_MAX_ITERS).ok()
            } else if p.levels_below == Levels::Many {
                coarse.step(&p.factor, cc, CYCLE_ITERS).ok()
            } else if p.slow {
                solve_until_stalled(coarse, &p.factor, cc)
            } else {
                coarse.step(&p.factor, cc, CORRECTION_MAX_ITERS).ok()
            };
            coarse.set_linear_term(Vec::new());
            coarse.interrupt = None;
            coarse.drift_limit = None;
            let report = report?;
            // the gain the coarse model predicts, in the fine level's
            // units (`solver/detail_fit.rs`)
            let predicted = (report.initial_objective - report.objective) / (ratio * ratio);
            let its = (
                report.iterations,
                (report.iterations as Real + report.coarse_work) * p.level.share(),
            );
            if report.interrupted {
                return Some((its, Err(())));
            }
            if report.iterations >= CORRECTION_MAX_ITERS && !report.converged {
                p.slow = true;
            }
            if report.diverged {
                return Some((its, Ok(None)));
            }
            // ΔR_c = R_c R_c⁰ᵀ as rotation vectors, prolongated
            let w_c: Vec<Vector3<Real>> = coarse
                .elastic
                .rot
                .iter()
                .zip(&rot_c0)
                .map(|(r1, r0)| (r1 * r0.inverse()).scaled_axis())
                .collect();
            let w_f = p.level.prolongate_vectors(
                &fine.rest,
                &w_c,
                &p.fine_fixed,
                &p.coarse_fixed,
                PROLONGATION_PASSES,
            );
            Some((its, Ok(Some((w_f, predicted)))))
        });
        match field {
            None => Correction::Unavailable(run((0, 0.0), 0.0)),
            Some((its, Err(()))) => Correction::Interrupted(run(its, 0.0)),
            Some((its, Ok(None))) => Correction::Unavailable(run(its, 0.0)),
            Some((its, Ok(Some((w_f, predicted))))) => {
                match self.apply_rotation_correction(factor, (el, set), &w_f, e) {
                    Some(e_new) => {
                        self.detail_fit.record(factor.id(), e, e - e_new, predicted);
                        Correction::Kept(e_new, run(its, 1.0))
                    }
                    None => Correction::Dropped(run(its, 1.0)),
                }
            }
        }
    }
}
