//! [`SessionRegistry`]: the one owner of this instance's live sessions.
//!
//! It holds the map of live sessions by id and is the only code that reads
//! or changes it. Everything that opens, finds or closes a session asks it:
//! the HTTP and WebSocket handlers ([`SessionRegistry::find`],
//! [`SessionRegistry::create`], [`SessionRegistry::close`]), the lease
//! renewer and the drain (`lease.rs`: [`SessionRegistry::leases`],
//! [`SessionRegistry::drop_local`], [`SessionRegistry::hand_over`]), the
//! idle reaper and the metrics. Admission (the draining flag, the solver
//! queue's limit, `max_sessions`) is checked here, and the live-session
//! gauges are set here whenever the map changes.
//!
//! A session becomes live by one path, [`SessionRegistry::open`] (in
//! `open.rs`), whether it was just created or is revived from the store:
//! spawn its actor, restore its stored constraint set with the recovered
//! targets, insert it if there is room.

mod open;

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Weak};
use std::time::Duration;

use parking_lot::{Mutex, RwLock};

use crate::blocking::store_call;
use crate::cluster::Cluster;
use crate::config::Config;
use crate::error::ApiError;
use crate::metrics::Metrics;
use crate::rests::Rests;
use crate::scheduler::Scheduler;
use crate::session::{SessionHandle, SessionOptions};
use crate::store::{Fence, Store};
use dend::deform::FactorCache;

/// What the registry needs to open sessions.
#[derive(Clone)]
pub struct RegistryParts {
    /// The configuration (limits, solver options).
    pub config: Arc<Config>,
    /// Meshes and sessions storage.
    pub store: Arc<dyn Store>,
    /// The factor cache shared by all sessions.
    pub cache: Arc<FactorCache>,
    /// Session gauges and counters; the sessions' solver statistics.
    pub metrics: Arc<Metrics>,
    /// Runs every session's solves.
    pub scheduler: Arc<Scheduler>,
    /// Rest precomputations shared by a mesh's sessions.
    pub rests: Arc<Rests>,
    /// This instance in a shared-store deployment (None: no leases).
    pub cluster: Option<Arc<Cluster>>,
}

/// The live sessions of this instance, and every way in and out of them.
pub struct SessionRegistry {
    parts: RegistryParts,
    /// Live sessions by id.
    live: RwLock<HashMap<String, SessionHandle>>,
    /// Per session id, held from its lease to its insertion among the live
    /// ones, so that two requests reviving one session take one lease.
    open_locks: Mutex<HashMap<String, Weak<tokio::sync::Mutex<()>>>>,
    /// Set on SIGTERM (see `lease::drain`): not ready, no new sessions.
    draining: AtomicBool,
}

impl SessionRegistry {
    /// An empty registry.
    pub fn new(parts: RegistryParts) -> Self {
        SessionRegistry {
            parts,
            live: RwLock::new(HashMap::new()),
            open_locks: Mutex::new(HashMap::new()),
            draining: AtomicBool::new(false),
        }
    }

    /// This instance in a shared-store deployment.
    pub fn cluster(&self) -> Option<&Arc<Cluster>> {
        self.parts.cluster.as_ref()
    }

    /// The live session `id` as held here, fenced or not.
    pub fn get(&self, id: &str) -> Option<SessionHandle> {
        self.live.read().get(id).cloned()
    }

    /// Whether session `id` is live here (fenced or not).
    pub fn contains(&self, id: &str) -> bool {
        self.live.read().contains_key(id)
    }

    /// How many sessions are live here.
    pub fn len(&self) -> usize {
        self.live.read().len()
    }

    /// Whether no session is live here.
    pub fn is_empty(&self) -> bool {
        self.live.read().is_empty()
    }

    /// Every live session.
    pub fn all(&self) -> Vec<SessionHandle> {
        self.live.read().values().cloned().collect()
    }

    /// How many live sessions deform mesh `mesh_id`.
    pub fn on_mesh(&self, mesh_id: &str) -> usize {
        self.live
            .read()
            .values()
            .filter(|s| s.info().mesh_id == mesh_id)
            .count()
    }

    /// The live sessions idle for longer than `timeout`.
    pub fn idle(&self, timeout: Duration) -> Vec<SessionHandle> {
        self.live
            .read()
            .values()
            .filter(|s| s.is_idle(timeout))
            .cloned()
            .collect()
    }

    /// The leases this instance holds: each unfenced live session with its
    /// fence.
    pub fn leases(&self) -> Vec<(String, Fence)> {
        self.live
            .read()
            .values()
            .filter(|s| !s.is_fenced())
            .map(|s| (s.id().to_owned(), s.fence()))
            .collect()
    }

    /// Sets the live-session gauges (`sessions`, `sessions_owned`). A
    /// fenced session (a store write of its found the lease another
    /// instance's) stays live here until its clients leave, but is no
    /// longer owned: the lease renewal skips it, so counting it kept the
    /// gauge at the sessions a resumed frozen instance had lost.
    pub fn update_gauges(&self) {
        let (n, owned) = {
            let live = self.live.read();
            (live.len(), live.values().filter(|s| !s.is_fenced()).count())
        };
        self.parts.metrics.sessions.set(n as i64);
        self.parts.metrics.sessions_owned.set(owned as i64);
    }

    /// Starts a drain: from now on no session is created or opened here
    /// and readiness answers 503 `draining`.
    pub fn start_draining(&self) {
        self.draining.store(true, Ordering::Relaxed);
    }

    /// 503 `draining` once a drain started.
    pub fn not_draining(&self) -> Result<(), ApiError> {
        if self.draining.load(Ordering::Relaxed) {
            return Err(ApiError::Draining);
        }
        Ok(())
    }

    /// Admission control: refuses a new session (503 `overloaded`) while
    /// `admission_waiting_sessions` sessions or more wait for a solver
    /// worker (docs/deployment.md), and any while draining.
    pub fn admit(&self) -> Result<(), ApiError> {
        self.not_draining()?;
        let config = &self.parts.config;
        let limit = config.admission_limit(self.parts.scheduler.workers());
        let waiting = self.parts.scheduler.waiting();
        if waiting >= limit {
            self.parts.metrics.sessions_refused.inc();
            return Err(ApiError::Overloaded { waiting, limit });
        }
        Ok(())
    }

    /// 503 `too_many_sessions` when `max_sessions` sessions are live.
    fn check_room(&self) -> Result<(), ApiError> {
        let max = self.parts.config.max_sessions;
        if self.len() >= max {
            return Err(ApiError::TooManySessions(max));
        }
        Ok(())
    }

    /// Inserts `handle` among the live sessions if there is room (checked
    /// under the map's lock, so that concurrent openings cannot both take
    /// the last slot).
    fn insert_if_room(&self, handle: &SessionHandle) -> Result<(), ApiError> {
        let max = self.parts.config.max_sessions;
        {
            let mut live = self.live.write();
            if live.len() >= max {
                return Err(ApiError::TooManySessions(max));
            }
            let _ = live.insert(handle.id().to_owned(), handle.clone());
        }
        self.update_gauges();
        Ok(())
    }

    /// The options of a session opened on this instance under `fence`.
    fn session_options(&self, fence: Fence) -> SessionOptions {
        let p = &self.parts;
        SessionOptions {
            cache: p.cache.clone(),
            store: p.store.clone(),
            observer: p.metrics.clone(),
            iters_per_frame: p.config.iters_per_frame,
            preview_above_ms: p.config.preview_above_ms,
            build_wait: p.config.build_wait(),
            scheduler: p.scheduler.clone(),
            fence,
        }
    }

    /// The opening lock of session `id` (see `open_locks`).
    fn open_lock(&self, id: &str) -> Arc<tokio::sync::Mutex<()>> {
        let mut locks = self.open_locks.lock();
        if let Some(l) = locks.get(id).and_then(Weak::upgrade) {
            return l;
        }
        locks.retain(|_, w| w.strong_count() > 0);
        let l = Arc::new(tokio::sync::Mutex::new(()));
        let _ = locks.insert(id.to_owned(), Arc::downgrade(&l));
        l
    }

    /// Stops a session and forgets it, store included.
    pub async fn close(&self, s: &SessionHandle) {
        let _ = self.live.write().remove(s.id());
        s.close().await;
        let key = s.id().to_owned();
        if let Err(e) = store_call(&self.parts.store, move |st| st.delete_session(&key)).await {
            tracing::error!(session = s.id(), error = %e, "deleting session from the store failed");
        }
        self.update_gauges();
    }

    /// Forgets a live session here without touching the store (its lease is
    /// another instance's now).
    pub async fn drop_local(&self, s: &SessionHandle) {
        let removed = {
            let mut live = self.live.write();
            match live.get(s.id()) {
                Some(l) if l.fence() == s.fence() => live.remove(s.id()),
                _ => None,
            }
        };
        if removed.is_some() {
            s.close().await;
            self.update_gauges();
        }
    }

    /// Hands session `h` over: closes it here, its clients told to
    /// reconnect at once (they reach the instance the load balancer routes
    /// them to now), and releases its lease so that instance takes it at
    /// once. Nothing to do without a shared store.
    pub async fn hand_over(&self, h: &SessionHandle) {
        let Some(cluster) = self.parts.cluster.clone() else {
            return;
        };
        h.mark_moving();
        self.drop_local(h).await;
        let (fence, id) = (h.fence(), h.id().to_owned());
        if let Err(e) = store_call(&self.parts.store, move |s| {
            s.release_lease(&id, &cluster.instance, fence)
        })
        .await
        {
            tracing::warn!(error = %e, "releasing a handed-over lease failed");
        }
        self.parts.metrics.leases_handed_over.inc();
    }
}

#[cfg(test)]
#[path = "revive_tests.rs"]
mod tests;
