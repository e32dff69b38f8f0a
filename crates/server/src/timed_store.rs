//! [`TimedStore`]: the server's store wrapped so that every call's wall
//! time lands in the `dend_store_seconds{op}` histogram.

use std::sync::Arc;
use std::time::{Duration, Instant};

use prometheus::HistogramVec;

use crate::store::{
    Checkpoint, Fence, JournalEntry, LeaseGrant, NamedPose, SessionRecord, Store, StoreError,
    StoredAsset,
};
use dend::mesh::Mesh;

/// A [`Store`] that times each call of the store it wraps.
pub struct TimedStore {
    inner: Arc<dyn Store>,
    seconds: HistogramVec,
}

impl TimedStore {
    /// Wraps `inner`, observing into `seconds` (label `op`).
    pub fn new(inner: Arc<dyn Store>, seconds: HistogramVec) -> Self {
        TimedStore { inner, seconds }
    }

    fn timed<T>(&self, op: &str, f: impl FnOnce(&dyn Store) -> T) -> T {
        let t0 = Instant::now();
        let r = f(&*self.inner);
        self.seconds
            .with_label_values(&[op])
            .observe(t0.elapsed().as_secs_f64());
        r
    }
}

impl Store for TimedStore {
    fn put_mesh(&self, id: &str, mesh: Arc<Mesh>) -> Result<(), StoreError> {
        self.timed("put_mesh", |s| s.put_mesh(id, mesh))
    }
    fn get_mesh(&self, id: &str) -> Result<Option<Arc<Mesh>>, StoreError> {
        self.timed("get_mesh", |s| s.get_mesh(id))
    }
    fn mesh_count(&self) -> Result<usize, StoreError> {
        self.timed("mesh_count", |s| s.mesh_count())
    }
    fn put_asset(&self, id: &str, asset: &StoredAsset) -> Result<(), StoreError> {
        self.timed("put_asset", |s| s.put_asset(id, asset))
    }
    fn get_asset(&self, id: &str) -> Result<Option<StoredAsset>, StoreError> {
        self.timed("get_asset", |s| s.get_asset(id))
    }
    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError> {
        self.timed("delete_mesh", |s| s.delete_mesh(id))
    }
    fn put_session(&self, record: &SessionRecord) -> Result<(), StoreError> {
        self.timed("put_session", |s| s.put_session(record))
    }
    fn get_session(&self, id: &str) -> Result<Option<SessionRecord>, StoreError> {
        self.timed("get_session", |s| s.get_session(id))
    }
    fn list_sessions(&self) -> Result<Vec<SessionRecord>, StoreError> {
        self.timed("list_sessions", |s| s.list_sessions())
    }
    fn delete_session(&self, id: &str) -> Result<(), StoreError> {
        self.timed("delete_session", |s| s.delete_session(id))
    }
    fn set_constraints(
        &self,
        id: &str,
        fence: Fence,
        spec: &serde_json::Value,
    ) -> Result<(), StoreError> {
        self.timed("set_constraints", |s| s.set_constraints(id, fence, spec))
    }
    fn append(&self, id: &str, fence: Fence, entries: &[JournalEntry]) -> Result<(), StoreError> {
        self.timed("append", |s| s.append(id, fence, entries))
    }
    fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError> {
        self.timed("journal", |s| s.journal(id))
    }
    fn checkpoint(&self, id: &str, fence: Fence, cp: &Checkpoint) -> Result<(), StoreError> {
        self.timed("checkpoint", |s| s.checkpoint(id, fence, cp))
    }
    fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError> {
        self.timed("get_checkpoint", |s| s.get_checkpoint(id))
    }
    fn acquire_lease(
        &self,
        id: &str,
        owner: &str,
        ttl: Duration,
    ) -> Result<LeaseGrant, StoreError> {
        self.timed("acquire_lease", |s| s.acquire_lease(id, owner, ttl))
    }
    fn renew_leases(
        &self,
        owner: &str,
        leases: &[(String, Fence)],
        ttl: Duration,
    ) -> Result<Vec<String>, StoreError> {
        self.timed("renew_leases", |s| s.renew_leases(owner, leases, ttl))
    }
    fn release_lease(&self, id: &str, owner: &str, revision: Fence) -> Result<(), StoreError> {
        self.timed("release_lease", |s| s.release_lease(id, owner, revision))
    }
    fn handoffs_wanted(&self, owner: &str) -> Result<Vec<String>, StoreError> {
        self.timed("handoffs_wanted", |s| s.handoffs_wanted(owner))
    }
    fn ping(&self) -> Result<(), StoreError> {
        self.timed("ping", |s| s.ping())
    }
    fn announce_liveness(&self, instance: &str) -> Result<(), StoreError> {
        self.inner.announce_liveness(instance)
    }
    fn put_named_pose(&self, id: &str, fence: Fence, pose: &NamedPose) -> Result<(), StoreError> {
        self.timed("put_named_pose", |s| s.put_named_pose(id, fence, pose))
    }
    fn rename_named_pose(
        &self,
        id: &str,
        fence: Fence,
        from: &str,
        to: &str,
    ) -> Result<(), StoreError> {
        self.timed("rename_named_pose", |s| {
            s.rename_named_pose(id, fence, from, to)
        })
    }
    fn delete_named_pose(&self, id: &str, fence: Fence, name: &str) -> Result<(), StoreError> {
        self.timed("delete_named_pose", |s| {
            s.delete_named_pose(id, fence, name)
        })
    }
    fn named_poses(&self, id: &str) -> Result<Vec<NamedPose>, StoreError> {
        self.timed("named_poses", |s| s.named_poses(id))
    }
}
