//! The deformation server: axum HTTP (`/v1`, JSON) + WebSocket on tokio.
//!
//! [`app`] builds the router from an [`AppState`]; [`serve`] binds, prints
//! the URL, runs until SIGINT/SIGTERM and drains gracefully. Routes live in
//! one table (`routes!`, which defines [`ROUTES`] and the router's
//! `route_list`), which a test keeps equal to `api/openapi.yaml`.

mod auth;
pub mod config;
mod curvature;
pub mod error;
pub mod fuzzing;
pub mod lease;
mod meshes;
pub mod metrics;
mod morph_export;
pub mod presets;

mod poses;
pub mod recover;
pub mod scheduler;
pub mod session;
mod sessions;
pub mod store;
pub mod timed_store;
pub mod web;
pub mod ws;

use std::collections::HashMap;
use std::sync::{Arc, Weak};
use std::time::Duration;

use axum::error_handling::HandleErrorLayer;
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{header, Uri};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::MethodRouter;
use axum::{BoxError, Router};
use parking_lot::{Mutex, RwLock};
use tower::ServiceBuilder;
use tower_http::trace::TraceLayer;

pub use config::Config;
pub use error::ApiError;
pub use metrics::Metrics;

use crate::session::{SessionHandle, SessionOptions};
use crate::store::{MemoryStore, Store};
use dend::deform::{FactorCache, Rest, SolveOptions};

/// Shared server state: cheap to clone (`Arc` fields).
#[derive(Clone)]
pub struct AppState {
    /// The configuration.
    pub config: Arc<Config>,
    /// Meshes and sessions storage.
    pub store: Arc<dyn Store>,
    /// The factor cache shared by all sessions.
    pub cache: Arc<FactorCache>,
    /// Prometheus metrics.
    pub metrics: Arc<Metrics>,
    /// Runs every session's solves, fairly between sessions.
    pub scheduler: Arc<scheduler::Scheduler>,
    /// Set on SIGTERM (see [`lease::drain`]): not ready, no new sessions.
    pub draining: Arc<std::sync::atomic::AtomicBool>,
    /// Live sessions by id.
    pub sessions: Arc<RwLock<HashMap<String, SessionHandle>>>,
    /// Rest precomputations by mesh id, shared by that mesh's sessions.
    rests: Arc<Mutex<HashMap<String, Weak<Rest>>>>,
    /// Ids of every rest built per mesh id (factors are cached by rest id):
    /// deleting a mesh evicts their factors.
    rest_ids: Arc<Mutex<HashMap<String, Vec<u64>>>>,
    /// Held across an upload's `max_meshes` check and its insert, so that
    /// concurrent uploads cannot both pass the check for the last slot.
    mesh_admission: Arc<Mutex<()>>,
    /// This instance in a shared-store deployment (None: embedded store,
    /// no leases); see [`lease`].
    pub cluster: Option<Arc<lease::Cluster>>,
    /// Per session id, held from its lease to its insertion among the live
    /// ones, so that two requests reviving one session take one lease.
    open_locks: Arc<Mutex<HashMap<String, Weak<tokio::sync::Mutex<()>>>>>,
}

impl AppState {
    /// Runs `f` on the store from tokio's blocking pool: the SQLite store's
    /// calls block (a mutex and an fsync per write) and must not hold an
    /// async worker thread that other sessions' requests and frames need.
    pub(crate) async fn store_call<T, F>(&self, f: F) -> Result<T, ApiError>
    where
        F: FnOnce(&dyn Store) -> Result<T, crate::store::StoreError> + Send + 'static,
        T: Send + 'static,
    {
        let store = self.store.clone();
        tokio::task::spawn_blocking(move || f(&*store))
            .await
            .map_err(|e| ApiError::Internal(format!("store task: {e}")))?
            .map_err(ApiError::from)
    }

    /// The options of a session opened on this instance under `fence`.
    pub(crate) fn session_options(&self, fence: crate::store::Fence) -> SessionOptions {
        SessionOptions {
            cache: self.cache.clone(),
            store: self.store.clone(),
            observer: self.metrics.clone(),
            iters_per_frame: self.config.iters_per_frame,
            preview_above_ms: self.config.preview_above_ms,
            build_wait: self.config.build_wait(),
            scheduler: self.scheduler.clone(),
            fence,
        }
    }

    /// Admission control: refuses a new session (503 `overloaded`) while
    /// `admission_waiting_sessions` sessions or more wait for a solver
    /// worker (docs/deployment.md).
    pub(crate) fn admit(&self) -> Result<(), ApiError> {
        self.not_draining()?;
        let limit = self.config.admission_limit(self.scheduler.workers());
        let waiting = self.scheduler.waiting();
        if waiting >= limit {
            self.metrics.sessions_refused.inc();
            return Err(ApiError::Overloaded { waiting, limit });
        }
        Ok(())
    }

    /// 503 `draining` once SIGTERM started a drain ([`lease::drain`]).
    pub(crate) fn not_draining(&self) -> Result<(), ApiError> {
        if self.draining.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(ApiError::Draining);
        }
        Ok(())
    }

    /// The opening lock of session `id` (see `open_locks`).
    pub(crate) fn open_lock(&self, id: &str) -> Arc<tokio::sync::Mutex<()>> {
        let mut locks = self.open_locks.lock();
        if let Some(l) = locks.get(id).and_then(Weak::upgrade) {
            return l;
        }
        locks.retain(|_, w| w.strong_count() > 0);
        let l = Arc::new(tokio::sync::Mutex::new(()));
        let _ = locks.insert(id.to_owned(), Arc::downgrade(&l));
        l
    }

    /// State with the embedded in-memory store.
    pub fn new(config: Config) -> anyhow::Result<Self> {
        Self::with_store(config, Arc::new(MemoryStore::new()))
    }

    /// State with a given store (timed into the `dend_store_seconds`
    /// histogram). A configured shared store (`config.store`) turns
    /// session leases on.
    pub fn with_store(config: Config, store: Arc<dyn Store>) -> anyhow::Result<Self> {
        let metrics = Arc::new(Metrics::new()?);
        let store: Arc<dyn Store> = Arc::new(timed_store::TimedStore::new(
            store,
            metrics.store_seconds.clone(),
        ));
        let scheduler = Arc::new(scheduler::Scheduler::new(
            config.solver_threads,
            Some(scheduler::SchedulerMetrics {
                delay: metrics.schedule_delay_seconds.clone(),
                depth: metrics.solve_queue_depth.clone(),
            }),
        ));
        Ok(AppState {
            scheduler,
            draining: Arc::new(std::sync::atomic::AtomicBool::new(false)),
            cluster: lease::Cluster::from_config(&config),
            open_locks: Arc::new(Mutex::new(HashMap::new())),
            cache: Arc::new(FactorCache::with_options(
                config.factor_cache_bytes,
                SolveOptions {
                    precision: config.factor_precision,
                    ..SolveOptions::default()
                },
            )),
            config: Arc::new(config),
            store,
            metrics,
            sessions: Arc::new(RwLock::new(HashMap::new())),
            rests: Arc::new(Mutex::new(HashMap::new())),
            rest_ids: Arc::new(Mutex::new(HashMap::new())),
            mesh_admission: Arc::new(Mutex::new(())),
        })
    }
}

/// Defines [`ROUTES`] and `route_list` from one table of
/// `"path" => [method(handler), ..]` entries, so that the router and the
/// route list the OpenAPI test reads cannot disagree.
macro_rules! routes {
    ($($path:literal => [$($method:ident($handler:path)),+ $(,)?]),* $(,)?) => {
        /// Every route: (path, methods). `api/openapi.yaml` must list exactly these.
        pub const ROUTES: &[(&str, &[&str])] = &[$(($path, &[$(stringify!($method)),+])),*];

        /// Every route with its handlers.
        fn route_list() -> Vec<(&'static str, MethodRouter<AppState>)> {
            vec![$(($path, MethodRouter::new()$(.$method($handler))+)),*]
        }
    };
}

routes! {
    "/healthz" => [get(healthz)],
    "/healthz/ready" => [get(ready)],
    "/metrics" => [get(metrics::render)],
    "/v1/presets" => [get(presets::get)],
    "/v1/meshes" => [post(meshes::upload)],
    "/v1/meshes/generate" => [post(meshes::generate)],
    "/v1/meshes/{id}" => [get(meshes::info), delete(meshes::remove)],
    "/v1/sessions" => [post(sessions::create)],
    "/v1/sessions/{id}" => [get(sessions::info), delete(sessions::remove)],
    "/v1/sessions/{id}/constraints" => [put(sessions::set_constraints)],
    "/v1/sessions/{id}/drag" => [post(sessions::drag)],
    "/v1/sessions/{id}/pose" => [get(sessions::pose)],
    "/v1/sessions/{id}/export" => [get(sessions::export)],
    "/v1/sessions/{id}/curvature" => [get(curvature::curvature)],
    "/v1/sessions/{id}/undo" => [post(sessions::undo)],
    "/v1/sessions/{id}/redo" => [post(sessions::redo)],
    "/v1/sessions/{id}/reset" => [post(sessions::reset)],
    "/v1/sessions/{id}/ws" => [get(ws::upgrade)],
    "/v1/sessions/{id}/poses" => [get(poses::list), post(poses::save)],
    "/v1/sessions/{id}/poses/{name}" => [get(poses::get), patch(poses::rename), delete(poses::remove)],
    "/v1/sessions/{id}/poses/{name}/restore" => [post(poses::restore)],
}

/// The router with every route and middleware (tracing, request timeout,
/// body limit answered from `Content-Length` before reading the body).
pub fn app(state: AppState) -> Router {
    let mut router = Router::new();
    for (path, mr) in route_list() {
        router = router.route(path, mr);
    }
    // a method a route does not serve: JSON 405 (axum's own is empty)
    let router = router.method_not_allowed_fallback(error::method_not_allowed);
    let timeout = state.config.request_timeout();
    router
        // The web client's static files (`/`, outside the `/v1` API).
        .merge(web::router())
        .fallback(|uri: Uri| async move { ApiError::RouteNotFound(uri.path().to_owned()) })
        .layer(
            ServiceBuilder::new()
                .layer(TraceLayer::new_for_http())
                .layer(HandleErrorLayer::new(|e: BoxError| async move {
                    if e.is::<tower::timeout::error::Elapsed>() {
                        ApiError::Timeout
                    } else {
                        ApiError::Internal(e.to_string())
                    }
                }))
                .timeout(timeout)
                .layer(axum::middleware::from_fn_with_state(
                    state.clone(),
                    content_length_limit,
                ))
                .layer(DefaultBodyLimit::max(state.config.max_upload_bytes)),
        )
        .with_state(state)
}

/// Rejects a declared `Content-Length` over the limit before any body byte
/// is read (bodies without one are cut off while streaming by
/// `DefaultBodyLimit`).
async fn content_length_limit(State(st): State<AppState>, req: Request, next: Next) -> Response {
    let limit = st.config.max_upload_bytes;
    let declared = req
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    match declared {
        Some(n) if n > limit as u64 => ApiError::PayloadTooLarge(limit).into_response(),
        _ => next.run(req).await,
    }
}

/// `GET /healthz`: liveness (the process answers), with this instance's id.
async fn healthz(State(st): State<AppState>) -> impl IntoResponse {
    let instance = st.cluster.as_ref().map(|c| c.instance.clone());
    axum::Json(serde_json::json!({"status": "ok", "instance": instance}))
}

/// `GET /healthz/ready`: readiness, the store answers within 2 s; else 503
/// `store_unavailable` (the load balancer's health check).
async fn ready(State(st): State<AppState>) -> Result<impl IntoResponse, ApiError> {
    st.not_draining()?;
    let ping = st.store_call(|s| s.ping());
    match tokio::time::timeout(Duration::from_secs(2), ping).await {
        Ok(Ok(())) => Ok(axum::Json(serde_json::json!({"status": "ready"}))),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(ApiError::StoreUnavailable("store ping timed out".into())),
    }
}

/// Closes sessions idle for longer than the configured timeout, every
/// `period`, until the process ends.
pub fn spawn_idle_reaper(state: AppState, period: Duration) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(period);
        loop {
            let _ = tick.tick().await;
            let idle: Vec<SessionHandle> = {
                let timeout = state.config.idle_timeout();
                state
                    .sessions
                    .read()
                    .values()
                    .filter(|s| s.is_idle(timeout))
                    .cloned()
                    .collect()
            };
            for s in idle {
                tracing::info!(session = s.id(), "closing idle session");
                sessions::close_session(&state, &s).await;
            }
        }
    })
}

/// Serves `app` on an already bound `listener` until the listener fails
/// (no signal handling: for embedding the server in another program or a
/// test; [`serve`] is the binary's entry point).
pub async fn serve_on(listener: tokio::net::TcpListener, app: Router) -> std::io::Result<()> {
    axum::serve(no_delay(listener), app).await
}

/// The listener with `TCP_NODELAY` on every accepted connection. Without
/// it, a windowed WebSocket client's small messages (an ack, then the
/// next drag) meet Nagle's algorithm and the peer's delayed ACK: frames
/// came about every 40 ms (camel, window 1: 24 frames/s, drag→frame p50
/// 69 ms, against 13 ms for the same drags without a window).
pub fn no_delay(
    listener: tokio::net::TcpListener,
) -> impl axum::serve::Listener<Addr = std::net::SocketAddr> {
    use axum::serve::ListenerExt;
    listener.tap_io(|tcp| {
        if let Err(e) = tcp.set_nodelay(true) {
            tracing::debug!(%e, "TCP_NODELAY not set on a connection");
        }
    })
}

/// Binds `config.addr`, prints `listening on http://ADDR`, and serves until
/// SIGINT or SIGTERM; then, with a shared store, hands its sessions over to
/// the other instances ([`lease::drain`]) and drains open requests.
pub async fn serve(config: Config) -> anyhow::Result<()> {
    let listener = tokio::net::TcpListener::bind(config.addr).await?;
    let addr = listener.local_addr()?;
    let store = recover::open_store(&config)?;
    let state = AppState::with_store(config, store)?;
    let _reaper = spawn_idle_reaper(state.clone(), Duration::from_secs(10));
    let _renewer = lease::spawn_renewer(state.clone());
    if let Some(c) = &state.cluster {
        // owner liveness (docs/deployment.md): others take this instance's
        // leases over as soon as it is gone, not when they expire
        let (store, instance) = (state.store.clone(), c.instance.clone());
        tokio::task::spawn_blocking(move || store.announce_liveness(&instance)).await??;
        println!(
            "instance {} (shared store, session leases of {:?})",
            c.instance, c.ttl
        );
    }
    println!("listening on http://{addr}");
    let drained = state.clone();
    axum::serve(no_delay(listener), app(state.clone()))
        .with_graceful_shutdown(async move {
            shutdown_signal().await;
            lease::drain(&drained).await;
        })
        .await?;
    lease::release_all(&state).await;
    Ok(())
}

/// Resolves on SIGINT (Ctrl-C) or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        if tokio::signal::ctrl_c().await.is_err() {
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                let _ = s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! { _ = ctrl_c => {}, _ = term => {} }
    tracing::info!("shutting down");
}

/// Rest precomputation of a mesh, shared while any session uses it.
pub(crate) async fn rest_for(st: &AppState, mesh_id: &str) -> Result<Arc<Rest>, ApiError> {
    if let Some(r) = st.rests.lock().get(mesh_id).and_then(Weak::upgrade) {
        return Ok(r);
    }
    let id = mesh_id.to_owned();
    let mesh = st
        .store_call(move |s| s.get_mesh(&id))
        .await?
        .ok_or_else(|| ApiError::MeshNotFound(mesh_id.to_owned()))?;
    let rest = tokio::task::spawn_blocking(move || Rest::new((*mesh).clone()))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))??;
    let rest = Arc::new(rest);
    {
        // the elastic solver's coarse level, off the first settle's path
        let rest = rest.clone();
        tokio::task::spawn_blocking(move || rest.prepare_coarse_level());
    }
    let mut rests = st.rests.lock();
    // Sessions created together may have built it concurrently: keep the
    // first one, so that they share its id and hence their factors.
    if let Some(r) = rests.get(mesh_id).and_then(Weak::upgrade) {
        return Ok(r);
    }
    rests.retain(|_, w| w.strong_count() > 0);
    let _ = rests.insert(mesh_id.to_owned(), Arc::downgrade(&rest));
    st.rest_ids
        .lock()
        .entry(mesh_id.to_owned())
        .or_default()
        .push(rest.id());
    Ok(rest)
}

/// Forgets mesh `mesh_id`'s rest precomputations and evicts their cached
/// factors ([`FactorCache::evict_rest`]); returns how many rests it had.
pub(crate) fn evict_mesh(st: &AppState, mesh_id: &str) -> usize {
    let _ = st.rests.lock().remove(mesh_id);
    let ids = st.rest_ids.lock().remove(mesh_id).unwrap_or_default();
    for &id in &ids {
        st.cache.evict_rest(id);
    }
    ids.len()
}
