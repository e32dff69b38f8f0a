//! The named-pose side of the session actor: the list (read from the store
//! when first needed), saves, renames, deletes and restores, each written
//! to the store before it is answered.

use std::sync::Arc;

use super::{Actor, AfterBuild, InstalledSet};
use crate::session::error::SessionError;
use crate::session::poses::{pose_list, PoseInfo, MAX_NAMED_POSES};
use crate::session::recovery::transform;
use crate::session::shared::off_worker;
use crate::session::shared::PoseCmd;
use crate::session::types::{Event, PoseSnapshot};
use crate::store::{NamedPose, StoreError, StoredTransform};
use dend::deform::{ConstraintsSpec, RigidTransform};
use dend_protocol::ws::SessionState;

impl Actor {
    /// Whether a queued pose command may run now: the pose is settled, no
    /// solve is running and no factor is being built.
    pub(super) fn pose_settled(&self) -> bool {
        self.solve.deformer.is_some()
            && self.shown.settled
            && self.state() != SessionState::Building
    }

    /// Reads the named poses of a revived session (none for a new one); a
    /// store failure is retried by the first pose command.
    pub(super) fn load_named_poses(&mut self) {
        if let Err(e) = self.named() {
            tracing::warn!(session = %self.inner.id, error = %e, "named poses not read yet");
        }
    }

    /// The named poses, read from the store the first time.
    fn named(&mut self) -> Result<&mut Vec<NamedPose>, SessionError> {
        if self.poses.named.is_none() {
            let (store, id) = (&self.opts.store, &self.inner.id);
            let poses = off_worker(|| store.named_poses(id))?;
            self.publish_names(&poses);
            self.poses.named = Some(poses);
        }
        Ok(self.poses.named.get_or_insert_with(Vec::new))
    }

    /// Tells the session's clients the pose names (in `state`).
    fn publish_names(&self, poses: &[NamedPose]) {
        self.inner.shared.lock().poses = Arc::new(pose_list(poses));
    }

    /// After a change of the list: store it in the shared state and tell
    /// every client.
    fn names_changed(&mut self) {
        if let Some(poses) = &self.poses.named {
            self.publish_names(poses);
        }
        let _ = self.inner.events.send(Event::State);
    }

    /// A failed store write of a pose: a fenced one stops the session.
    fn pose_store_error(&mut self, e: StoreError) -> SessionError {
        self.on_store_error(&e);
        e.into()
    }

    /// Runs one named-pose command (settled, when it
    /// [`waits_for_settle`](PoseCmd::waits_for_settle)).
    pub(super) fn on_pose_cmd(&mut self, cmd: PoseCmd) {
        match cmd {
            PoseCmd::Save {
                name,
                replace,
                reply,
            } => {
                let _ = reply.send(self.save_pose(name, replace));
            }
            PoseCmd::List(reply) => {
                let _ = reply.send(self.named().map(|p| Arc::new(p.clone())));
            }
            PoseCmd::Rename { from, to, reply } => {
                let _ = reply.send(self.rename_pose(&from, &to));
            }
            PoseCmd::Delete { name, reply } => {
                let _ = reply.send(self.delete_pose(&name));
            }
            PoseCmd::Restore { name, reply } => {
                let _ = reply.send(self.restore_pose(&name));
            }
        }
    }

    fn save_pose(&mut self, name: String, replace: bool) -> Result<PoseInfo, SessionError> {
        let (pose, targets) = (self.shown.pose.to_vec(), self.targets());
        let constraints = self.set.current.as_ref().map(|s| s.stored.clone());
        let revision = self.shown.revision;
        let poses = self.named()?;
        let existing = poses.iter().position(|p| p.name == name);
        if existing.is_some() && !replace {
            return Err(SessionError::PoseExists { name });
        }
        if existing.is_none() && poses.len() >= MAX_NAMED_POSES {
            return Err(SessionError::TooManyPoses {
                limit: MAX_NAMED_POSES,
            });
        }
        let ordinal = match existing {
            Some(i) => poses[i].ordinal,
            None => poses.iter().map(|p| p.ordinal + 1).max().unwrap_or(0),
        };
        let named = NamedPose {
            name,
            ordinal,
            revision,
            created_unix: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            constraints,
            pose,
            targets: targets.iter().map(StoredTransform::from).collect(),
        };
        let (store, id, fence) = (&self.opts.store, &self.inner.id, self.opts.fence);
        if let Err(e) = off_worker(|| store.put_named_pose(id, fence, &named)) {
            return Err(self.pose_store_error(e));
        }
        let poses = self.named()?;
        let index = match existing {
            Some(i) => {
                poses[i] = named;
                i
            }
            None => {
                poses.push(named);
                poses.len() - 1
            }
        };
        let info = pose_list(poses).swap_remove(index);
        self.names_changed();
        Ok(info)
    }

    fn rename_pose(&mut self, from: &str, to: &str) -> Result<(), SessionError> {
        let poses = self.named()?;
        let i = poses
            .iter()
            .position(|p| p.name == from)
            .ok_or_else(|| SessionError::UnknownPose { name: from.into() })?;
        if from == to {
            return Ok(());
        }
        if poses.iter().any(|p| p.name == to) {
            return Err(SessionError::PoseExists { name: to.into() });
        }
        let (store, id, fence) = (&self.opts.store, &self.inner.id, self.opts.fence);
        if let Err(e) = off_worker(|| store.rename_named_pose(id, fence, from, to)) {
            return Err(self.pose_store_error(e));
        }
        self.named()?[i].name = to.to_owned();
        self.names_changed();
        Ok(())
    }

    fn delete_pose(&mut self, name: &str) -> Result<(), SessionError> {
        let i = self
            .named()?
            .iter()
            .position(|p| p.name == name)
            .ok_or_else(|| SessionError::UnknownPose { name: name.into() })?;
        let (store, id, fence) = (&self.opts.store, &self.inner.id, self.opts.fence);
        if let Err(e) = off_worker(|| store.delete_named_pose(id, fence, name)) {
            return Err(self.pose_store_error(e));
        }
        let _ = self.named()?.remove(i);
        self.names_changed();
        Ok(())
    }

    /// The pose before becomes an undo step; the named pose's constraint
    /// set is installed again when the session has another one now (its
    /// factor is looked up or rebuilt while the pose is already restored,
    /// as an undo across constraint sets does). A pose saved before any
    /// constraint set restores its positions, the handles keeping their
    /// targets.
    fn restore_pose(&mut self, name: &str) -> Result<PoseSnapshot, SessionError> {
        let named = self
            .named()?
            .iter()
            .find(|p| p.name == name)
            .cloned()
            .ok_or_else(|| SessionError::UnknownPose { name: name.into() })?;
        if named.pose.len() != self.shown.pose.len() {
            return Err(StoreError::Corrupt {
                what: format!("named pose `{name}` of session `{}`", self.inner.id),
                reason: format!(
                    "{} positions for {} vertices",
                    named.pose.len(),
                    self.shown.pose.len()
                ),
            }
            .into());
        }
        let mut targets: Vec<RigidTransform> = named
            .targets
            .iter()
            .map(transform)
            .collect::<Result<_, _>>()?;
        self.commit();
        match &named.constraints {
            Some(stored) if self.set.current.as_ref().map(|s| &s.stored) != Some(stored) => {
                let corrupt = |reason: String| StoreError::Corrupt {
                    what: format!("constraints of named pose `{name}`"),
                    reason,
                };
                let spec: ConstraintsSpec =
                    serde_json::from_value(stored.clone()).map_err(|e| corrupt(e.to_string()))?;
                let constraints = spec.resolve(self.inner.rest.mesh())?;
                self.set.installed += 1;
                let set = Arc::new(InstalledSet {
                    id: self.set.installed,
                    client: spec,
                    stored: stored.clone(),
                    constraints,
                });
                self.install(set, AfterBuild::Keep)?;
            }
            Some(_) => {}
            None => targets = self.targets(),
        }
        let snap = self.restore(Arc::new(named.pose), &targets)?;
        self.history.uncommitted = true;
        self.commit();
        Ok(snap)
    }
}
