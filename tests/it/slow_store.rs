//! A store made slow on purpose for one session does not delay another
//! session's frames: the session actor's store writes (checkpoint,
//! constraints) leave the async worker (`block_in_place`) while they block.

use std::sync::Arc;
use std::time::{Duration, Instant};

use dend::mesh::Mesh;
use dend_client::ws::{DeltaJson, ServerMsg};
use dend_client::{Client, ClientError, WsEvent};
use dend_server::store::{
    Checkpoint, Fence, JournalEntry, LeaseGrant, MemoryStore, SessionRecord, Store, StoreError,
    StoredAsset,
};
use dend_server::Config;
use dend_testkit::server::{grid, grid_constraints, start_with_store};
use parking_lot::Mutex;
use serde_json::json;

/// A memory store whose writes for one session sleep `delay` first.
struct SlowStore {
    inner: MemoryStore,
    slow: Mutex<Option<String>>,
    delay: Duration,
    /// How long `mesh_count` takes (a slow store widens upload races).
    count_delay: Duration,
}

impl SlowStore {
    fn nap(&self, id: &str) {
        if self.slow.lock().as_deref() == Some(id) {
            std::thread::sleep(self.delay);
        }
    }
}

impl Store for SlowStore {
    fn put_mesh(&self, id: &str, mesh: Arc<Mesh>) -> Result<(), StoreError> {
        self.inner.put_mesh(id, mesh)
    }
    fn get_mesh(&self, id: &str) -> Result<Option<Arc<Mesh>>, StoreError> {
        self.inner.get_mesh(id)
    }
    fn mesh_count(&self) -> Result<usize, StoreError> {
        std::thread::sleep(self.count_delay);
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
        self.nap(id);
        self.inner.set_constraints(id, fence, spec)
    }
    fn append(&self, id: &str, fence: Fence, entries: &[JournalEntry]) -> Result<(), StoreError> {
        self.inner.append(id, fence, entries)
    }
    fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError> {
        self.inner.journal(id)
    }
    fn checkpoint(
        &self,
        id: &str,
        fence: Fence,
        checkpoint: &Checkpoint,
    ) -> Result<(), StoreError> {
        self.nap(id);
        self.inner.checkpoint(id, fence, checkpoint)
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
    fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError> {
        self.inner.get_checkpoint(id)
    }
}

/// One async worker thread, so that a write blocking it would stop every
/// other task: session A's checkpoints take 1.5 s each while session B is
/// dragged over WebSocket; B's frames keep coming.
#[tokio::test(flavor = "multi_thread", worker_threads = 1)]
async fn a_slow_store_for_one_session_does_not_stall_another() -> Result<(), ClientError> {
    let store = Arc::new(SlowStore {
        inner: MemoryStore::new(),
        slow: Mutex::new(None),
        delay: Duration::from_millis(1500),
        count_delay: Duration::ZERO,
    });
    let (base, _state) = start_with_store(Config::default(), store.clone()).await;

    let c = Client::new(&base);
    let (p, t) = grid(8);
    let mesh = c.upload_json(&p, &t).await?;
    let a = c.create_session(&mesh.id, json!({})).await?;
    let b = c.create_session(&mesh.id, json!({})).await?;
    for s in [&a, &b] {
        s.set_constraints(&grid_constraints(8)).await?;
        s.wait_ready(Duration::from_secs(60)).await?;
    }
    let mut ws = b.connect().await?;
    let _ = ws.frame_acking(0, true).await?;
    *store.slow.lock() = Some(a.id.clone());

    // A: drags answered after a settle, each followed by a slow checkpoint
    let slow = tokio::spawn(async move {
        for k in 0..3 {
            let d = DeltaJson::translate([0.0, 0.0, 0.1 * (k + 1) as f64]);
            a.drag(0, d, Some(200)).await?;
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
        Ok::<_, ClientError>(())
    });
    // B: drag after drag while A's checkpoints block
    let start = Instant::now();
    let mut worst = Duration::ZERO;
    let mut seq = 0;
    while start.elapsed() < Duration::from_secs(3) {
        seq += 1;
        let sent = Instant::now();
        ws.drag(0, [0.0, 0.01, 0.0], None, seq).await?;
        loop {
            match ws.next().await? {
                WsEvent::Frame(h, _) if h.ack_seq >= seq => break,
                WsEvent::Event(e @ ServerMsg::Error { .. }) => panic!("drag {seq} refused: {e:?}"),
                WsEvent::Closed(c) => panic!("closed ({c:?}) waiting for drag {seq}"),
                _ => {}
            }
        }
        worst = worst.max(sent.elapsed());
        // a person's pace, under the server's message rate limit (a tiny
        // mesh answers a drag in well under the limit's 2 ms)
        tokio::time::sleep(Duration::from_millis(4)).await;
    }
    slow.await.expect("join")?;
    assert!(seq > 5, "only {seq} drags of B in 3 s");
    assert!(
        worst < Duration::from_millis(750),
        "B waited {worst:?} for a frame while A's store was slow (1.5 s writes)"
    );
    Ok(())
}

/// Uploads racing for the last `max_meshes` slots on a store whose count
/// takes 50 ms: exactly the limit is stored, every other upload gets 503
/// (the check and the insert are one admission step; with them apart all
/// twelve uploads read the same count and pass).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn concurrent_uploads_never_exceed_max_meshes() {
    let store = Arc::new(SlowStore {
        inner: MemoryStore::new(),
        slow: Mutex::new(None),
        delay: Duration::ZERO,
        count_delay: Duration::from_millis(50),
    });
    let config = Config {
        max_meshes: 3,
        ..Config::default()
    };
    let (base, _state) = start_with_store(config, store).await;
    let (p, t) = grid(4);
    let body = json!({"positions": p, "triangles": t});
    let http = reqwest::Client::new();
    let uploads: Vec<_> = (0..12)
        .map(|_| {
            let (http, url, body) = (http.clone(), format!("{base}/v1/meshes"), body.clone());
            tokio::spawn(async move {
                http.post(url)
                    .json(&body)
                    .send()
                    .await
                    .map(|r| r.status().as_u16())
            })
        })
        .collect();
    let mut statuses = Vec::new();
    for u in uploads {
        statuses.push(u.await.expect("task").expect("request"));
    }
    let created = statuses.iter().filter(|&&s| s == 201).count();
    let refused = statuses.iter().filter(|&&s| s == 503).count();
    assert_eq!((created, refused), (3, 9), "{statuses:?}");
}
