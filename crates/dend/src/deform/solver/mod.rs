//! The DEND iteration ([`Deformer::step`], design.md §8).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use super::coarse::CoarseLevel;
use super::constraints::{Constraints, RigidTransform};
use super::error::DeformError;
use super::factor::{Factor, FactorKey};
use super::params::Params;
use super::rest::Rest;
use crate::mesh::{Point, Real};
use levels::CoarseRun;
pub use levels::{Galerkin, Levels};
use scratch::Scratch;
use state::State;

// The iteration's steps (`impl Deformer` blocks) name this file's types;
// the state a `Deformer` holds is in the leaves (`state.rs`,
// `newton_state.rs`, `scratch.rs`, `levels.rs`, `detail_fit.rs`), so this file names none
// of the steps (docs/architecture.md, "Layering"). deform/mod.rs
// re-exports the public items of `multilevel.rs` and `preview.rs`.
mod correct;
mod detail_fit;
mod galerkin;
mod galerkin_state;
mod least_squares;
pub(super) mod level_minima;
mod levels;
mod local_global;
pub(super) mod multilevel;
mod newton;
mod newton_pattern;
mod newton_state;
pub(super) mod prepared;
pub(super) mod preview;
mod propagate;
mod scratch;
mod state;

#[cfg(test)]
mod detail_fit_tests;
#[cfg(test)]
mod galerkin_tests;
#[cfg(test)]
mod hierarchy_tests;
#[cfg(test)]
mod interrupt_tests;
#[cfg(test)]
mod level_minima_tests;
#[cfg(test)]
mod newton_tests;
#[cfg(test)]
mod open_tests;
#[cfg(test)]
mod order_tests;
#[cfg(test)]
mod rest_start_tests;
#[cfg(test)]
mod test_util;
#[cfg(test)]
mod turn_tests;

/// What one [`Deformer::step`] did.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct StepReport {
    /// Iterations run.
    pub iterations: usize,
    /// The last iteration's largest vertex move, in mean edge lengths.
    pub last_update: Real,
    /// Whether the last update fell below `tol`.
    pub converged: bool,
    /// Whether the iteration stopped because its objective kept growing
    /// (the best pose seen is kept).
    pub diverged: bool,
    /// The final objective value (squared residual of the stacked rows).
    pub objective: Real,
    /// The objective at the start of the step (targets applied, before any
    /// iteration). A step that does not converge ends within 5 % of the best
    /// objective it saw, so then `objective <= 1.05 · initial_objective`.
    pub initial_objective: Real,
    /// Coarse iterations this step ran (elastic sequences with
    /// [`Levels::Two`] or [`Levels::Many`]: the coarse start of a sequence from the rest pose
    /// and the coarse corrections, `solver/multilevel.rs`; each costs about
    /// `#Vc / #V` of a fine iteration), not counted in `iterations`.
    pub coarse_iterations: usize,
    /// Wall time of that coarse work (level and coarse factor when first
    /// needed, coarse solves, transfers, the fine steps of corrections),
    /// ms; 0 without any.
    pub coarse_ms: Real,
    /// That coarse work in this mesh's iterations: each level's
    /// iterations weighted by its vertex count over this mesh's, summed
    /// over every level below, plus one iteration for the fine half of
    /// each correction. With `iterations` it is the step's work in fine
    /// iterations, a measure that does not depend on the host.
    pub coarse_work: Real,
    /// Whether the step stopped early because its interrupt flag was
    /// raised ([`Deformer::set_interrupt`]): the pose is the one after
    /// `iterations` whole iterations (unchanged when 0).
    pub interrupted: bool,
}

/// One editing state: the current pose, warm-started across drags, and the
/// scratch memory of the iteration (sized once per constraint set).
pub struct Deformer {
    rest: Arc<Rest>,
    params: Params,
    /// Normalised pose `Y`, `#V`.
    y: Vec<Point>,
    /// Pose in mesh units, kept in step with `y`.
    pose: Vec<Point>,
    /// `pose` in the mesh's own vertex order when the solver renumbered
    /// it ([`Rest::vertex_order`]; empty otherwise): what
    /// [`Deformer::pose`] returns.
    pose_user: Vec<Point>,
    scratch: Scratch,
    /// The elastic formulation's state (rotations, projections, Anderson).
    elastic: State,
    /// Whether sequences from rest start on the coarse level.
    levels: Levels,
    /// The coarse problem of the last fine factor a coarse start or
    /// correction used.
    coarse: Option<CoarseSlot>,
    /// The coarse problem of the coarse start where it is not the
    /// corrections' ([`Deformer::start_level`]).
    start_coarse: Option<CoarseSlot>,
    /// Whether coarse corrections wait (a gesture is under way; see
    /// [`Deformer::hold_corrections`]).
    corrections_held: bool,
    /// [`Deformer::hold_coarse_start`].
    coarse_start_held: bool,
    /// Stop a step once its update has grown this many iterations in a
    /// row (a correction's coarse solve: `multilevel::CORRECTION_DRIFT`);
    /// `None`, never.
    pub(super) drift_limit: Option<usize>,
    /// Whether this deformer is the coarsest level of a hierarchy, whose
    /// iteration takes Newton steps (`solver/newton.rs`).
    newton: bool,
    /// [`Deformer::set_newton_level`].
    newton_level: bool,
    /// Whether the sequences from a pose correct on a hierarchy of their
    /// own ([`multilevel::WARM_COARSE_RATIO`]): the fine mesh's deformer;
    /// a coarse problem's corrects on the levels below it.
    warm_levels: bool,
    /// The coarse previews' problem and last pose ([`Deformer::preview`]).
    preview: Option<Box<Preview>>,
    /// Raised by another thread to stop a step at its next safe point
    /// ([`Deformer::set_interrupt`]).
    interrupt: Option<Arc<AtomicBool>>,
    /// Corrections in the Galerkin coarse space, or the coarse problems'
    /// (`None`, the default; [`Deformer::set_galerkin`]).
    galerkin_mode: Option<Galerkin>,
    /// Their per-set state.
    galerkin: Option<Box<galerkin_state::GalerkinState>>,
    /// The coarse levels' detail weight (`solver/detail_fit.rs`).
    detail_fit: detail_fit::DetailFit,
}

/// The coarse problem of one fine constraint set.
struct CoarseProblem {
    level: Arc<CoarseLevel>,
    factor: Arc<Factor>,
    deformer: Box<Deformer>,
    /// The levels the coarse problem's own solve uses.
    levels_below: Levels,
    /// Constrained vertices of the fine and of the coarse mesh.
    fine_fixed: Vec<bool>,
    coarse_fixed: Vec<bool>,
    /// A coarse start solved ahead, beside the fine factorisation
    /// ([`Deformer::build_factor`]), for the next sequence from rest.
    solved_start: Option<SolvedStart>,
    /// A correction's coarse solve reached [`CORRECTION_MAX_ITERS`]
    /// without converging: the coarse problem has a slow mode of its own,
    /// and later corrections stop their coarse solves once they gain
    /// little ([`CORRECTION_STALL`]).
    ///
    /// [`CORRECTION_MAX_ITERS`]: multilevel::CORRECTION_MAX_ITERS
    /// [`CORRECTION_STALL`]: multilevel::CORRECTION_STALL
    slow: bool,
}

/// The coarse start of one set of targets, solved ahead.
struct SolvedStart {
    /// The handles' targets it was solved for.
    targets: Vec<RigidTransform>,
    /// The coarse rotations it reached.
    rotations: Vec<UnitQuaternion<Real>>,
    run: CoarseRun,
}

/// The coarse problem of the fine factor with id `.0 .0` at the coarse
/// ratio `.0 .1`, `None` when the set does not survive restriction or the
/// coarse factorisation failed.
type CoarseSlot = ((u64, usize), Option<Box<CoarseProblem>>);

/// The preview state of a deformer.
struct Preview {
    /// The fine factor id and the level's ratio the problem was built for.
    key: (u64, usize),
    problem: Option<Box<CoarseProblem>>,
    /// Whether the coarse pose follows the current gesture (else the next
    /// preview injects the fine pose first).
    following: bool,
    /// Whether `pose` is newer than the fine pose: the next
    /// [`Deformer::step`] starts from it.
    pending: bool,
    /// The prolongated pose (mesh units, `#V`).
    pose: Vec<Point>,
    /// `pose` in the mesh's vertex order when the solver renumbered it
    /// (`Rest::vertex_order`; empty otherwise).
    pose_user: Vec<Point>,
    /// The blended rigid motions `(M_i, t_i)` and their next pass.
    blend: Vec<Motion>,
    next: Vec<Motion>,
}

/// An affine motion `x ↦ M x + t` (a blend of rigid ones).
type Motion = (Matrix3<Real>, Vector3<Real>);

impl Deformer {
    /// A deformer at the rest pose.
    pub fn new(rest: Arc<Rest>, params: Params) -> Self {
        let y = rest.ops.positions.clone();
        let pose = rest.mesh.positions().to_vec();
        let pose_user = match rest.vertex_order() {
            Some(_) => rest.mesh().positions().to_vec(),
            None => Vec::new(),
        };
        Deformer {
            rest,
            params,
            y,
            pose,
            pose_user,
            scratch: Scratch::default(),
            elastic: State::default(),
            levels: Levels::default(),
            coarse: None,
            start_coarse: None,
            corrections_held: false,
            coarse_start_held: false,
            drift_limit: None,
            newton: false,
            newton_level: false,
            warm_levels: true,
            preview: None,
            interrupt: None,
            galerkin_mode: None,
            galerkin: None,
            detail_fit: detail_fit::DetailFit::default(),
        }
    }

    /// Makes the elastic iteration's coarse corrections Galerkin ones
    /// ([`Galerkin`]), or the coarse problems' of the hierarchy again
    /// (`None`, the default: `multilevel.rs`). The coarse start from the
    /// rest pose is the hierarchy's either way. Values below 1 (but
    /// `smooth`) are taken as 1.
    ///
    /// Not the default: replaying a gesture without the server
    /// (`drag_sim --path arc`, corrections running during the drags) they
    /// settle in fewer fine-iteration equivalents than the coarse
    /// problems' on every character, but a session holds its corrections
    /// while a person drags, and from the pose a held drag leaves its
    /// settle took as many iterations with them on camel_9770 (23) and
    /// more time on camel_9770 and feline_50k (`dend loadtest --path
    /// arc`; docs/performance.md).
    pub fn set_galerkin(&mut self, galerkin: Option<Galerkin>) {
        self.galerkin_mode = galerkin.map(|g| Galerkin {
            depth: g.depth.max(1),
            lag: g.lag.max(1),
            period: g.period.max(1),
            smooth: g.smooth,
        });
        self.galerkin = None;
    }

    /// The Galerkin corrections' setting ([`Deformer::set_galerkin`]),
    /// `None` for the coarse problems'.
    pub fn galerkin(&self) -> Option<Galerkin> {
        self.galerkin_mode
    }

    /// Chooses the levels of the elastic iteration ([`Levels`]; default a
    /// hierarchy where the mesh has coarse levels).
    pub fn set_levels(&mut self, levels: Levels) {
        self.levels = levels;
    }

    /// Corrects the sequences that do not start from the rest pose (a
    /// drag's, the settle after a gesture) on the fine mesh's *Newton
    /// level* (`true`), or on the hierarchy as every other sequence
    /// (`false`, the default). The Newton level is a coarse level of an
    /// eighth of the vertices (at the default coarse ratio) with no levels
    /// below it, whose correction is one Newton step
    /// (`solver/newton.rs`), on meshes where that level has at most
    /// [`NEWTON_LEVEL_MAX_VERTICES`](multilevel::NEWTON_LEVEL_MAX_VERTICES)
    /// vertices; a sequence from the rest pose keeps the hierarchy's start
    /// and corrections (`Deformer::start_level`).
    ///
    /// Not the default: replaying the arc gesture (`drag_sim --path arc
    /// --newton-level on`) it shortens the characters' settles (camel_9770
    /// 170 → 132 ms, armadillo_43k 2.47 → 1.83 s, in the same run) but
    /// doubles the survey's bumpy plane's (587 → 1,267 ms: its 5,050-vertex
    /// Newton level, simplified eight times, stands for the fine bumps less
    /// well than the hierarchy's 10,100-vertex level); through the server
    /// the camel's settle after a person's 30 Hz gesture falls (201 → 138
    /// ms) but after a closed-loop gesture rises (221 → 279 ms);
    /// docs/performance.md.
    pub fn set_newton_level(&mut self, on: bool) {
        self.newton_level = on;
    }

    /// Holds the coarse corrections of the elastic iteration (`true`) or
    /// lets them run (`false`, the default). A session holds them while a
    /// person drags: a correction costs several fine iterations, and a
    /// drag arriving behind it waited (camel at 60 drags/s: drag→frame p99
    /// 17–97 ms with corrections, 17–19 ms without), while the settle
    /// after the gesture needs them to converge.
    ///
    /// The first step after a hold, when it continues the held sequence
    /// (the same targets: a settle, a refinement), corrects after its first
    /// iteration, which applies the last drag's targets. Each drag starts a
    /// sequence of its own whose count of iterations towards a correction
    /// starts again, so a settle otherwise spent its first four iterations,
    /// which move the far parts little, before its first correction
    /// (`drag_sim --path arc`: settle iterations camel_9770 35 → 32,
    /// feline_50k 32 → 29, armadillo_43k 40 → 38; through the server at 30
    /// drags/s camel_9770 110–116 → 88–99 ms, eight camels 1.18 → 0.75–0.91
    /// s, and in closed loop 1.11–1.18 → 1.15–1.24 s; docs/performance.md).
    pub fn hold_corrections(&mut self, hold: bool) {
        if self.corrections_held && !hold {
            if let Some(e) = self.params.elastic() {
                let period = self.correction_period(e.correction_period);
                let st = &mut self.elastic;
                st.since_correction = st.since_correction.max(period.saturating_sub(1));
            }
        }
        self.corrections_held = hold;
    }

    /// Holds the coarse start of a sequence from the rest pose (`true`):
    /// such a step then starts from the handles' rotations spread by
    /// harmonic weights, as with [`Levels::One`], and the coarse level
    /// does its work in the corrections after. A session holds it for a
    /// drag's step while other sessions' solves wait for the solver: eight
    /// camel sessions starting together spent their first drags in each
    /// other's coarse starts (drag→frame median of the first drags 218 ms,
    /// p99 over the gesture 203 ms; held while contended: 68 and 78–92
    /// ms). Alone, a drag
    /// keeps it: the start puts the slow modes right, and without it the
    /// camel's settle after a 150-drag gesture took 31 iterations instead
    /// of 24.
    pub fn hold_coarse_start(&mut self, hold: bool) {
        self.coarse_start_held = hold;
    }

    /// Lets `flag` stop the next steps early (`None`: they run their
    /// budget). An elastic step checks it between iterations and, inside
    /// one, before anything of the state changes (after the right-hand
    /// side and after the solve), so a stopped step leaves a pose and
    /// rotations it could have ended with; a coarse correction's solve
    /// stops too, and the correction is then not applied. The report says
    /// `interrupted`. A session raises it when a drag arrives during a
    /// refinement: the drag then waits for at most a part of an iteration
    /// instead of a whole one (and not for a correction's coarse solve).
    pub fn set_interrupt(&mut self, flag: Option<Arc<AtomicBool>>) {
        self.interrupt = flag;
    }

    /// Whether the interrupt flag is raised.
    fn interrupted(&self) -> bool {
        self.interrupt
            .as_ref()
            .is_some_and(|f| f.load(Ordering::Relaxed))
    }

    /// The rest state.
    pub fn rest(&self) -> &Arc<Rest> {
        &self.rest
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Replaces the parameters (the caller must use a matching factor).
    pub fn set_params(&mut self, params: Params) -> Result<(), DeformError> {
        params.validate()?;
        self.params = params;
        self.scratch.evaluated = None;
        self.elastic.invalidate();
        self.scratch.mem = None; // re-size the scratch (Anderson window) on the next step
                                 // (the Galerkin aggregates follow the coarse ratio)
        self.galerkin = None;
        Ok(())
    }

    /// The current pose, mesh units, `#V×3` (in the mesh's vertex order).
    pub fn pose(&self) -> &[Point] {
        match self.rest.vertex_order() {
            Some(_) => &self.pose_user,
            None => &self.pose,
        }
    }

    /// Sets the current pose (undo/redo, restore); rejects wrong lengths and
    /// non-finite values.
    pub fn set_pose(&mut self, pose: Vec<Point>) -> Result<(), DeformError> {
        if pose.len() != self.pose.len() {
            return Err(DeformError::PoseLength {
                expected: self.pose.len(),
                got: pose.len(),
            });
        }
        if pose.iter().flatten().any(|v| !v.is_finite()) {
            return Err(DeformError::NonFinite { what: "pose" });
        }
        let pose = match self.rest.vertex_order() {
            Some(order) => {
                let mut internal = Vec::new();
                order.to_internal(&pose, &mut internal);
                self.pose_user = pose;
                internal
            }
            None => pose,
        };
        self.y = pose.iter().map(|&p| self.rest.ops.normalise(p)).collect();
        self.pose = pose;
        self.drop_preview();
        self.scratch.evaluated = None;
        self.elastic.invalidate();
        Ok(())
    }

    /// Back to the rest pose.
    pub fn reset(&mut self) {
        self.drop_preview();
        self.scratch.evaluated = None;
        self.elastic.reset();
        if let Some(g) = self.galerkin.as_mut() {
            // (assembled again at the first correction, as a new deformer's)
            g.age = None;
        }
        self.y = self.rest.ops.positions.clone();
        self.pose = self.rest.mesh.positions().to_vec();
        if self.rest.vertex_order().is_some() {
            self.pose_user = self.rest.mesh().positions().to_vec();
        }
    }

    /// Runs up to `max_iters` iterations towards the handle targets of
    /// `constraints`, warm-started from the current pose (design.md §9), with
    /// the formulation `factor` was built for: the elastic one
    /// (`local_global.rs`: exact local and global steps, the objective never
    /// grows) or the paper's (`least_squares.rs`: STEP 2 and one solve per
    /// iteration, safeguarded).
    ///
    /// `factor` must have been built for `constraints`' constrained set and
    /// this deformer's rest mesh and parameters.
    pub fn step(
        &mut self,
        factor: &Factor,
        constraints: &Constraints,
        max_iters: usize,
    ) -> Result<StepReport, DeformError> {
        if factor.elastic.is_none() {
            self.drop_preview();
        }
        let rest = self.rest.clone();
        let constraints = &*rest.internal_constraints(constraints);
        match &factor.elastic {
            Some((el, set)) => self.step_elastic(factor, (el, set), constraints, max_iters),
            None => self.step_least_squares(factor, constraints, max_iters),
        }
    }

    /// Checks that `factor` was built for `constraints` (and this rest
    /// mesh and these parameters), loads the normalised targets into
    /// `scratch.targets` and, with hard constraints, moves the constrained
    /// vertices onto them. Returns whether the objective changed (a target
    /// moved; always with soft constraints).
    fn load_targets(
        &mut self,
        factor: &Factor,
        constraints: &Constraints,
    ) -> Result<bool, DeformError> {
        self.check_factor(factor, constraints)?;
        let ops = &self.rest.ops;
        let s = &mut self.scratch;
        s.targets.clear();
        s.targets_given.clear();
        for (&v, &p) in constraints.fixed.iter().zip(&constraints.fixed_at) {
            if p.iter().any(|c| !c.is_finite()) {
                return Err(DeformError::NonFinite {
                    what: "fixed position",
                });
            }
            s.targets.push((v, ops.normalise(p)));
            s.targets_given.push(p);
        }
        for h in &constraints.handles {
            for (v, p) in h.target_positions() {
                if p.iter().any(|c| !c.is_finite()) {
                    return Err(DeformError::NonFinite {
                        what: "handle target",
                    });
                }
                s.targets.push((v, ops.normalise(p)));
                s.targets_given.push(p);
            }
        }
        let hard = factor.sys.lambda1 == 0.0;
        let mut moved = !hard; // soft constraints: the objective depends on the targets
        if hard {
            for &(v, p) in &s.targets {
                let y = &mut self.y[v as usize];
                moved |= *y != p;
                *y = p;
            }
        }
        Ok(moved)
    }

    /// Checks that `factor` was built for `constraints`' constrained set,
    /// this rest mesh and these parameters.
    fn check_factor(&self, factor: &Factor, constraints: &Constraints) -> Result<(), DeformError> {
        if factor.sys.constrained != constraints.constrained()
            || factor.key() != &FactorKey::of_internal(&self.rest, &self.params, constraints)
        {
            return Err(DeformError::FactorMismatch);
        }
        Ok(())
    }

    /// The mesh-unit pose from `Y`. Hard-constrained vertices get their
    /// targets as given (kept by `load_targets`), not through the
    /// normalisation's round trip (`denormalise(normalise(p))` can differ
    /// from `p` in the last bit): a fixed vertex keeps its stored bits, so
    /// an asset export leaves what did not move byte for byte.
    fn sync_pose(&mut self, factor: &Factor) {
        let ops = &self.rest.ops;
        for (p, &y) in self.pose.iter_mut().zip(&self.y) {
            *p = ops.denormalise(y);
        }
        if factor.sys.lambda1 == 0.0 {
            let s = &self.scratch;
            for (&(v, _), &p) in s.targets.iter().zip(&s.targets_given) {
                self.pose[v as usize] = p;
            }
        }
        if let Some(order) = self.rest.vertex_order() {
            order.to_user(&self.pose, &mut self.pose_user);
        }
    }
}
