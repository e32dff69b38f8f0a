//! The history side of the session actor: commit points (history entries
//! and their checkpoints), undo, redo and reset, and what a failed store
//! write means for the session.

use std::sync::atomic::Ordering;
use std::sync::Arc;

use super::{Actor, AfterBuild, InstalledSet, Snapshot, Step, HISTORY_LIMIT};
use crate::session::error::SessionError;
use crate::session::shared::off_worker;
use crate::session::types::{Event, Frame, PoseSnapshot};
use crate::store::{Checkpoint, StoreError, StoredTransform};
use dend::deform::RigidTransform;
use dend_protocol::ws::SessionState;
use dend_protocol::{FrameBody, FrameHeader};

impl Actor {
    /// [`commit`](Self::commit) unless a client holds a handle: one user
    /// gesture (grab … release) is one undo step, however often the pose
    /// settles during it; the release commits ([`Cmd::GestureEnded`]).
    pub(super) fn commit_gesture(&mut self) {
        if self.inner.shared.lock().grabs.is_empty() {
            self.commit();
        }
    }

    /// Records the settled state as a history entry and checkpoints it.
    pub(super) fn commit(&mut self) {
        if !self.history.uncommitted {
            return;
        }
        self.history.uncommitted = false;
        if !self.history.entries.is_empty() {
            self.history.entries.truncate(self.history.cursor + 1);
        }
        let Some(set) = self.set.current.clone() else {
            return;
        };
        let targets = self.targets();
        match self.history.entries.last_mut() {
            // a gesture that left the set and the targets as they were (a
            // zero drag, a drag back to where it started, the settle of a
            // set's first solve that a drag joined late) is not an undo
            // step of its own: the step it would repeat takes its pose
            Some(top) if top.set.id == set.id && top.targets == targets => {
                top.pose = self.shown.pose.clone();
            }
            _ => self.history.entries.push(Snapshot {
                pose: self.shown.pose.clone(),
                targets,
                set,
            }),
        }
        if self.history.entries.len() > HISTORY_LIMIT {
            let _ = self.history.entries.remove(0);
        }
        self.history.cursor = self.history.entries.len() - 1;
        self.checkpoint();
        self.sync_shared();
        // clients enable their undo/redo buttons from `can_undo`/`can_redo`
        let _ = self.inner.events.send(Event::State);
    }

    pub(super) fn checkpoint(&mut self) {
        // the targets hold every drag received, also those the next solve
        // has yet to journal (`last_seq`), and writing the checkpoint
        // empties the stored journal: so its `ack_seq` is `last_seq`, and
        // those drags, now in the checkpoint, are not journaled again. With
        // the shown pose's `applied_seq` instead, a revival after a drag
        // that arrived as the pose settled served that drag's target under
        // the previous sequence number, and a client resending the drag
        // would have had it applied twice.
        let cp = Checkpoint {
            revision: self.shown.revision,
            ack_seq: self.shown.last_seq.max(self.shown.applied_seq),
            pose: self.shown.pose.to_vec(),
            targets: self.targets().iter().map(StoredTransform::from).collect(),
        };
        let (store, id, fence) = (&self.opts.store, &self.inner.id, self.opts.fence);
        match off_worker(|| store.checkpoint(id, fence, &cp)) {
            Ok(()) => {
                self.solve.journal.clear();
                self.set.confirmed = self.set.constraints.clone();
            }
            // the session was deleted while this checkpoint was on its way
            // (a settle frame racing a close): there is nothing to keep
            Err(StoreError::Missing(_)) => {
                tracing::debug!(session = %self.inner.id, "checkpoint skipped: the session was deleted");
            }
            Err(e) => {
                // the journal stays as it was: a recovery still replays every
                // acknowledged drag onto the previous checkpoint
                tracing::error!(session = %self.inner.id, error = %e, "checkpoint failed");
                self.on_store_error(&e);
            }
        }
    }

    /// A store write failed: a fenced one means another instance owns the
    /// session now, so this one stops driving it (its clients are told the
    /// session closed and reconnect, reaching the owner).
    pub(super) fn on_store_error(&mut self, e: &StoreError) {
        if matches!(e, StoreError::Fenced { .. }) {
            tracing::warn!(session = %self.inner.id, error = %e, "lease lost: closing the session here");
            self.inner.ownership.fenced.store(true, Ordering::Relaxed);
            self.go(Step::Fenced);
        }
    }

    /// Restores a pose and targets without solving; publishes a converged frame.
    pub(super) fn restore(
        &mut self,
        pose: Arc<Vec<[f64; 3]>>,
        targets: &[RigidTransform],
    ) -> Result<PoseSnapshot, SessionError> {
        // a solve in flight holds the deformer: it gets this pose when it
        // returns (`pose_epoch`)
        if let Some(d) = self.solve.deformer.as_mut() {
            d.set_pose(pose.to_vec())?;
        }
        self.solve.pose_epoch += 1;
        if let Some(c) = self.set.constraints.as_mut() {
            for (h, t) in Arc::make_mut(c).handles.iter_mut().zip(targets) {
                h.target = *t;
            }
        }
        self.set.confirmed = self.set.constraints.clone();
        self.shown.pose = pose;
        // every drag received so far is taken back with the targets (and
        // covered by the checkpoint that follows): the frame acknowledges
        // them, else a client keeps them pending and resends them after a
        // reconnect, on top of this pose
        self.shown.applied_seq = self.shown.last_seq;
        self.drags_taken();
        self.shown.settled = true;
        self.shown.converged = true;
        self.shown.objective = f64::NAN;
        self.solve.iters_since_change = 0;
        self.solve.journal.clear();
        let state = self.state();
        for (_, w) in self.flow.waiters.drain(..) {
            let _ = w.send(Err(SessionError::NotReady { state }));
        }
        // iteration 0, converged and settled, no objective (set above)
        let header = self.publish_shown_pose();
        Ok(self.snapshot_for(&header))
    }

    /// Publishes the shown pose as a frame of a new revision (a pose set
    /// without a solve); returns its header.
    fn publish_shown_pose(&mut self) -> FrameHeader {
        self.shown.revision += 1;
        let header = self.header();
        let bytes = FrameBody::from_pose(&self.shown.pose).finish(&header);
        self.frames_tx.send_replace(Some(Frame { header, bytes }));
        header
    }

    /// Publishes the current pose under a frame that acknowledges every
    /// drag received (when one is not yet): for drags taken back without a
    /// solve. A client keeps unacknowledged drags pending and resends them
    /// after a reconnect, onto a pose or a constraint set they were not
    /// meant for.
    pub(super) fn acknowledge_taken_back(&mut self) {
        if self.shown.applied_seq == self.shown.last_seq {
            return;
        }
        self.shown.applied_seq = self.shown.last_seq;
        self.publish_shown_pose();
    }

    pub(super) fn undo_redo(&mut self, undo: bool) -> Result<PoseSnapshot, SessionError> {
        if self.state() != SessionState::Ready {
            return Err(SessionError::NotReady {
                state: self.state(),
            });
        }
        let target = if undo {
            if self.history.uncommitted && !self.history.entries.is_empty() {
                Some(self.history.cursor)
            } else {
                self.history
                    .cursor
                    .checked_sub(1)
                    .filter(|_| !self.history.entries.is_empty())
            }
            .ok_or(SessionError::NothingToUndo)?
        } else {
            Some(self.history.cursor + 1)
                .filter(|i| !self.history.uncommitted && *i < self.history.entries.len())
                .ok_or(SessionError::NothingToRedo)?
        };
        let entry = &self.history.entries[target];
        let (pose, targets, set) = (entry.pose.clone(), entry.targets.clone(), entry.set.clone());
        if self.set.current.as_ref().map(|s| s.id) != Some(set.id) {
            // back to another constraint set: its factor is looked up (or
            // rebuilt) while the pose is already the entry's
            self.install(set, AfterBuild::Keep)?;
        }
        self.history.cursor = target;
        self.history.uncommitted = false;
        let snap = self.restore(pose, &targets)?;
        self.checkpoint();
        self.sync_shared();
        let _ = self.inner.events.send(Event::State);
        Ok(snap)
    }

    pub(super) fn reset(&mut self) -> Result<PoseSnapshot, SessionError> {
        if self.state() != SessionState::Ready {
            return Err(SessionError::NotReady {
                state: self.state(),
            });
        }
        let mesh = self.inner.rest.mesh();
        let rest = Arc::new(mesh.positions().to_vec());
        // the set anchored at rest again (a set installed on a posed mesh
        // holds its vertices where that pose had them)
        if let Some(set) = self.set.current.clone() {
            let at_rest = set.client.resolve(mesh)?;
            let stored = serde_json::to_value(set.client.anchored(mesh, &at_rest))
                .map_err(|e| SessionError::InvalidConstraints(e.to_string()))?;
            if stored != set.stored {
                self.set.installed += 1;
                let set = Arc::new(InstalledSet {
                    id: self.set.installed,
                    client: set.client.clone(),
                    stored,
                    constraints: at_rest,
                });
                self.install(set, AfterBuild::Keep)?;
            }
        }
        let targets: Vec<RigidTransform> = self
            .set
            .constraints
            .as_ref()
            .map(|c| {
                c.handles
                    .iter()
                    .map(|h| RigidTransform::identity(h.rest_centroid))
                    .collect()
            })
            .unwrap_or_default();
        let snap = self.restore(rest, &targets)?;
        self.history.uncommitted = true;
        self.commit();
        Ok(snap)
    }
}
