//! The session actor: owns the deformer, composes drags, runs one solve at a
//! time on the blocking pool, publishes frames and keeps the history.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use tokio::sync::{mpsc, watch};

use super::shared::QueuedDrag;

use super::shared::{off_worker, Cmd, Inner, Internal, Reply, Restore, SessionOptions};
use super::{
    Delta, Event, Frame, FrameHeader, PeerEvent, PoseSnapshot, SessionError, SessionState,
};
use crate::store::JournalEntry;
use dend::deform::{Constraints, ConstraintsSpec, Deformer, RigidTransform};

/// Most history entries kept per session (older ones are dropped).
const HISTORY_LIMIT: usize = 64;

/// One history entry: a settled pose, its handle targets and the
/// constraint set they belong to (undo and redo span constraint edits).
struct Snapshot {
    pose: Arc<Vec<[f64; 3]>>,
    targets: Vec<RigidTransform>,
    set: Arc<InstalledSet>,
}

/// A constraint set as the session installed it.
struct InstalledSet {
    /// Installation number (equal numbers: the same set).
    id: u64,
    /// The spec as the client sent it (anchors, if any, its own).
    client: ConstraintsSpec,
    /// The spec as stored: anchored at the pose it was installed on
    /// (`ConstraintsSpec::anchored`), so a revival resolves the same set.
    stored: serde_json::Value,
    /// The resolved set with the targets it was installed with.
    constraints: Constraints,
}

/// What the session does once a constraint set's factor is ready.
#[derive(Clone, Copy, PartialEq, Eq)]
enum AfterBuild {
    /// Solve towards the set's targets; the settled pose becomes a history
    /// entry (a new set, a revival).
    Solve,
    /// Keep the pose as it is (undo, redo and reset to another set).
    Keep,
}

pub(super) struct Actor {
    inner: Arc<Inner>,
    opts: SessionOptions,
    frames_tx: watch::Sender<Option<Frame>>,
    internal_tx: mpsc::UnboundedSender<Internal>,
    internal_rx: Option<mpsc::UnboundedReceiver<Internal>>,
    deformer: Option<Deformer>,
    constraints: Option<Arc<Constraints>>,
    /// `constraints` with the targets of the journaled drags only (what a
    /// revival would rebuild): restored when a journal append fails.
    confirmed: Option<Arc<Constraints>>,
    /// The installed constraint set (None before the first).
    set: Option<Arc<InstalledSet>>,
    sets_installed: u64,
    after_build: AfterBuild,
    state: SessionState,
    generation: u64,
    /// The factor of the installed set once built (`None` while it
    /// builds): every solve of the set uses it, no cache lookup per solve.
    factor: Option<Arc<dend::deform::Factor>>,
    /// Counts the poses set from outside the solver (undo, redo, reset,
    /// restore): a solve started in an older epoch returns a pose that is
    /// no longer the session's.
    pose_epoch: u64,
    /// Targets changed since the last solve started.
    dirty: bool,
    /// A drag was applied since the last solve started (`dirty` may also
    /// be a new constraint set's solve, which nobody waits for).
    drag_pending: bool,
    /// When the last drag without a waiter (a WebSocket drag) was applied:
    /// the coarse corrections wait until drags pause
    /// ([`crate::session::CORRECTION_QUIET`]).
    last_stream_drag: Option<std::time::Instant>,
    /// The time between the last two WebSocket drags, when they came
    /// within [`crate::session::CORRECTION_QUIET`] of each other: a
    /// refinement that the next drag would interrupt before its first
    /// iteration is not started (`Actor::next_drag_due`).
    drag_gap: Option<std::time::Duration>,
    /// The last fine solve's time per iteration, ms, coarse corrections
    /// left out (NaN before one): coarse previews answer drags while it
    /// is above `SessionOptions::preview_above_ms`.
    fine_iter_ms: f64,
    /// Whether the last frame's coarse preview converged (the next solve
    /// of the gesture without a new drag is then the full mesh's).
    preview_converged: bool,
    /// When the next solve is due although nothing changes: the end of
    /// the quiet time of a gesture answered by converged previews.
    wake_at: Option<std::time::Instant>,
    /// The level the current frame shows (`LEVEL_FULL` or, for a coarse
    /// preview, `LEVEL_COARSE`).
    level: u8,
    /// Nothing more to iterate (converged, budget spent or failed).
    settled: bool,
    iters_since_change: usize,
    last_seq: u64,
    applied_seq: u64,
    revision: u64,
    converged: bool,
    /// The solver's objective at the current pose (NaN before a solve).
    objective: f64,
    journal: Vec<JournalEntry>,
    waiters: Vec<(usize, Reply<PoseSnapshot>)>,
    inflight: Vec<Reply<PoseSnapshot>>,
    deferred: VecDeque<Cmd>,
    /// Drags that reached the session while its factor was being built
    /// (a new constraint set, a revival): applied, in order, once it is
    /// ready; refused after `SessionOptions::build_wait`.
    queued: VecDeque<QueuedDrag>,
    /// Set from a revival until its solve settles: the pose is the
    /// checkpoint's, without the journaled drags, or an iterate on the way
    /// to them, and is not served.
    reviving: bool,
    /// Pose reads waiting for the end of a revival.
    pose_waiters: Vec<Reply<PoseSnapshot>>,
    history: Vec<Snapshot>,
    cursor: usize,
    uncommitted: bool,
    pose: Arc<Vec<[f64; 3]>>,
    /// Set when the lease is lost (a fenced write): the actor ends.
    stop: bool,
    /// The named poses (None until read from the store, see `actor_poses.rs`).
    named: Option<Vec<crate::store::NamedPose>>,
    /// Named-pose commands waiting for the pose to settle.
    settle_queue: VecDeque<super::shared::PoseCmd>,
    /// Raised when a drag arrives while a refinement runs (a solve
    /// started without new drags or waiters: between drags, over the
    /// settle, or towards a new constraint set): the solver stops it at
    /// its next safe point ([`Deformer::set_interrupt`]) and the drag is
    /// answered sooner.
    interrupt: Arc<std::sync::atomic::AtomicBool>,
    /// Whether the solve in flight is such a refinement.
    refining: bool,
}

impl Actor {
    pub(super) fn new(
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
            deformer: Some(deformer),
            constraints: None,
            confirmed: None,
            set: None,
            sets_installed: 0,
            after_build: AfterBuild::Solve,
            state: SessionState::Empty,
            generation: 0,
            factor: None,
            pose_epoch: 0,
            dirty: false,
            last_stream_drag: None,
            drag_gap: None,
            fine_iter_ms: f64::NAN,
            preview_converged: true,
            wake_at: None,
            level: dend_protocol::LEVEL_FULL,
            settled: true,
            iters_since_change: 0,
            last_seq: 0,
            applied_seq: 0,
            revision: 0,
            converged: true,
            objective: f64::NAN,
            journal: vec![],
            waiters: vec![],
            inflight: vec![],
            deferred: VecDeque::new(),
            queued: VecDeque::new(),
            reviving: false,
            pose_waiters: vec![],
            history: vec![],
            cursor: 0,
            uncommitted: false,
            pose,
            stop: false,
            named: None,
            settle_queue: VecDeque::new(),
            interrupt: Arc::default(),
            refining: false,
            drag_pending: false,
        }
    }

    pub(super) async fn run(mut self, mut rx: mpsc::Receiver<Cmd>) {
        let Some(mut internal_rx) = self.internal_rx.take() else {
            return;
        };
        self.load_named_poses();
        loop {
            while self.deformer.is_some() {
                let Some(cmd) = self.deferred.pop_front() else {
                    break;
                };
                if !self.on_cmd(cmd) {
                    return self.closed();
                }
            }
            while self.pose_settled() {
                let Some(cmd) = self.settle_queue.pop_front() else {
                    break;
                };
                self.on_pose_cmd(cmd);
            }
            self.maybe_start_solve();
            // the oldest queued drag's deadline (far away when none is queued)
            let deadline = self.queued.front().map_or_else(
                || tokio::time::Instant::now() + std::time::Duration::from_secs(3600),
                |q| tokio::time::Instant::from_std(q.at + self.opts.build_wait),
            );
            tokio::select! {
                Some(msg) = internal_rx.recv() => self.on_internal(msg),
                () = tokio::time::sleep_until(deadline), if !self.queued.is_empty() => {
                    self.expire_queued();
                }
                () = super::sleep_until_or_never(self.wake_at.map(tokio::time::Instant::from_std)),
                    if self.wake_at.is_some() => {
                    // the loop's `maybe_start_solve` starts the full mesh's solve
                    self.wake_at = None;
                }
                cmd = rx.recv() => match cmd {
                    Some(cmd) => if !self.on_cmd(cmd) { return self.closed() },
                    None => return self.closed(),
                },
            }
            if self.stop {
                return self.closed();
            }
        }
    }

    fn closed(&mut self) {
        let _ = self.inner.events.send(Event::Closed);
    }

    fn snapshot(&self) -> PoseSnapshot {
        self.snapshot_for(&self.header())
    }

    /// The header of a frame of the current pose.
    fn header(&self) -> FrameHeader {
        FrameHeader {
            revision: self.revision,
            ack_seq: self.applied_seq,
            iteration: self.iters_since_change as u32,
            converged: self.converged,
            settled: self.settled,
            objective: self.objective,
            vertex_count: self.pose.len() as u32,
            level: self.level,
        }
    }

    fn sync_shared(&self) {
        let mut s = self.inner.shared.lock();
        s.state = self.state;
        s.revision = self.revision;
        s.can_undo = self.uncommitted && !self.history.is_empty() || self.cursor > 0;
        s.can_redo = !self.uncommitted && self.cursor + 1 < self.history.len();
    }

    /// Handles one command; false when the session must stop.
    fn on_cmd(&mut self, cmd: Cmd) -> bool {
        // these read or replace the pose: they wait for a running solve
        let needs_deformer = matches!(
            cmd,
            Cmd::Undo(_) | Cmd::Redo(_) | Cmd::Reset(_) | Cmd::SetConstraints { .. }
        );
        if needs_deformer && self.deformer.is_none() {
            self.deferred.push_back(cmd);
            return true;
        }
        match cmd {
            Cmd::Drag {
                handle,
                delta,
                seq,
                reply,
            } => self.on_drag(handle, delta, seq, reply),
            Cmd::SetConstraints {
                spec,
                if_revision,
                reply,
            } => {
                let r = self.on_set_constraints(spec, if_revision);
                let _ = reply.send(r);
            }
            Cmd::Restore { restore, reply } => {
                let r = self.on_restore(restore);
                let _ = reply.send(r);
            }
            Cmd::Undo(reply) => {
                let r = self.undo_redo(true);
                let _ = reply.send(r);
            }
            Cmd::Redo(reply) => {
                let r = self.undo_redo(false);
                let _ = reply.send(r);
            }
            Cmd::Reset(reply) => {
                let r = self.reset();
                let _ = reply.send(r);
            }
            Cmd::Pose(reply) => {
                if self.reviving && self.state == SessionState::Failed {
                    // the revival failed: there is no pose of the session's
                    let _ = reply.send(Err(SessionError::NotReady { state: self.state }));
                } else if self.reviving {
                    // the checkpoint pose lacks the journaled drags: wait
                    // for the revival's solve to settle
                    self.pose_waiters.push(reply);
                } else {
                    let _ = reply.send(Ok(self.snapshot()));
                }
            }
            Cmd::Poses(cmd) => {
                if cmd.waits_for_settle() && !self.pose_settled() {
                    self.settle_queue.push_back(cmd);
                } else {
                    self.on_pose_cmd(cmd);
                }
            }
            Cmd::GestureEnded => {
                if self.settled && self.deformer.is_some() {
                    self.commit_gesture();
                }
            }
            Cmd::Close => return false,
        }
        true
    }

    fn on_drag(
        &mut self,
        handle: usize,
        delta: Delta,
        seq: u64,
        reply: Option<(usize, Reply<PoseSnapshot>)>,
    ) {
        let fail = |reply: Option<(usize, Reply<PoseSnapshot>)>, e: SessionError| {
            if let Some((_, r)) = reply {
                let _ = r.send(Err(e));
            }
        };
        if self.state == SessionState::Building {
            // applied once the factor is ready (see `queued`)
            self.queued.push_back(QueuedDrag {
                handle,
                delta,
                seq,
                reply,
                at: Instant::now(),
            });
            return;
        }
        if self.state != SessionState::Ready {
            return fail(reply, SessionError::NotReady { state: self.state });
        }
        let Some(c) = self.constraints.as_mut() else {
            return fail(reply, SessionError::NotReady { state: self.state });
        };
        let c = Arc::make_mut(c);
        let Some(h) = c.handles.get_mut(handle) else {
            return fail(
                reply,
                SessionError::UnknownHandle {
                    handle: super::HandleRef::Index(handle),
                },
            );
        };
        h.target = h.target.then(delta.rotation, delta.translation);
        let q = delta.rotation.coords;
        self.journal.push(JournalEntry::Drag {
            handle,
            rotation: [q.x, q.y, q.z, q.w],
            translation: delta.translation,
            seq,
        });
        if seq > 0 {
            self.last_seq = seq;
        }
        self.dirty = true;
        self.drag_pending = true;
        self.settled = false;
        self.uncommitted = true;
        if self.deformer.is_none() && self.refining {
            self.interrupt
                .store(true, std::sync::atomic::Ordering::Relaxed);
        }
        match reply {
            Some(w) => self.waiters.push(w),
            None => {
                let now = std::time::Instant::now();
                self.drag_gap = self
                    .last_stream_drag
                    .map(|t| now.saturating_duration_since(t))
                    .filter(|&g| g < crate::session::CORRECTION_QUIET);
                self.last_stream_drag = Some(now);
            }
        }
    }

    /// The drags applied so far are accounted for (a solve took them, or
    /// they were dropped): nothing new to solve, and no drag waits.
    pub(super) fn drags_taken(&mut self) {
        self.dirty = false;
        self.drag_pending = false;
    }

    /// A client's new constraint set, resolved here once, anchored at the
    /// current pose (`ConstraintsSpec::resolve_at`: fixed vertices stay
    /// where the pose has them, handles move from there): the pose before
    /// it stays in the history, and the pose does not jump. An invalid set
    /// is refused before a stale one, as nothing is changed for either.
    fn on_set_constraints(
        &mut self,
        client: ConstraintsSpec,
        if_revision: Option<u64>,
    ) -> Result<SessionState, SessionError> {
        let mesh = self.inner.rest.mesh();
        let anchored = client.resolve_at(mesh, Some(&self.pose))?;
        let current = self.set.as_ref().map_or(0, |s| s.id);
        if let Some(given) = if_revision.filter(|&given| given != current) {
            return Err(SessionError::StaleConstraints { current, given });
        }
        let stored = serde_json::to_value(client.anchored(mesh, &anchored))
            .map_err(|e| SessionError::InvalidConstraints(e.to_string()))?;
        // the pose the edit starts from is an undo step of its own
        self.commit();
        self.sets_installed += 1;
        let set = Arc::new(InstalledSet {
            id: self.sets_installed,
            client,
            stored,
            constraints: anchored,
        });
        self.install(set, AfterBuild::Solve)?;
        // the store's checkpoint went with its old constraints
        self.checkpoint();
        Ok(SessionState::Building)
    }

    /// A stored constraint set re-opened with the recovered targets and
    /// pose (resolved by the handle); a revived session's history starts
    /// here.
    fn on_restore(&mut self, r: Restore) -> Result<SessionState, SessionError> {
        if let (Some(pose), Some(d)) = (r.pose, self.deformer.as_mut()) {
            d.set_pose(pose)?;
            self.pose = Arc::new(d.pose().to_vec());
        }
        self.last_seq = r.ack_seq;
        self.applied_seq = r.ack_seq;
        self.history.clear();
        self.cursor = 0;
        self.uncommitted = false;
        self.reviving = true;
        self.sets_installed += 1;
        let set = Arc::new(InstalledSet {
            id: self.sets_installed,
            client: r.spec,
            stored: r.stored,
            constraints: r.constraints,
        });
        self.activate(set, AfterBuild::Solve);
        Ok(SessionState::Building)
    }

    /// Writes `set`'s stored spec to the store, then [`activate`](Self::activate)s it.
    fn install(&mut self, set: Arc<InstalledSet>, after: AfterBuild) -> Result<(), SessionError> {
        let (store, id, fence) = (&self.opts.store, &self.inner.id, self.opts.fence);
        if let Err(e) = off_worker(|| store.set_constraints(id, fence, &set.stored)) {
            self.on_store_error(&e);
            return Err(e.into());
        }
        self.activate(set, after);
        Ok(())
    }

    /// Makes `set` the session's constraint set (with the targets it
    /// carries) and starts its factor's lookup or build (state
    /// `building`); every grab ends, visibly.
    fn activate(&mut self, set: Arc<InstalledSet>, after: AfterBuild) {
        self.generation += 1;
        self.factor = None;
        self.state = SessionState::Building;
        self.after_build = after;
        self.inner.shared.lock().handles = set
            .constraints
            .handles
            .iter()
            .map(|h| h.name.clone())
            .collect();
        // the handle list changed: every grab ends, visibly
        let released = self.inner.shared.lock().grabs.clear();
        for (handle, client) in released {
            let _ = self
                .inner
                .events
                .send(Event::Peer(PeerEvent::HandleReleased { handle, client }));
        }
        self.journal.clear();
        self.drags_taken();
        self.settled = true;
        for (_, w) in self.waiters.drain(..) {
            let _ = w.send(Err(SessionError::NotReady {
                state: SessionState::Building,
            }));
        }
        // drags queued for the previous set do not carry over to this one
        self.refuse_queued(|| SessionError::NotReady {
            state: SessionState::Building,
        });
        let constraints = Arc::new(set.constraints.clone());
        self.constraints = Some(constraints.clone());
        self.confirmed = Some(constraints.clone());
        let warnings: Vec<_> = set
            .constraints
            .warnings(self.inner.rest.mesh())
            .iter()
            .filter_map(|w| {
                crate::wire::warning(w)
                    .map_err(|e| tracing::error!(%e, "constraint warning"))
                    .ok()
            })
            .collect();
        {
            let mut s = self.inner.shared.lock();
            s.constraints = match crate::wire::constraints(&set.client) {
                Ok(c) => Some(Arc::new(c)),
                Err(e) => {
                    tracing::error!(%e, "installed constraints");
                    None
                }
            };
            s.constraints_revision = set.id;
            s.warnings = Arc::new(warnings);
        }
        self.set = Some(set);
        self.revision += 1;
        self.sync_shared();
        let _ = self.inner.events.send(Event::State);
        let (generation, tx) = (self.generation, self.internal_tx.clone());
        let (rest, params, cache) = (
            self.inner.rest.clone(),
            self.inner.params,
            self.opts.cache.clone(),
        );
        drop(tokio::task::spawn_blocking(move || {
            let t0 = Instant::now();
            let report = |stage| {
                let _ = tx.send(Internal::Stage { generation, stage });
            };
            let result = cache
                .get_or_build_reporting(&rest, &params, &constraints, &report)
                .map_err(SessionError::from);
            let _ = tx.send(Internal::Built {
                generation,
                result,
                seconds: t0.elapsed().as_secs_f64(),
            });
        }));
    }

    fn targets(&self) -> Vec<RigidTransform> {
        self.constraints
            .as_ref()
            .map(|c| c.handles.iter().map(|h| h.target).collect())
            .unwrap_or_default()
    }
}

#[path = "actor_history.rs"]
mod history;
#[path = "actor_queue.rs"]
mod queue;

#[path = "actor_poses.rs"]
mod named_poses;
#[path = "actor_solve.rs"]
mod solve;
