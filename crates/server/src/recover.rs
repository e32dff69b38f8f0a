//! Sessions outlive the process: choosing the store and re-opening stored
//! sessions after a restart.
//!
//! At start-up [`open_store`] opens the configured store and lists its
//! sessions (logging how many, and failing on a corrupt one). Sessions are
//! re-opened lazily: the first request naming a stored session that is not
//! live ([`revive`]) rebuilds its [`Rest`](dend::deform::Rest), spawns its
//! actor and, when it had constraints, restores them with the recovered
//! targets (last checkpoint + every journaled drag after it) and the
//! checkpoint pose as the warm start. The session then goes `building` →
//! `ready` exactly as after `PUT constraints` (clients get the `state` and
//! `ready` events) and accepts drags when ready.

use std::sync::Arc;

use super::error::ApiError;
use super::{rest_for, AppState, Config};
use crate::session::{Recovered, SessionHandle};
use crate::store::{MemoryStore, PgStore, SqliteStore, Store};
use dend::deform::Params;

/// Opens the store `config` asks for (PostgreSQL with `store`, SQLite in
/// `data_dir`, or memory with `in_memory`) and reports the stored sessions
/// on stderr's log.
pub fn open_store(config: &Config) -> anyhow::Result<Arc<dyn Store>> {
    if let Some(url) = &config.store {
        return open_postgres(url, config.store_connections);
    }
    if config.in_memory {
        tracing::warn!("in-memory store: nothing survives a restart");
        return Ok(Arc::new(MemoryStore::new()));
    }
    let store = SqliteStore::open(&config.data_dir)?;
    let sessions = store.list_sessions()?;
    tracing::info!(path = %store.path().display(), sessions = sessions.len(), "opened the session store");
    Ok(Arc::new(store))
}

/// Opens the shared PostgreSQL store (migrating its schema) on a plain
/// thread: the blocking client must not run inside the async runtime.
fn open_postgres(url: &str, connections: u32) -> anyhow::Result<Arc<dyn Store>> {
    if !(url.starts_with("postgres://") || url.starts_with("postgresql://")) {
        anyhow::bail!("--store takes a postgres:// or postgresql:// URL");
    }
    let url = url.to_owned();
    let opened = std::thread::spawn(move || -> anyhow::Result<(PgStore, usize)> {
        let store = PgStore::open(&url, connections)?;
        let n = store.list_sessions()?.len();
        Ok((store, n))
    })
    .join()
    .map_err(|_| anyhow::anyhow!("opening the PostgreSQL store panicked"))?;
    let (store, sessions) = opened?;
    tracing::info!(sessions, "opened the shared PostgreSQL session store");
    Ok(Arc::new(store))
}

/// Re-opens the stored session `id` if it is not live; `None` when the
/// store has no such session. `token` must be the session's: it is checked
/// against the stored hash before the rest operators are built or a
/// factor build starts, so a request without the right token costs one
/// store read.
///
/// The revival runs in a task of its own: a request dropped midway (its
/// client gone, a timeout) does not cancel it half-way. The session
/// becomes live only once it is whole (lease, actor, restored constraint
/// set), one opening at a time per session, so a request that comes
/// meanwhile waits for it and gets the same session instead of opening it
/// again; a revival that fails leaves nothing live and the next request
/// tries again.
pub(crate) async fn revive(
    st: &AppState,
    id: &str,
    token: Option<&str>,
) -> Result<Option<SessionHandle>, ApiError> {
    let task = tokio::spawn(revive_whole(
        st.clone(),
        id.to_owned(),
        token.map(str::to_owned),
    ));
    task.await
        .map_err(|e| ApiError::Internal(format!("re-opening session `{id}`: {e}")))?
}

/// [`revive`]'s work, which must run to its end once started.
async fn revive_whole(
    st: AppState,
    id: String,
    token: Option<String>,
) -> Result<Option<SessionHandle>, ApiError> {
    let key = id.clone();
    let Some(record) = st.store_call(move |s| s.get_session(&key)).await? else {
        return Ok(None);
    };
    let params: Params = serde_json::from_value(record.params.clone())
        .map_err(|e| ApiError::Internal(format!("stored params: {e}")))?;
    let token_sha256: [u8; 32] = hex::decode(&record.token_sha256)
        .ok()
        .and_then(|h| h.try_into().ok())
        .ok_or_else(|| {
            ApiError::Internal(format!("stored token hash of session `{id}` is malformed"))
        })?;
    crate::auth::check_token_hash(&token_sha256, token.as_deref())?;
    // one opening of this session at a time: check, lease, spawn, restore
    // and insert together
    let opening = st.open_lock(&id).lock_owned().await;
    if let Some(live) = st.sessions.read().get(&id).filter(|s| !s.is_fenced()) {
        return Ok(Some(live.clone()));
    }
    if st.sessions.read().len() >= st.config.max_sessions {
        return Err(ApiError::TooManySessions(st.config.max_sessions));
    }
    // a draining instance takes no session (the load balancer is taking
    // it out of its ring; the client retries and reaches another one)
    st.not_draining()?;
    if record.constraints.is_none() {
        // a session opened for the first time (shared store: created
        // elsewhere, opened here): admission control as at creation
        st.admit()?;
    }
    // the lease before the rest operators: a session owned elsewhere costs
    // a store read and a lease check, not a rest build
    let fence = crate::lease::acquire(&st, &id).await?;
    let rest = rest_for(&st, &record.mesh_id).await?;
    let opts = st.session_options(fence);
    let handle = SessionHandle::spawn(
        id.clone(),
        record.mesh_id.clone(),
        token_sha256,
        rest,
        params,
        opts,
    );
    if let Some(spec) = record.constraints {
        if let Err(e) = restore(&st, &handle, spec).await {
            // not left live half-restored: the next request tries again
            tracing::error!(session = id, error = %e, "restoring a stored session failed");
            handle.close().await;
            return Err(e);
        }
    }
    handle.touch();
    let _ = st.sessions.write().insert(id, handle.clone());
    drop(opening);
    st.metrics.sessions.set(st.sessions.read().len() as i64);
    Ok(Some(handle))
}

/// Restores the stored constraint set `spec` of `handle`'s session with
/// the recovered targets: the last checkpoint and every journaled drag
/// after it.
async fn restore(
    st: &AppState,
    handle: &SessionHandle,
    spec: serde_json::Value,
) -> Result<(), ApiError> {
    let key = handle.id().to_owned();
    // read after the lease was taken: every write of a previous owner is
    // either in it or refused
    let (checkpoint, journal) = st
        .store_call(move |s| Ok((s.get_checkpoint(&key)?, s.journal(&key)?)))
        .await?;
    let recovered = Recovered::new(checkpoint, journal);
    tracing::info!(
        session = handle.id(),
        drags = recovered.journal.len(),
        "re-opening a stored session"
    );
    let _ = handle.restore(spec, recovered).await?;
    Ok(())
}

#[cfg(test)]
#[path = "recover_tests.rs"]
mod tests;
