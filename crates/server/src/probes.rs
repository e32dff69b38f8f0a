//! The probes: liveness, readiness and the Prometheus metrics.

use std::time::Duration;

use axum::extract::State;
use axum::http::header;
use axum::response::IntoResponse;

use crate::error::ApiError;
use crate::state::AppState;

/// `GET /healthz`: liveness (the process answers), with this instance's id.
pub async fn healthz(State(st): State<AppState>) -> impl IntoResponse {
    let instance = st.cluster().map(|c| c.instance.clone());
    axum::Json(serde_json::json!({"status": "ok", "instance": instance}))
}

/// `GET /healthz/ready`: readiness, the store answers within 2 s; else 503
/// `store_unavailable` (the load balancer's health check).
pub async fn ready(State(st): State<AppState>) -> Result<impl IntoResponse, ApiError> {
    st.registry.not_draining()?;
    let ping = st.store_call(|s| s.ping());
    match tokio::time::timeout(Duration::from_secs(2), ping).await {
        Ok(Ok(())) => Ok(axum::Json(serde_json::json!({"status": "ready"}))),
        Ok(Err(e)) => Err(e),
        Err(_) => Err(ApiError::StoreUnavailable("store ping timed out".into())),
    }
}

/// `GET /metrics`.
pub async fn metrics(State(st): State<AppState>) -> Result<impl IntoResponse, ApiError> {
    let m = &st.metrics;
    m.factor_cache_bytes.set(st.cache.bytes() as i64);
    m.factor_cache_entries.set(st.cache.len() as i64);
    m.factor_cache_hits.set(st.cache.hits() as i64);
    m.factor_cache_builds.set(st.cache.builds() as i64);
    st.registry.update_gauges();
    Ok((
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        m.render()?,
    ))
}
