//! The state a session's actor and its handles share: the options a
//! session runs with, the `Inner` both hold, and the grab table, whose
//! changes all go through [`Grabs`].

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, AtomicUsize};
use std::sync::Arc;
use std::time::Instant;

use parking_lot::Mutex;
use tokio::sync::{broadcast, mpsc, watch};

use tokio::sync::oneshot;

use super::error::SessionError;
use super::types::{Delta, Event, Frame, Observer, PoseSnapshot};
use crate::store::{NamedPose, Store};
use dend::deform::{BuildStage, Constraints, ConstraintsSpec, Deformer, StepReport};
use dend_protocol::ws::{ClientId, PoseInfo, SessionState};

use dend::deform::{FactorCache, Params, Rest};
use dend_protocol::FrameBody;

/// What a session needs besides its rest mesh and parameters.
#[derive(Clone)]
pub struct SessionOptions {
    /// The shared factor cache.
    pub cache: Arc<FactorCache>,
    /// Where drags are journaled and checkpoints kept.
    pub store: Arc<dyn Store>,
    /// Solver statistics sink.
    pub observer: Arc<dyn Observer>,
    /// DEND iterations per frame while settling.
    pub iters_per_frame: usize,
    /// Coarse previews answer drags while a fine iteration takes longer
    /// than this, ms (`Config::preview_above_ms`; negative: never).
    pub preview_above_ms: f64,
    /// The session's lease revision, carried by every store write
    /// ([`NO_FENCE`](crate::store::NO_FENCE) without leases).
    pub fence: crate::store::Fence,
    /// How long a drag that reaches the session while its factor is
    /// being built (a constraint edit, a revival) waits for it; past this
    /// it is refused with `not_ready`.
    pub build_wait: std::time::Duration,
    /// Where the session's solves run (fairly between sessions).
    pub scheduler: Arc<crate::scheduler::Scheduler>,
}

/// A drag waiting for the factor build (see `SessionOptions::build_wait`).
pub(super) struct QueuedDrag {
    pub handle: usize,
    pub delta: Delta,
    pub seq: u64,
    pub reply: Option<(usize, Reply<PoseSnapshot>)>,
    /// When it arrived.
    pub at: Instant,
}

/// State shared between the actor and the handles.
pub(super) struct Shared {
    pub state: SessionState,
    pub revision: u64,
    pub handles: Vec<String>,
    pub grabs: Grabs,
    pub can_undo: bool,
    pub can_redo: bool,
    /// The installed constraint set as its client sent it (as the
    /// protocol writes it), and its revision (0: none yet).
    pub constraints: Option<Arc<dend_protocol::ConstraintsSpec>>,
    pub constraints_revision: u64,
    /// The installed set's warnings (`Constraints::warnings`), each with
    /// its `code`, details and a `message`.
    pub warnings: Arc<Vec<dend_protocol::ConstraintWarning>>,
    /// The factor build's stage under way (`SessionInfo::build_stage`).
    pub build_stage: Option<BuildStage>,
    /// The named poses, listed (`SessionInfo::poses`).
    pub poses: Arc<Vec<PoseInfo>>,
}

pub(super) struct Inner {
    pub id: String,
    pub mesh_id: String,
    pub token_sha256: [u8; 32],
    pub params: Params,
    pub rest: Arc<Rest>,
    pub cmd_tx: mpsc::Sender<Cmd>,
    pub frames: watch::Receiver<Option<Frame>>,
    pub events: broadcast::Sender<Event>,
    pub shared: Mutex<Shared>,
    /// Its clients and when it was last used.
    pub presence: Presence,
    /// Its lease and whether another instance owns it now.
    pub ownership: Ownership,
}

/// A session's clients and when it was last used (an idle session with
/// no client is closed).
pub(super) struct Presence {
    pub started: Instant,
    /// Milliseconds from `started` to the last use.
    pub last_active_ms: AtomicU64,
    /// Clients connected now.
    pub clients: AtomicUsize,
    /// The next client's id.
    pub next_client: AtomicU64,
}

/// A session's lease, and whether it is another instance's now.
pub(super) struct Ownership {
    /// The lease revision this session runs under.
    pub fence: crate::store::Fence,
    /// Set when a store write was fenced: another instance owns the session.
    pub fenced: std::sync::atomic::AtomicBool,
    /// Set when the session is handed over to another instance (a drain,
    /// a hand-over request): its clients are told to reconnect at once.
    pub moving: std::sync::atomic::AtomicBool,
}

/// Which client holds which handle (by index): one holder per handle.
#[derive(Debug, Default)]
pub(super) struct Grabs(HashMap<usize, ClientId>);

impl Grabs {
    /// Whether no handle is held (no gesture is open).
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The client holding `handle`, if any.
    pub fn holder(&self, handle: usize) -> Option<ClientId> {
        self.0.get(&handle).copied()
    }

    /// Gives `handle` to `client` unless another client holds it (then
    /// `Err(holder)`); `Ok(true)` when it was newly grabbed.
    pub fn grab(&mut self, handle: usize, client: ClientId) -> Result<bool, ClientId> {
        match self.0.get(&handle) {
            Some(&c) if c != client => Err(c),
            Some(_) => Ok(false),
            None => {
                let _ = self.0.insert(handle, client);
                Ok(true)
            }
        }
    }

    /// Releases `handle` if `client` holds it; whether it did.
    pub fn release(&mut self, handle: usize, client: ClientId) -> bool {
        if self.0.get(&handle) == Some(&client) {
            let _ = self.0.remove(&handle);
            true
        } else {
            false
        }
    }

    /// Releases every handle `client` holds; the handles released.
    pub fn release_client(&mut self, client: ClientId) -> Vec<usize> {
        let mine: Vec<usize> = self
            .0
            .iter()
            .filter(|(_, c)| **c == client)
            .map(|(h, _)| *h)
            .collect();
        for h in &mine {
            let _ = self.0.remove(h);
        }
        mine
    }

    /// Releases every handle (the handle list changed); what was held.
    pub fn clear(&mut self) -> Vec<(usize, ClientId)> {
        self.0.drain().collect()
    }
}

/// A reply channel of a command.
pub(super) type Reply<T> = oneshot::Sender<Result<T, SessionError>>;

/// What a handle asks the actor to do.
pub(super) enum Cmd {
    Drag {
        handle: usize,
        delta: Delta,
        seq: u64,
        reply: Option<(usize, Reply<PoseSnapshot>)>,
    },
    /// A client's new constraint set, parsed by the handle; the actor
    /// resolves it once, at its current pose.
    SetConstraints {
        spec: ConstraintsSpec,
        /// The constraints revision the edit is based on (None: any).
        if_revision: Option<u64>,
        reply: Reply<SessionState>,
    },
    /// A stored constraint set re-opened, resolved by the handle.
    Restore {
        restore: Restore,
        reply: Reply<SessionState>,
    },
    Undo(Reply<PoseSnapshot>),
    Redo(Reply<PoseSnapshot>),
    Reset(Reply<PoseSnapshot>),
    Pose(Reply<PoseSnapshot>),
    /// Answered once the drags received before it are in a frame
    /// ([`SessionHandle::drags_shown`](super::SessionHandle::drags_shown)).
    DragsShown(oneshot::Sender<()>),
    /// A grab ended: the gesture's settled pose may become a history entry.
    GestureEnded,
    /// A named-pose command (`poses.rs`).
    Poses(PoseCmd),
    Close,
}

/// Re-opening a stored session: its stored constraint set, parsed and
/// resolved once (by the handle) with the recovered targets; the store is
/// left as is (its checkpoint + journal stay valid until the first commit
/// writes a new checkpoint).
pub(super) struct Restore {
    /// The spec as stored (already anchored).
    pub stored: serde_json::Value,
    /// `stored`, parsed.
    pub spec: ConstraintsSpec,
    /// `spec` resolved on the rest mesh, with the recovered targets.
    pub constraints: Constraints,
    /// Warm start (the last checkpoint's pose).
    pub pose: Option<Vec<[f64; 3]>>,
    /// Highest sequence number included in the targets.
    pub ack_seq: u64,
}

/// Runs a blocking store call from the actor's task without holding an
/// async worker: on a multi-threaded runtime (the server's) the worker
/// hands its other tasks to a new worker while `f` blocks
/// (`block_in_place`), so a slow store delays this session only, and the
/// call stays ordered with the actor's other work. On a current-thread
/// runtime (some tests) it simply runs.
pub(super) fn off_worker<T>(f: impl FnOnce() -> T) -> T {
    match tokio::runtime::Handle::try_current().map(|h| h.runtime_flavor()) {
        Ok(tokio::runtime::RuntimeFlavor::MultiThread) => tokio::task::block_in_place(f),
        _ => f(),
    }
}

/// What the solver and factor-build tasks send back to the actor.
// One message per solve, moved once: boxing the deformer would buy nothing.
#[allow(clippy::large_enum_variant)]
pub(super) enum Internal {
    Solved {
        deformer: Deformer,
        result: Result<StepReport, SessionError>,
        /// Whether the frame shows a coarse preview (`Deformer::preview`).
        preview: bool,
        body: FrameBody,
        seconds: f64,
        applied_seq: u64,
        /// Whether the journal append failed (nothing solved, nothing
        /// acknowledged).
        journal_failed: bool,
        /// The constraints the solve used (targets with its drags).
        constraints: Arc<Constraints>,
        /// The constraint generation it was started in.
        generation: u64,
        /// The pose epoch it was started in (a restore during the solve
        /// starts a new one, and the solve's pose is then dropped).
        pose_epoch: u64,
    },
    /// A stage of the factor build of constraint generation `generation`
    /// started.
    Stage { generation: u64, stage: BuildStage },
    Built {
        generation: u64,
        /// The set's factor, kept by the actor for every solve of the set.
        result: Result<Arc<dend::deform::Factor>, SessionError>,
        /// Wall time of the factor's lookup or build.
        seconds: f64,
    },
    /// The coarse levels of constraint generation `generation`, built
    /// beside its factor in `seconds`.
    LevelsBuilt {
        generation: u64,
        levels: dend::deform::PreparedLevels,
        seconds: f64,
    },
}

/// What a handle asks the actor to do with named poses.
pub(super) enum PoseCmd {
    /// Save the settled pose as `name` (replacing one of that name).
    Save {
        name: String,
        /// Whether a pose of the same name may be replaced (else
        /// `PoseExists`).
        replace: bool,
        reply: Reply<PoseInfo>,
    },
    /// The named poses, with their positions.
    List(Reply<Arc<Vec<NamedPose>>>),
    Rename {
        from: String,
        to: String,
        reply: Reply<()>,
    },
    Delete {
        name: String,
        reply: Reply<()>,
    },
    /// Make the named pose the current one (an undo step).
    Restore {
        name: String,
        reply: Reply<PoseSnapshot>,
    },
}

impl PoseCmd {
    /// Whether the command reads or replaces the pose, so it waits until
    /// the session has settled (no solve running or to come, no factor
    /// being built).
    pub(super) fn waits_for_settle(&self) -> bool {
        matches!(self, PoseCmd::Save { .. } | PoseCmd::Restore { .. })
    }
}
