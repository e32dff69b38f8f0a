//! Revival is cancellation-safe: a request dropped while it re-opens a
//! stored session neither leaves the session live half-restored nor stops
//! the revival, and a later request gets that same session.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::task::Context;
use std::time::{Duration, Instant};

use super::*;
use crate::session::SessionState;
use crate::store::JournalEntry;
use crate::store::{
    Checkpoint, Fence, LeaseGrant, MemoryStore, SessionRecord, StoreError, StoredAsset,
};
use dend::mesh::Mesh;

const TOKEN: &str = "revival-token";

/// A memory store whose journal reads wait at a gate until it opens: a
/// revival holds still there, after its lease and rest build, before its
/// constraint set is restored.
#[derive(Default)]
struct GatedStore {
    inner: MemoryStore,
    /// A journal read is waiting at the gate.
    entered: AtomicBool,
    open: Mutex<bool>,
    opened: Condvar,
}

impl GatedStore {
    fn open(&self) {
        *self.open.lock().expect("gate") = true;
        self.opened.notify_all();
    }
}

/// Opens the gate when dropped: a failing test must not leave a blocking
/// thread waiting (the runtime's shutdown would wait for it).
struct OpenOnDrop(Arc<GatedStore>);

impl Drop for OpenOnDrop {
    fn drop(&mut self) {
        self.0.open();
    }
}

impl Store for GatedStore {
    fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError> {
        self.entered.store(true, Ordering::SeqCst);
        let open = self.open.lock().expect("gate");
        drop(self.opened.wait_while(open, |o| !*o).expect("gate"));
        self.inner.journal(id)
    }
    // the rest as the memory store
    fn put_mesh(&self, id: &str, mesh: Arc<Mesh>) -> Result<(), StoreError> {
        self.inner.put_mesh(id, mesh)
    }
    fn get_mesh(&self, id: &str) -> Result<Option<Arc<Mesh>>, StoreError> {
        self.inner.get_mesh(id)
    }
    fn mesh_count(&self) -> Result<usize, StoreError> {
        self.inner.mesh_count()
    }
    fn put_asset(&self, id: &str, asset: &StoredAsset) -> Result<(), StoreError> {
        self.inner.put_asset(id, asset)
    }
    fn get_asset(&self, id: &str) -> Result<Option<StoredAsset>, StoreError> {
        self.inner.get_asset(id)
    }
    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError> {
        self.inner.delete_mesh(id)
    }
    fn put_session(&self, record: &SessionRecord) -> Result<(), StoreError> {
        self.inner.put_session(record)
    }
    fn get_session(&self, id: &str) -> Result<Option<SessionRecord>, StoreError> {
        self.inner.get_session(id)
    }
    fn list_sessions(&self) -> Result<Vec<SessionRecord>, StoreError> {
        self.inner.list_sessions()
    }
    fn delete_session(&self, id: &str) -> Result<(), StoreError> {
        self.inner.delete_session(id)
    }
    fn set_constraints(
        &self,
        id: &str,
        fence: Fence,
        spec: &serde_json::Value,
    ) -> Result<(), StoreError> {
        self.inner.set_constraints(id, fence, spec)
    }
    fn append(&self, id: &str, fence: Fence, entries: &[JournalEntry]) -> Result<(), StoreError> {
        self.inner.append(id, fence, entries)
    }
    fn checkpoint(&self, id: &str, fence: Fence, cp: &Checkpoint) -> Result<(), StoreError> {
        self.inner.checkpoint(id, fence, cp)
    }
    fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError> {
        self.inner.get_checkpoint(id)
    }
    fn put_named_pose(
        &self,
        id: &str,
        fence: Fence,
        pose: &crate::store::NamedPose,
    ) -> Result<(), StoreError> {
        self.inner.put_named_pose(id, fence, pose)
    }
    fn rename_named_pose(
        &self,
        id: &str,
        fence: Fence,
        from: &str,
        to: &str,
    ) -> Result<(), StoreError> {
        self.inner.rename_named_pose(id, fence, from, to)
    }
    fn delete_named_pose(&self, id: &str, fence: Fence, name: &str) -> Result<(), StoreError> {
        self.inner.delete_named_pose(id, fence, name)
    }
    fn named_poses(&self, id: &str) -> Result<Vec<crate::store::NamedPose>, StoreError> {
        self.inner.named_poses(id)
    }
    fn acquire_lease(
        &self,
        id: &str,
        owner: &str,
        ttl: Duration,
    ) -> Result<LeaseGrant, StoreError> {
        self.inner.acquire_lease(id, owner, ttl)
    }
    fn renew_leases(
        &self,
        owner: &str,
        leases: &[(String, Fence)],
        ttl: Duration,
    ) -> Result<Vec<String>, StoreError> {
        self.inner.renew_leases(owner, leases, ttl)
    }
    fn release_lease(&self, id: &str, owner: &str, revision: Fence) -> Result<(), StoreError> {
        self.inner.release_lease(id, owner, revision)
    }
    fn handoffs_wanted(&self, owner: &str) -> Result<Vec<String>, StoreError> {
        self.inner.handoffs_wanted(owner)
    }
}

/// The gated store with a 6×6 grid and the stored session `s`, constrained
/// (bottom row fixed, top row the handle `top`), and an app state on it in
/// which `s` is not live.
fn stored() -> (Arc<GatedStore>, AppState) {
    let store = Arc::new(GatedStore::default());
    store
        .put_mesh("m", Arc::new(dend_testkit::unit_grid(6)))
        .expect("mesh");
    store
        .put_session(&SessionRecord {
            id: "s".into(),
            mesh_id: "m".into(),
            token_sha256: hex::encode(crate::auth::token_hash(TOKEN)),
            params: serde_json::to_value(Params::default()).expect("params"),
            constraints: Some(serde_json::json!({
                "fixed": [0, 1, 2, 3, 4, 5],
                "handles": [{"name": "top", "vertices": [30, 31, 32, 33, 34, 35]}]
            })),
            created_unix: 0,
        })
        .expect("session");
    let st = AppState::with_store(Config::default(), store.clone()).expect("state");
    (store, st)
}

/// Waits until `done` holds, at most 20 s.
async fn eventually(what: &str, done: impl Fn() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(20);
    while !done() {
        assert!(Instant::now() < deadline, "never: {what}");
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dropped_revival_request_leaves_the_session_whole_and_opened_once() {
    let (store, st) = stored();
    let _gate = OpenOnDrop(store.clone());
    // the request runs until the revival waits at the journal read (lease
    // taken, rest built, constraint set not yet restored), then is dropped
    let waker = futures_util::task::noop_waker();
    let mut cx = Context::from_waker(&waker);
    let mut request = Box::pin(revive(&st, "s", Some(TOKEN)));
    let deadline = Instant::now() + Duration::from_secs(20);
    while !store.entered.load(Ordering::SeqCst) {
        assert!(request.as_mut().poll(&mut cx).is_pending(), "done early");
        assert!(Instant::now() < deadline, "never reached the journal read");
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    drop(request);
    assert!(
        !st.sessions.read().contains_key("s"),
        "live before its constraint set is restored"
    );
    store.open();

    // the revival goes on without its request, and the session is whole
    eventually("the session is live", || {
        st.sessions.read().contains_key("s")
    })
    .await;
    let live = st.sessions.read().get("s").cloned().expect("live");
    let info = live.info();
    assert_ne!(
        info.state,
        SessionState::Empty,
        "live without its constraints"
    );
    assert_eq!(info.handles, ["top"]);

    // a later request gets that very session, not a second opening
    let again = revive(&st, "s", Some(TOKEN))
        .await
        .expect("revival")
        .expect("stored");
    let _client = again.join();
    assert_eq!(live.info().peers, 1, "a second actor for session `s`");
    assert_eq!(st.sessions.read().len(), 1);
}
