//! The deformation server: axum HTTP (`/v1`, JSON) + WebSocket on tokio.
//!
//! [`app`] builds the router from an [`AppState`]; [`serve`] binds, prints
//! the URL, runs until SIGINT/SIGTERM and drains gracefully. Routes live in
//! one table (`routes!`, which defines [`ROUTES`] and the router's
//! `route_list`), which a test keeps equal to `api/openapi.yaml`.

mod auth;
mod blocking;
pub mod cluster;
pub mod config;
mod curvature;
pub mod error;
pub mod fuzzing;
pub mod lease;
mod meshes;
pub mod metrics;
mod morph_export;
pub mod presets;
mod skeleton_export;

mod poses;
mod probes;
pub mod recover;
pub mod registry;
mod rests;
pub mod scheduler;
pub mod session;
mod sessions;
pub mod state;
pub mod store;
pub mod timed_store;
pub mod web;
mod wire;
pub mod ws;

use std::time::Duration;

use axum::error_handling::HandleErrorLayer;
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{header, Uri};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::MethodRouter;
use axum::{BoxError, Router};
use tower::ServiceBuilder;
use tower_http::trace::TraceLayer;

pub use config::Config;
pub use error::ApiError;
pub use metrics::Metrics;
pub use state::AppState;

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
    "/healthz" => [get(probes::healthz)],
    "/healthz/ready" => [get(probes::ready)],
    "/metrics" => [get(probes::metrics)],
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

/// Closes sessions idle for longer than the configured timeout, every
/// `period`, until the process ends.
pub fn spawn_idle_reaper(state: AppState, period: Duration) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(period);
        loop {
            let _ = tick.tick().await;
            for s in state.registry.idle(state.config.idle_timeout()) {
                tracing::info!(session = s.id(), "closing idle session");
                state.registry.close(&s).await;
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
    if let Some(c) = state.cluster() {
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
