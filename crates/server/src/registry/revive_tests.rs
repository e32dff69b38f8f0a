//! Revival is cancellation-safe: a request dropped while it re-opens a
//! stored session neither leaves the session live half-restored nor stops
//! the revival, and a later request gets that same session.

use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::task::Context;
use std::time::{Duration, Instant};

use crate::session::SessionState;
use crate::state::AppState;
use crate::store::{with_faults, MemoryStore, MeshStore, SessionLog, SessionRecord};
use crate::Config;
use dend::deform::Params;

const TOKEN: &str = "revival-token";

/// A gate that a memory store's journal reads wait at until it opens: a
/// revival holds still there, after its lease and rest build, before its
/// constraint set is restored.
#[derive(Default)]
struct Gate {
    /// A journal read is waiting at the gate.
    entered: AtomicBool,
    open: Mutex<bool>,
    opened: Condvar,
}

impl Gate {
    fn open(&self) {
        *self.open.lock().expect("gate") = true;
        self.opened.notify_all();
    }

    fn pass(&self) {
        self.entered.store(true, Ordering::SeqCst);
        let open = self.open.lock().expect("gate");
        drop(self.opened.wait_while(open, |o| !*o).expect("gate"));
    }
}

/// Opens the gate when dropped: a failing test must not leave a blocking
/// thread waiting (the runtime's shutdown would wait for it).
struct OpenOnDrop(Arc<Gate>);

impl Drop for OpenOnDrop {
    fn drop(&mut self) {
        self.0.open();
    }
}

/// A gated memory store with a 6×6 grid and the stored session `s`, constrained
/// (bottom row fixed, top row the handle `top`), and an app state on it in
/// which `s` is not live.
fn stored() -> (Arc<Gate>, AppState) {
    let gate = Arc::new(Gate::default());
    let store = Arc::new(MemoryStore::new());
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
    let g = gate.clone();
    let gated = with_faults(store, move |call| {
        if call.op == "journal" {
            g.pass();
        }
        Ok(())
    });
    let st = AppState::with_store(Config::default(), Arc::new(gated)).expect("state");
    (gate, st)
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
    let mut request = Box::pin(st.registry.revive("s", Some(TOKEN)));
    let deadline = Instant::now() + Duration::from_secs(20);
    while !store.entered.load(Ordering::SeqCst) {
        assert!(request.as_mut().poll(&mut cx).is_pending(), "done early");
        assert!(Instant::now() < deadline, "never reached the journal read");
        tokio::time::sleep(Duration::from_millis(1)).await;
    }
    drop(request);
    assert!(
        !st.registry.contains("s"),
        "live before its constraint set is restored"
    );
    store.open();

    // the revival goes on without its request, and the session is whole
    eventually("the session is live", || st.registry.contains("s")).await;
    let live = st.registry.get("s").expect("live");
    let info = live.info();
    assert_ne!(
        info.state,
        SessionState::Empty,
        "live without its constraints"
    );
    assert_eq!(info.handles, ["top"]);

    // a later request gets that very session, not a second opening
    let again = st
        .registry
        .revive("s", Some(TOKEN))
        .await
        .expect("revival")
        .expect("stored");
    let _client = again.join();
    assert_eq!(live.info().peers, 1, "a second actor for session `s`");
    assert_eq!(st.registry.len(), 1);
}
