//! The session actor's state, in parts: its [`Phase`], the installed
//! constraint set, the shown pose, the solve (`actor_solve.rs`), the
//! history (`actor_history.rs`), the named poses (`actor_poses.rs`) and
//! what waits for the session (`actor_queue.rs`).

use std::collections::VecDeque;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use tokio::sync::{mpsc, watch};

use super::phase::Phase;
use crate::session::shared::{Cmd, Inner, Internal, QueuedDrag, Reply, SessionOptions};
use crate::session::types::{Frame, PoseSnapshot};
use crate::store::{JournalEntry, NamedPose};
use dend::deform::{
    Constraints, ConstraintsSpec, Deformer, Factor, LevelPlan, PreparedLevels, RigidTransform,
};

/// Most history entries kept per session (older ones are dropped).
pub(super) const HISTORY_LIMIT: usize = 64;

/// A session's actor: owns the deformer, composes drags, runs one solve
/// at a time, publishes frames and keeps the history.
pub(in crate::session) struct Actor {
    pub(super) inner: Arc<Inner>,
    pub(super) opts: SessionOptions,
    pub(super) frames_tx: watch::Sender<Option<Frame>>,
    pub(super) internal_tx: mpsc::UnboundedSender<Internal>,
    pub(super) internal_rx: Option<mpsc::UnboundedReceiver<Internal>>,
    /// Where the constraint set is, whether a revival is on its way, and
    /// whether the lease is lost (`actor_phase.rs`).
    pub(super) phase: Phase,
    pub(super) set: SetState,
    pub(super) shown: Shown,
    pub(super) solve: Solve,
    pub(super) history: History,
    pub(super) poses: Poses,
    pub(super) flow: Flow,
}

/// One history entry: a settled pose, its handle targets and the
/// constraint set they belong to (undo and redo span constraint edits).
pub(super) struct Snapshot {
    pub(super) pose: Arc<Vec<[f64; 3]>>,
    pub(super) targets: Vec<RigidTransform>,
    pub(super) set: Arc<InstalledSet>,
}

/// A constraint set as the session installed it.
pub(super) struct InstalledSet {
    /// Installation number (equal numbers: the same set).
    pub(super) id: u64,
    /// The spec as the client sent it (anchors, if any, its own).
    pub(super) client: ConstraintsSpec,
    /// The spec as stored: anchored at the pose it was installed on
    /// (`ConstraintsSpec::anchored`), so a revival resolves the same set.
    pub(super) stored: serde_json::Value,
    /// The resolved set with the targets it was installed with.
    pub(super) constraints: Constraints,
}

/// The installed constraint set, its factor and its handles' targets.
#[derive(Default)]
pub(super) struct SetState {
    /// The installed set (None before the first).
    pub(super) current: Option<Arc<InstalledSet>>,
    /// Sets installed so far (the next one's id follows).
    pub(super) installed: u64,
    /// Counts the factor lookups started: a build result of an older one
    /// is not the installed set's.
    pub(super) generation: u64,
    /// The factor of the installed set once built (`None` while it
    /// builds): every solve of the set uses it, no cache lookup per solve.
    pub(super) factor: Option<Arc<Factor>>,
    /// The set's coarse levels, built beside its factor, until the next
    /// solve hands them to the deformer (`Deformer::install_levels`).
    pub(super) prepared: Option<PreparedLevels>,
    /// The set with the targets of every drag applied.
    pub(super) constraints: Option<Arc<Constraints>>,
    /// `constraints` with the targets of the journaled drags only (what a
    /// revival would rebuild): restored when a journal append fails.
    pub(super) confirmed: Option<Arc<Constraints>>,
}

/// The pose the session shows and its frame header's fields.
pub(super) struct Shown {
    pub(super) pose: Arc<Vec<[f64; 3]>>,
    pub(super) revision: u64,
    /// The highest drag `seq` applied to the targets.
    pub(super) last_seq: u64,
    /// The highest drag `seq` the pose acknowledges (journaled and solved).
    pub(super) applied_seq: u64,
    /// The level the current frame shows (`LEVEL_FULL` or, for a coarse
    /// preview, `LEVEL_COARSE`).
    pub(super) level: u8,
    /// Nothing more to iterate (converged, budget spent or failed).
    pub(super) settled: bool,
    pub(super) converged: bool,
    /// The solver's objective at the current pose (NaN before a solve).
    pub(super) objective: f64,
}

/// The solve: the deformer (away while a solve runs on the scheduler),
/// what is left to solve, and the timing the drag stream is read from.
pub(super) struct Solve {
    /// `None` while a solve runs: it holds the deformer.
    pub(super) deformer: Option<Deformer>,
    /// What the deformer's coarse levels are: a new constraint set's are
    /// built from it beside the set's factor (`Deformer::level_plan`).
    pub(super) level_plan: LevelPlan,
    /// Counts the poses set from outside the solver (undo, redo, reset,
    /// restore): a solve started in an older epoch returns a pose that is
    /// no longer the session's.
    pub(super) pose_epoch: u64,
    /// Targets changed since the last solve started.
    pub(super) dirty: bool,
    /// A drag was applied since the last solve started (`dirty` may also
    /// be a new constraint set's solve, which nobody waits for).
    pub(super) drag_pending: bool,
    /// The drags applied since the last solve started, journaled by it.
    pub(super) journal: Vec<JournalEntry>,
    /// The solve that runs took drags (no frame shows them yet).
    pub(super) inflight_drags: bool,
    /// Solves started so far (one runs at a time, and each takes every
    /// drag received before it: `Actor::answer_drags_shown`).
    pub(super) solves_started: u64,
    /// Solves whose result the session has taken in.
    pub(super) solves_done: u64,
    pub(super) iters_since_change: usize,
    /// When the last drag without a waiter (a WebSocket drag) was applied:
    /// the coarse corrections wait until drags pause
    /// ([`crate::session::CORRECTION_QUIET`]).
    pub(super) last_stream_drag: Option<Instant>,
    /// The time between the last two WebSocket drags, when they came
    /// within [`crate::session::CORRECTION_QUIET`] of each other: a
    /// refinement that the next drag would interrupt before its first
    /// iteration is not started (`Actor::next_drag_due`).
    pub(super) drag_gap: Option<Duration>,
    /// The last fine solve's time per iteration, ms, coarse corrections
    /// left out (NaN before one): coarse previews answer drags while it
    /// is above `SessionOptions::preview_above_ms`.
    pub(super) fine_iter_ms: f64,
    /// Whether the last frame's coarse preview converged (the next solve
    /// of the gesture without a new drag is then the full mesh's).
    pub(super) preview_converged: bool,
    /// When the next solve is due although nothing changes: the end of
    /// the quiet time of a gesture answered by converged previews.
    pub(super) wake_at: Option<Instant>,
    /// Raised when a drag arrives while a refinement runs (a solve
    /// started without new drags or waiters: between drags, over the
    /// settle, or towards a new constraint set): the solver stops it at
    /// its next safe point ([`Deformer::set_interrupt`]) and the drag is
    /// answered sooner.
    pub(super) interrupt: Arc<AtomicBool>,
    /// Whether the solve in flight is such a refinement.
    pub(super) refining: bool,
    /// When the current run of refinements began (`None` after a solve
    /// that answered a drag or a waiter): the scheduler runs the earliest
    /// run's first (`Scheduler::submit_refinement`).
    pub(super) refining_since: Option<Instant>,
}

/// The undo history.
#[derive(Default)]
pub(super) struct History {
    pub(super) entries: Vec<Snapshot>,
    /// The entry the pose is (or, when `uncommitted`, was last) at.
    pub(super) cursor: usize,
    /// The pose moved since the entry at `cursor`.
    pub(super) uncommitted: bool,
}

/// The named poses.
#[derive(Default)]
pub(super) struct Poses {
    /// The list (None until read from the store, see `actor_poses.rs`).
    pub(super) named: Option<Vec<NamedPose>>,
}

/// What waits: commands, drags and reads held until the session can
/// answer them, and the callers a solve answers.
#[derive(Default)]
pub(super) struct Flow {
    /// The commands that change the pose or the targets and wait (for a
    /// running solve, the solve of earlier drags, the settle), in order,
    /// with the ones that arrived behind them (`Actor::must_wait`).
    pub(super) deferred: VecDeque<Cmd>,
    /// Drags that reached the session while its factor was being built
    /// (a new constraint set, a revival): applied, in order, once it is
    /// ready; refused after `SessionOptions::build_wait`.
    pub(super) queued: VecDeque<QueuedDrag>,
    /// Pose reads waiting for the end of a revival.
    pub(super) pose_waiters: Vec<Reply<PoseSnapshot>>,
    /// HTTP drags waiting for the next solve (each with its iteration
    /// budget).
    pub(super) waiters: Vec<(usize, Reply<PoseSnapshot>)>,
    /// The HTTP drags the solve in flight answers.
    pub(super) inflight: Vec<Reply<PoseSnapshot>>,
    /// Questions whether the drags received before them are in a frame
    /// (`Cmd::DragsShown`), with the solves started when each came.
    pub(super) shown_waiters: Vec<(u64, tokio::sync::oneshot::Sender<()>)>,
}

impl Actor {
    pub(in crate::session) fn new(
        inner: Arc<Inner>,
        frames_tx: watch::Sender<Option<Frame>>,
        opts: SessionOptions,
    ) -> Self {
        let (internal_tx, internal_rx) = mpsc::unbounded_channel();
        let deformer = Deformer::new(inner.rest.clone(), inner.params);
        let pose = Arc::new(deformer.pose().to_vec());
        Actor {
            inner,
            opts,
            frames_tx,
            internal_tx,
            internal_rx: Some(internal_rx),
            phase: Phase::Empty,
            set: SetState::default(),
            shown: Shown {
                pose,
                revision: 0,
                last_seq: 0,
                applied_seq: 0,
                level: dend_protocol::LEVEL_FULL,
                settled: true,
                converged: true,
                objective: f64::NAN,
            },
            solve: Solve {
                level_plan: deformer.level_plan(),
                deformer: Some(deformer),
                pose_epoch: 0,
                dirty: false,
                drag_pending: false,
                journal: vec![],
                inflight_drags: false,
                solves_started: 0,
                solves_done: 0,
                iters_since_change: 0,
                last_stream_drag: None,
                drag_gap: None,
                fine_iter_ms: f64::NAN,
                preview_converged: true,
                wake_at: None,
                interrupt: Arc::default(),
                refining: false,
                refining_since: None,
            },
            history: History::default(),
            poses: Poses::default(),
            flow: Flow::default(),
        }
    }
}
