//! [`MemoryStore`]: the embedded in-process store (nothing survives a
//! restart; a crash-safe backend implements the same trait).

use std::collections::HashMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use parking_lot::Mutex;

use super::lease_rule::{self, Expiry};
use crate::store::traits::{LeaseStore, MeshStore, PoseStore, SessionLog};
use crate::store::types::{
    Checkpoint, Fence, JournalEntry, LeaseGrant, NamedPose, SessionRecord, StoreError, StoredAsset,
};
use dend::mesh::Mesh;

#[derive(Default)]
struct SessionData {
    record: Option<SessionRecord>,
    journal: Vec<JournalEntry>,
    checkpoint: Option<Checkpoint>,
    /// Named poses, by ordinal.
    poses: Vec<NamedPose>,
}

/// An in-memory [`Store`]: hash maps behind mutexes.
#[derive(Default)]
pub struct MemoryStore {
    meshes: Mutex<HashMap<String, Arc<Mesh>>>,
    assets: Mutex<HashMap<String, StoredAsset>>,
    sessions: Mutex<HashMap<String, SessionData>>,
    leases: Mutex<HashMap<String, LeaseRow>>,
}

/// A lease: owner, revision, expiry (`None` once released).
struct LeaseRow {
    owner: String,
    revision: Fence,
    expires: Option<Instant>,
    /// Another instance asked for the session.
    wanted_by: Option<String>,
}

impl LeaseRow {
    /// The row as the lease rule reads it, at `now`.
    fn view(&self, now: Instant) -> lease_rule::LeaseRow<'_> {
        lease_rule::LeaseRow {
            owner: &self.owner,
            revision: self.revision,
            expiry: match self.expires {
                None => Expiry::Released,
                Some(t) if t > now => Expiry::Live {
                    left_ms: u64::try_from((t - now).as_millis()).unwrap_or(u64::MAX),
                },
                Some(_) => Expiry::Expired,
            },
        }
    }
}

impl MemoryStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }
}

fn missing(id: &str) -> StoreError {
    StoreError::Missing(id.to_string())
}

impl MemoryStore {
    /// Refuses a write fenced by a revision that is not `id`'s lease's.
    fn check_fence(&self, id: &str, fence: Fence) -> Result<(), StoreError> {
        let leases = self.leases.lock();
        let current = leases.get(id).map(|l| (l.owner.as_str(), l.revision));
        lease_rule::check_fence(id, fence, current)
    }
}

impl MeshStore for MemoryStore {
    fn put_mesh(&self, id: &str, mesh: Arc<Mesh>) -> Result<(), StoreError> {
        let _ = self.meshes.lock().insert(id.to_owned(), mesh);
        Ok(())
    }

    fn get_mesh(&self, id: &str) -> Result<Option<Arc<Mesh>>, StoreError> {
        Ok(self.meshes.lock().get(id).cloned())
    }

    fn mesh_count(&self) -> Result<usize, StoreError> {
        Ok(self.meshes.lock().len())
    }

    fn put_asset(&self, id: &str, asset: &StoredAsset) -> Result<(), StoreError> {
        let _ = self.assets.lock().insert(id.to_owned(), asset.clone());
        Ok(())
    }

    fn get_asset(&self, id: &str) -> Result<Option<StoredAsset>, StoreError> {
        Ok(self.assets.lock().get(id).cloned())
    }

    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError> {
        let _ = self.assets.lock().remove(id);
        Ok(self.meshes.lock().remove(id).is_some())
    }
}

impl SessionLog for MemoryStore {
    fn put_session(&self, record: &SessionRecord) -> Result<(), StoreError> {
        let _ = super::codec::RecordRow::encode(record)?; // the same checks as the SQL stores
        self.sessions
            .lock()
            .entry(record.id.clone())
            .or_default()
            .record = Some(record.clone());
        Ok(())
    }

    fn get_session(&self, id: &str) -> Result<Option<SessionRecord>, StoreError> {
        Ok(self.sessions.lock().get(id).and_then(|s| s.record.clone()))
    }

    fn list_sessions(&self) -> Result<Vec<SessionRecord>, StoreError> {
        Ok(self
            .sessions
            .lock()
            .values()
            .filter_map(|s| s.record.clone())
            .collect())
    }

    fn delete_session(&self, id: &str) -> Result<(), StoreError> {
        let _ = self.sessions.lock().remove(id);
        let _ = self.leases.lock().remove(id);
        Ok(())
    }

    fn set_constraints(
        &self,
        id: &str,
        fence: Fence,
        spec: &serde_json::Value,
    ) -> Result<(), StoreError> {
        // the sessions lock is held across the check: a takeover waits
        let mut sessions = self.sessions.lock();
        self.check_fence(id, fence)?;
        let s = sessions.get_mut(id).ok_or_else(|| missing(id))?;
        let record = s.record.as_mut().ok_or_else(|| missing(id))?;
        record.constraints = Some(spec.clone());
        s.journal.clear();
        s.checkpoint = None;
        Ok(())
    }

    fn append(&self, id: &str, fence: Fence, entries: &[JournalEntry]) -> Result<(), StoreError> {
        let mut sessions = self.sessions.lock();
        let s = sessions.get_mut(id).ok_or_else(|| missing(id))?;
        self.check_fence(id, fence)?;
        s.journal.extend_from_slice(entries);
        Ok(())
    }

    fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError> {
        Ok(self
            .sessions
            .lock()
            .get(id)
            .map(|s| s.journal.clone())
            .unwrap_or_default())
    }

    fn checkpoint(
        &self,
        id: &str,
        fence: Fence,
        checkpoint: &Checkpoint,
    ) -> Result<(), StoreError> {
        let mut sessions = self.sessions.lock();
        let s = sessions.get_mut(id).ok_or_else(|| missing(id))?;
        self.check_fence(id, fence)?;
        s.checkpoint = Some(checkpoint.clone());
        s.journal.clear();
        Ok(())
    }

    fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError> {
        Ok(self
            .sessions
            .lock()
            .get(id)
            .and_then(|s| s.checkpoint.clone()))
    }
}

impl LeaseStore for MemoryStore {
    fn acquire_lease(
        &self,
        id: &str,
        owner: &str,
        ttl: Duration,
    ) -> Result<LeaseGrant, StoreError> {
        // the sessions lock first, as the fenced writes take it: a takeover
        // waits for a write in flight
        let _sessions = self.sessions.lock();
        let mut leases = self.leases.lock();
        let now = Instant::now();
        let grant = lease_rule::acquire(leases.get(id).map(|l| l.view(now)), owner);
        match &grant {
            LeaseGrant::HeldBy { .. } => {
                if let Some(l) = leases.get_mut(id) {
                    l.wanted_by = Some(owner.to_owned());
                }
            }
            LeaseGrant::Granted { revision, .. } => {
                let _ = leases.insert(
                    id.to_owned(),
                    LeaseRow {
                        owner: owner.to_owned(),
                        revision: *revision,
                        expires: Some(now + ttl),
                        wanted_by: None,
                    },
                );
            }
        }
        Ok(grant)
    }

    fn renew_leases(
        &self,
        owner: &str,
        held: &[(String, Fence)],
        ttl: Duration,
    ) -> Result<Vec<String>, StoreError> {
        let mut leases = self.leases.lock();
        let now = Instant::now();
        let mut lost = vec![];
        for (id, rev) in held {
            match leases.get_mut(id) {
                Some(l) if lease_rule::holds(l.view(now), owner, *rev) => {
                    l.expires = Some(now + ttl);
                }
                _ => lost.push(id.clone()),
            }
        }
        Ok(lost)
    }

    fn release_lease(&self, id: &str, owner: &str, revision: Fence) -> Result<(), StoreError> {
        if let Some(l) = self.leases.lock().get_mut(id) {
            if lease_rule::holds(l.view(Instant::now()), owner, revision) {
                l.expires = None;
            }
        }
        Ok(())
    }

    fn handoffs_wanted(&self, owner: &str) -> Result<Vec<String>, StoreError> {
        let now = Instant::now();
        Ok(self
            .leases
            .lock()
            .iter()
            .filter(|(_, l)| lease_rule::wants_handoff(l.view(now), l.wanted_by.is_some(), owner))
            .map(|(id, _)| id.clone())
            .collect())
    }
    fn ping(&self) -> Result<(), StoreError> {
        Ok(())
    }
    /// One process uses this store: there is no owner liveness to announce.
    fn announce_liveness(&self, _instance: &str) -> Result<(), StoreError> {
        Ok(())
    }
}

impl PoseStore for MemoryStore {
    fn put_named_pose(&self, id: &str, fence: Fence, pose: &NamedPose) -> Result<(), StoreError> {
        self.named_write(id, fence, |poses| {
            poses.retain(|p| p.name != pose.name);
            poses.push(pose.clone());
            poses.sort_by(|a, b| (a.ordinal, &a.name).cmp(&(b.ordinal, &b.name)));
        })
    }

    fn rename_named_pose(
        &self,
        id: &str,
        fence: Fence,
        from: &str,
        to: &str,
    ) -> Result<(), StoreError> {
        self.named_write(id, fence, |poses| {
            if let Some(p) = poses.iter_mut().find(|p| p.name == from) {
                p.name = to.to_owned();
            }
        })
    }

    fn delete_named_pose(&self, id: &str, fence: Fence, name: &str) -> Result<(), StoreError> {
        self.named_write(id, fence, |poses| poses.retain(|p| p.name != name))
    }

    fn named_poses(&self, id: &str) -> Result<Vec<NamedPose>, StoreError> {
        Ok(self
            .sessions
            .lock()
            .get(id)
            .map(|s| s.poses.clone())
            .unwrap_or_default())
    }
}

impl MemoryStore {
    /// Changes session `id`'s named poses with `f`, fenced.
    fn named_write(
        &self,
        id: &str,
        fence: Fence,
        f: impl FnOnce(&mut Vec<NamedPose>),
    ) -> Result<(), StoreError> {
        let mut sessions = self.sessions.lock();
        let s = sessions
            .get_mut(id)
            .filter(|s| s.record.is_some())
            .ok_or_else(|| missing(id))?;
        self.check_fence(id, fence)?;
        f(&mut s.poses);
        Ok(())
    }
}
