//! How a session becomes live: created ([`SessionRegistry::create`]) or
//! revived from the store ([`SessionRegistry::revive`]), both through
//! [`SessionRegistry::open`].
//!
//! Sessions outlive the process: the first request naming a stored session
//! that is not live revives it. It rebuilds its
//! [`Rest`](dend::deform::Rest), spawns its actor and, when it had
//! constraints, restores them with the recovered targets (last checkpoint +
//! every journaled drag after it) and the checkpoint pose as the warm
//! start. The session then goes `building` → `ready` exactly as after
//! `PUT constraints` (clients get the `state` and `ready` events) and
//! accepts drags when ready.

use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use super::SessionRegistry;
use crate::auth::{check_token_hash, token_hash};
use crate::blocking::store_call;
use crate::error::ApiError;
use crate::session::{Recovered, SessionHandle, SessionState};
use crate::store::{Fence, LeaseGrant, SessionRecord, NO_FENCE};
use dend::deform::{Params, Rest};
use dend_protocol::ws::Created;

/// A session about to be opened here.
struct Opening {
    id: String,
    mesh_id: String,
    token_sha256: [u8; 32],
    rest: Arc<Rest>,
    params: Params,
    /// Its lease revision ([`NO_FENCE`] without a shared store).
    fence: Fence,
    /// Its stored constraint set, restored with the recovered targets.
    constraints: Option<serde_json::Value>,
}

impl SessionRegistry {
    /// Looks a live session up, re-opening a stored one after a restart or
    /// a takeover ([`SessionRegistry::revive`]). A stored session is
    /// re-opened only for its own `token`, checked against the stored hash
    /// before any work is done (a live session's token is checked by the
    /// caller).
    pub async fn find(
        self: &Arc<Self>,
        id: &str,
        token: Option<&str>,
    ) -> Result<SessionHandle, ApiError> {
        match self.get(id) {
            Some(s) if !s.is_fenced() => Ok(s),
            // its lease was taken over: forget it here, then it is revived
            // here only if this instance can lease it again
            _ => self
                .revive(id, token)
                .await?
                .ok_or_else(|| ApiError::SessionNotFound(id.to_owned())),
        }
    }

    /// Creates a session on mesh `mesh_id` with the resolved `params`: its
    /// record is stored, then (embedded store) it is opened here. With a
    /// shared store it opens on the instance its first request reaches
    /// (the load balancer hashes its id), which leases it then.
    pub async fn create(&self, mesh_id: String, params: Params) -> Result<Created, ApiError> {
        self.admit()?;
        self.check_room()?;
        let store = &self.parts.store;
        let rest = if self.parts.cluster.is_some() {
            // the rest is built where the session opens
            let key = mesh_id.clone();
            if store_call(store, move |s| s.get_mesh(&key))
                .await?
                .is_none()
            {
                return Err(ApiError::MeshNotFound(mesh_id));
            }
            None
        } else {
            let rest = self.parts.rests.get(store, &mesh_id).await?;
            prefetch_levels(&rest, params);
            Some(rest)
        };
        let id = crate::auth::new_id();
        let token = hex::encode(rand::random::<[u8; 32]>());
        let hash = token_hash(&token);
        let record = SessionRecord {
            id: id.clone(),
            mesh_id: mesh_id.clone(),
            token_sha256: hex::encode(hash),
            // the resolved parameters, every field written out: a stored
            // session keeps its formulation and defaults across upgrades
            params: serde_json::to_value(params)
                .map_err(|e| ApiError::Internal(format!("params: {e}")))?,
            constraints: None,
            created_unix: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_secs())
                .unwrap_or(0),
        };
        store_call(store, move |s| s.put_session(&record)).await?;
        let state = match rest {
            None => SessionState::Empty,
            Some(rest) => {
                let opening = Opening {
                    id: id.clone(),
                    mesh_id: mesh_id.clone(),
                    token_sha256: hash,
                    rest,
                    params,
                    fence: NO_FENCE,
                    constraints: None,
                };
                match self.open(opening).await {
                    Ok(handle) => handle.info().state,
                    Err(e) => {
                        let key = id.clone();
                        store_call(store, move |s| s.delete_session(&key)).await?;
                        return Err(e);
                    }
                }
            }
        };
        self.parts.metrics.sessions_created.inc();
        Ok(Created {
            id,
            token,
            mesh_id,
            state,
        })
    }

    /// Re-opens the stored session `id` if it is not live; `None` when the
    /// store has no such session. `token` must be the session's: it is
    /// checked against the stored hash before the rest operators are built
    /// or a factor build starts, so a request without the right token
    /// costs one store read.
    ///
    /// The revival runs in a task of its own: a request dropped midway (its
    /// client gone, a timeout) does not cancel it half-way. The session
    /// becomes live only once it is whole (lease, actor, restored
    /// constraint set), one opening at a time per session, so a request
    /// that comes meanwhile waits for it and gets the same session instead
    /// of opening it again; a revival that fails leaves nothing live and
    /// the next request tries again.
    pub async fn revive(
        self: &Arc<Self>,
        id: &str,
        token: Option<&str>,
    ) -> Result<Option<SessionHandle>, ApiError> {
        let task = tokio::spawn(
            self.clone()
                .revive_whole(id.to_owned(), token.map(str::to_owned)),
        );
        task.await
            .map_err(|e| ApiError::Internal(format!("re-opening session `{id}`: {e}")))?
    }

    /// [`SessionRegistry::revive`]'s work, which must run to its end once
    /// started.
    async fn revive_whole(
        self: Arc<Self>,
        id: String,
        token: Option<String>,
    ) -> Result<Option<SessionHandle>, ApiError> {
        let key = id.clone();
        let store = &self.parts.store;
        let Some(record) = store_call(store, move |s| s.get_session(&key)).await? else {
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
        check_token_hash(&token_sha256, token.as_deref())?;
        // one opening of this session at a time: check, lease, spawn,
        // restore and insert together
        let _opening = self.open_lock(&id).lock_owned().await;
        if let Some(live) = self.get(&id).filter(|s| !s.is_fenced()) {
            return Ok(Some(live));
        }
        self.check_room()?;
        // a draining instance takes no session (the load balancer is taking
        // it out of its ring; the client retries and reaches another one)
        self.not_draining()?;
        if record.constraints.is_none() {
            // a session opened for the first time (shared store: created
            // elsewhere, opened here): admission control as at creation
            self.admit()?;
        }
        // the lease before the rest operators: a session owned elsewhere
        // costs a store read and a lease check, not a rest build
        let fence = self.acquire(&id).await?;
        let rest = self.parts.rests.get(store, &record.mesh_id).await?;
        let opening = Opening {
            id,
            mesh_id: record.mesh_id,
            token_sha256,
            rest,
            params,
            fence,
            constraints: record.constraints,
        };
        self.open(opening).await.map(Some)
    }

    /// The one way a session becomes live: spawns its actor, restores its
    /// stored constraint set (if any) with the recovered targets, and
    /// inserts it among the live sessions if there is room. A session that
    /// fails any step is closed and nothing is left live: the next request
    /// tries again.
    async fn open(&self, o: Opening) -> Result<SessionHandle, ApiError> {
        let opts = self.session_options(o.fence);
        let handle = SessionHandle::spawn(o.id, o.mesh_id, o.token_sha256, o.rest, o.params, opts);
        if let Some(spec) = o.constraints {
            if let Err(e) = self.restore(&handle, spec).await {
                // not left live half-restored
                tracing::error!(session = handle.id(), error = %e, "restoring a stored session failed");
                handle.close().await;
                return Err(e);
            }
        }
        handle.touch();
        if let Err(e) = self.insert_if_room(&handle) {
            handle.close().await;
            return Err(e);
        }
        Ok(handle)
    }

    /// Restores the stored constraint set `spec` of `handle`'s session with
    /// the recovered targets: the last checkpoint and every journaled drag
    /// after it.
    async fn restore(
        &self,
        handle: &SessionHandle,
        spec: serde_json::Value,
    ) -> Result<(), ApiError> {
        let key = handle.id().to_owned();
        // read after the lease was taken: every write of a previous owner is
        // either in it or refused
        let (checkpoint, journal) = store_call(&self.parts.store, move |s| {
            Ok((s.get_checkpoint(&key)?, s.journal(&key)?))
        })
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

    /// Takes session `id`'s lease for this instance: its fence, or
    /// [`NO_FENCE`] without a shared store; 409 `session_owned_elsewhere`
    /// while another instance holds it.
    async fn acquire(&self, id: &str) -> Result<Fence, ApiError> {
        let Some(cluster) = self.parts.cluster.clone() else {
            return Ok(NO_FENCE);
        };
        let key = id.to_owned();
        let grant = store_call(&self.parts.store, move |s| {
            s.acquire_lease(&key, &cluster.instance, cluster.ttl)
        })
        .await?;
        match grant {
            LeaseGrant::Granted {
                revision,
                taken_over,
            } => {
                if taken_over {
                    self.parts.metrics.leases_taken_over.inc();
                    tracing::info!(session = id, revision, "took over an expired session lease");
                }
                Ok(revision)
            }
            LeaseGrant::HeldBy {
                owner,
                expires_in_ms,
            } => Err(ApiError::SessionOwnedElsewhere {
                session: id.to_owned(),
                owner,
                retry_after_ms: expires_in_ms,
            }),
        }
    }
}

/// Builds the coarse levels a new session's first drags use, off their
/// path: the elastic solver's levels for its coarse ratio (the first and
/// every level of the hierarchy below it; levels already built are
/// reused) and the coarse previews' level.
fn prefetch_levels(rest: &Arc<Rest>, params: Params) {
    if params.elastic().is_some() {
        let rest = rest.clone();
        tokio::task::spawn_blocking(move || rest.prepare_coarse_level_for(&params));
    }
    let rest = rest.clone();
    tokio::task::spawn_blocking(move || rest.prepare_preview_level(&params));
}
