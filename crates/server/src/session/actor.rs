//! The session actor: owns the deformer, composes drags, runs one solve at a
//! time on the blocking pool, publishes frames and keeps the history.

use std::sync::Arc;
use std::time::Instant;

use tokio::sync::mpsc;

use super::error::SessionError;
use super::shared::{off_worker, Cmd, Internal, QueuedDrag, Reply, Restore};
use super::timing::{sleep_until_or_never, CORRECTION_QUIET};
use super::types::{Delta, Event, PoseSnapshot};
use crate::store::JournalEntry;
use dend::deform::{ConstraintsSpec, FactorKey, RigidTransform};
use dend_protocol::ws::{HandleRef, PeerEvent, SessionState};
use dend_protocol::FrameHeader;

pub(in crate::session) use parts::Actor;
use parts::{InstalledSet, Snapshot, HISTORY_LIMIT};
use phase::{AfterBuild, Phase, Read, Step};

impl Actor {
    pub(super) async fn run(mut self, mut rx: mpsc::Receiver<Cmd>) {
        let Some(mut internal_rx) = self.internal_rx.take() else {
            return;
        };
        self.load_named_poses();
        loop {
            while let Some(cmd) = self.flow.deferred.front() {
                if self.must_wait(cmd) {
                    break;
                }
                let Some(cmd) = self.flow.deferred.pop_front() else {
                    break;
                };
                if !self.run_cmd(cmd) {
                    return self.closed();
                }
            }
            self.maybe_start_solve();
            // the oldest queued drag's deadline (far away when none is queued)
            let deadline = self.flow.queued.front().map_or_else(
                || tokio::time::Instant::now() + std::time::Duration::from_secs(3600),
                |q| tokio::time::Instant::from_std(q.at + self.opts.build_wait),
            );
            self.answer_drags_shown();
            tokio::select! {
                Some(msg) = internal_rx.recv() => self.on_internal(msg),
                () = tokio::time::sleep_until(deadline), if !self.flow.queued.is_empty() => {
                    self.expire_queued();
                }
                () = sleep_until_or_never(self.solve.wake_at.map(tokio::time::Instant::from_std)),
                    if self.solve.wake_at.is_some() => {
                    // the loop's `maybe_start_solve` starts the full mesh's solve
                    self.solve.wake_at = None;
                }
                cmd = rx.recv() => match cmd {
                    Some(cmd) => if !self.on_cmd(cmd) { return self.closed() },
                    None => return self.closed(),
                },
            }
            if self.phase.draining() {
                return self.closed();
            }
        }
    }

    /// The state clients see.
    fn state(&self) -> SessionState {
        self.phase.state()
    }

    /// Takes `step` ([`Phase::next`]); a step that is not legal leaves the
    /// phase as it is (a draining actor finishing its last command may
    /// try one: it ends after it).
    fn go(&mut self, step: Step) {
        match self.phase.next(step) {
            Ok(next) => self.phase = next,
            Err(e) if self.phase.draining() => {
                tracing::debug!(session = %self.inner.id, error = %e, "draining");
            }
            Err(e) => {
                tracing::error!(session = %self.inner.id, error = %e, "illegal phase step");
                debug_assert!(false, "{e}");
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
            revision: self.shown.revision,
            ack_seq: self.shown.applied_seq,
            iteration: self.solve.iters_since_change as u32,
            converged: self.shown.converged,
            settled: self.shown.settled,
            objective: self.shown.objective,
            vertex_count: self.shown.pose.len() as u32,
            level: self.shown.level,
        }
    }

    /// Whether the session holds drags no frame shows yet: received
    /// since the last solve started, taken by the solve that runs, or
    /// queued for the factor.
    fn drags_unshown(&self) -> bool {
        self.solve.drag_pending
            || self.solve.inflight_drags
            || !self.flow.queued.is_empty()
            || self.drags_held()
    }

    /// Whether drags wait in `deferred` behind a command that waits
    /// ([`Actor::on_cmd`]).
    fn drags_held(&self) -> bool {
        self.flow
            .deferred
            .iter()
            .any(|c| matches!(c, Cmd::Drag { .. }))
    }

    /// Whether `cmd` keeps its place among the commands that change the
    /// pose or the targets: behind one that waits, it waits too
    /// ([`Actor::on_cmd`]).
    fn in_order(cmd: &Cmd) -> bool {
        match cmd {
            Cmd::Drag { .. }
            | Cmd::Undo(_)
            | Cmd::Redo(_)
            | Cmd::Reset(_)
            | Cmd::SetConstraints { .. } => true,
            Cmd::Poses(c) => c.waits_for_settle(),
            _ => false,
        }
    }

    /// Whether `cmd`, next in turn, waits (in `deferred`). An undo, redo,
    /// reset or constraint edit reads or replaces the pose and writes a
    /// checkpoint, which truncates the stored journal: it waits for a
    /// running solve, so that the journal append the solve starts with
    /// lands before the checkpoint (else a revival replays drags the
    /// checkpoint holds or undid). A constraint edit also waits for the
    /// solve of the drags received before it: it commits the pose as an
    /// undo step and anchors the new set there, so the pose holds them
    /// (else they went with the old set's targets, unsolved, into that
    /// step). A named pose's save or restore waits for the settle (not in
    /// a failed session, which may never settle and takes a new
    /// constraint set next).
    fn must_wait(&self, cmd: &Cmd) -> bool {
        let running = self.solve.deformer.is_none();
        match cmd {
            Cmd::Undo(_) | Cmd::Redo(_) | Cmd::Reset(_) => running,
            Cmd::SetConstraints { .. } => {
                running || self.state() == SessionState::Ready && self.solve.drag_pending
            }
            Cmd::Poses(c) => {
                c.waits_for_settle() && !self.pose_settled() && self.state() != SessionState::Failed
            }
            _ => false,
        }
    }

    /// Answers the `Cmd::DragsShown` questions whose drags are in a frame:
    /// none is unshown, or a solve started after the question has ended.
    /// Called before the loop waits, after every change of either.
    fn answer_drags_shown(&mut self) {
        if self.flow.shown_waiters.is_empty() {
            return;
        }
        let (unshown, done) = (self.drags_unshown(), self.solve.solves_done);
        // (a held drag is in no solve's targets yet: only its own solve,
        // once it is applied, shows it)
        let held = self.drags_held();
        let waiting = std::mem::take(&mut self.flow.shown_waiters);
        for (started, reply) in waiting {
            if held {
                // the solves that end while drags are held do not show
                // them: counted from the next one
                self.flow
                    .shown_waiters
                    .push((self.solve.solves_started, reply));
            } else if unshown && done <= started {
                self.flow.shown_waiters.push((started, reply));
            } else {
                let _ = reply.send(());
            }
        }
    }

    fn sync_shared(&self) {
        let mut s = self.inner.shared.lock();
        s.state = self.state();
        s.revision = self.shown.revision;
        s.can_undo =
            self.history.uncommitted && !self.history.entries.is_empty() || self.history.cursor > 0;
        s.can_redo =
            !self.history.uncommitted && self.history.cursor + 1 < self.history.entries.len();
    }

    /// Handles one command as it arrives; false when the session must stop.
    fn on_cmd(&mut self, cmd: Cmd) -> bool {
        // the commands that change the pose or the targets keep their
        // order behind one that waits: a drag composed into the targets at
        // once would be replaced with them (taken back, though its frame
        // acknowledges it) or go to a constraint set it was not sent for,
        // and an undo run at once would go before the drags it should take
        // back
        let behind = Self::in_order(&cmd) && !self.flow.deferred.is_empty();
        if behind || self.must_wait(&cmd) {
            self.flow.deferred.push_back(cmd);
            return true;
        }
        self.run_cmd(cmd)
    }

    /// Runs one command, in its turn; false when the session must stop.
    fn run_cmd(&mut self, cmd: Cmd) -> bool {
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
                match self.phase.read() {
                    // the revival failed: there is no pose of the session's
                    Read::Refuse => {
                        let _ = reply.send(Err(SessionError::NotReady {
                            state: self.state(),
                        }));
                    }
                    // the checkpoint pose lacks the journaled drags: wait
                    // for the revival's solve to settle
                    Read::Wait => self.flow.pose_waiters.push(reply),
                    Read::Serve => {
                        let _ = reply.send(Ok(self.snapshot()));
                    }
                }
            }
            Cmd::Poses(cmd) => self.on_pose_cmd(cmd),
            Cmd::DragsShown(reply) => {
                if self.drags_unshown() {
                    self.flow
                        .shown_waiters
                        .push((self.solve.solves_started, reply));
                } else {
                    let _ = reply.send(());
                }
            }
            Cmd::GestureEnded => {
                if self.shown.settled && self.solve.deformer.is_some() {
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
        if self.state() == SessionState::Building {
            // applied once the factor is ready (see `queued`)
            self.flow.queued.push_back(QueuedDrag {
                handle,
                delta,
                seq,
                reply,
                at: Instant::now(),
            });
            return;
        }
        if self.state() != SessionState::Ready {
            return fail(
                reply,
                SessionError::NotReady {
                    state: self.state(),
                },
            );
        }
        let Some(c) = self.set.constraints.as_mut() else {
            return fail(
                reply,
                SessionError::NotReady {
                    state: self.state(),
                },
            );
        };
        let c = Arc::make_mut(c);
        let Some(h) = c.handles.get_mut(handle) else {
            return fail(
                reply,
                SessionError::UnknownHandle {
                    handle: HandleRef::Index(handle),
                },
            );
        };
        h.target = h.target.then(delta.rotation, delta.translation);
        let q = delta.rotation.coords;
        self.solve.journal.push(JournalEntry::Drag {
            handle,
            rotation: [q.x, q.y, q.z, q.w],
            translation: delta.translation,
            seq,
        });
        if seq > 0 {
            self.shown.last_seq = seq;
        }
        self.solve.dirty = true;
        self.solve.drag_pending = true;
        self.shown.settled = false;
        self.history.uncommitted = true;
        if self.solve.deformer.is_none() && self.solve.refining {
            self.solve
                .interrupt
                .store(true, std::sync::atomic::Ordering::Relaxed);
            // a refinement still waiting for a worker now stands for the
            // drag's answer: it stops after an iteration and hands over
            // (it no longer waits behind earlier sessions' settles)
            self.opts.scheduler.answer_now(&self.inner.id);
        }
        match reply {
            Some(w) => self.flow.waiters.push(w),
            None => {
                let now = std::time::Instant::now();
                self.solve.drag_gap = self
                    .solve
                    .last_stream_drag
                    .map(|t| now.saturating_duration_since(t))
                    .filter(|&g| g < CORRECTION_QUIET);
                self.solve.last_stream_drag = Some(now);
            }
        }
    }

    /// The drags applied so far are accounted for (a solve took them, or
    /// they were dropped): nothing new to solve, and no drag waits.
    pub(super) fn drags_taken(&mut self) {
        self.solve.dirty = false;
        self.solve.drag_pending = false;
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
        let anchored = client.resolve_at(mesh, Some(&self.shown.pose))?;
        let current = self.set.current.as_ref().map_or(0, |s| s.id);
        if let Some(given) = if_revision.filter(|&given| given != current) {
            return Err(SessionError::StaleConstraints { current, given });
        }
        let stored = serde_json::to_value(client.anchored(mesh, &anchored))
            .map_err(|e| SessionError::InvalidConstraints(e.to_string()))?;
        // the pose the edit starts from is an undo step of its own
        self.commit();
        self.set.installed += 1;
        let set = Arc::new(InstalledSet {
            id: self.set.installed,
            client,
            stored,
            constraints: anchored,
        });
        self.install(set, AfterBuild::Solve)?;
        // (the edit waited for the solve of the drags received before it,
        // `must_wait`; were one left unsolved, it went with the old set's
        // targets: like an undo, the edit takes it back, and a frame says so)
        self.acknowledge_taken_back();
        // the store's checkpoint went with its old constraints
        self.checkpoint();
        Ok(SessionState::Building)
    }

    /// A stored constraint set re-opened with the recovered targets and
    /// pose (resolved by the handle); a revived session's history starts
    /// here.
    fn on_restore(&mut self, r: Restore) -> Result<SessionState, SessionError> {
        if let (Some(pose), Some(d)) = (r.pose, self.solve.deformer.as_mut()) {
            d.set_pose(pose)?;
            self.shown.pose = Arc::new(d.pose().to_vec());
        }
        self.shown.last_seq = r.ack_seq;
        self.shown.applied_seq = r.ack_seq;
        self.history.entries.clear();
        self.history.cursor = 0;
        self.history.uncommitted = false;
        self.set.installed += 1;
        let set = Arc::new(InstalledSet {
            id: self.set.installed,
            client: r.spec,
            stored: r.stored,
            constraints: r.constraints,
        });
        self.activate(set, Step::Revive);
        Ok(SessionState::Building)
    }

    /// Writes `set`'s stored spec to the store, then [`activate`](Self::activate)s it.
    fn install(&mut self, set: Arc<InstalledSet>, after: AfterBuild) -> Result<(), SessionError> {
        let (store, id, fence) = (&self.opts.store, &self.inner.id, self.opts.fence);
        if let Err(e) = off_worker(|| store.set_constraints(id, fence, &set.stored)) {
            self.on_store_error(&e);
            return Err(e.into());
        }
        self.activate(set, Step::Install(after));
        Ok(())
    }

    /// Makes `set` the session's constraint set (with the targets it
    /// carries) and starts its factor's lookup or build (`step`: a set
    /// installed, or a revival; state `building`); every grab ends,
    /// visibly.
    fn activate(&mut self, set: Arc<InstalledSet>, step: Step) {
        // a set with the constrained vertices of the factor installed
        // before (a reset, a restore, an edit of targets or names) has the
        // deformer's levels already: none are built for it
        let same_levels = self.set.factor.as_ref().is_some_and(|f| {
            *f.key() == FactorKey::new(&self.inner.rest, &self.inner.params, &set.constraints)
        });
        self.set.generation += 1;
        self.set.factor = None;
        self.set.prepared = None;
        self.go(step);
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
        self.solve.journal.clear();
        self.drags_taken();
        self.shown.settled = true;
        for (_, w) in self.flow.waiters.drain(..) {
            let _ = w.send(Err(SessionError::NotReady {
                state: SessionState::Building,
            }));
        }
        // drags queued for the previous set do not carry over to this one
        self.refuse_queued(|| SessionError::NotReady {
            state: SessionState::Building,
        });
        let constraints = Arc::new(set.constraints.clone());
        self.set.constraints = Some(constraints.clone());
        self.set.confirmed = Some(constraints.clone());
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
        self.set.current = Some(set);
        self.shown.revision += 1;
        self.sync_shared();
        let _ = self.inner.events.send(Event::State);
        let (generation, tx) = (self.set.generation, self.internal_tx.clone());
        let (rest, params, cache) = (
            self.inner.rest.clone(),
            self.inner.params,
            self.opts.cache.clone(),
        );
        // the set's coarse levels, beside the factor (they need the rest
        // operators and the constraints only): the first drag's preview
        // and the first settle's corrections then find them built
        if !same_levels {
            let (plan, levels_tx, levels_for) = (
                self.solve.level_plan.clone(),
                self.internal_tx.clone(),
                constraints.clone(),
            );
            drop(tokio::task::spawn_blocking(move || {
                let t0 = Instant::now();
                let levels = plan.build(&levels_for);
                let _ = levels_tx.send(Internal::LevelsBuilt {
                    generation,
                    levels,
                    seconds: t0.elapsed().as_secs_f64(),
                });
            }));
        }
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
        self.set
            .constraints
            .as_ref()
            .map(|c| c.handles.iter().map(|h| h.target).collect())
            .unwrap_or_default()
    }
}

#[path = "actor_parts.rs"]
mod parts;
#[path = "actor_phase.rs"]
mod phase;

#[path = "actor_history.rs"]
mod history;
#[path = "actor_queue.rs"]
mod queue;

#[path = "actor_poses.rs"]
mod named_poses;
#[path = "actor_solve.rs"]
mod solve;
