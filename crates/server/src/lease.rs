//! Session ownership across instances sharing one store (docs/deployment.md).
//!
//! With a shared store (`--store postgres://…`) every live session is
//! leased by the instance that drives it:
//! - a session is opened (created, or revived from the store) only after
//!   [`acquire`] got its lease; the lease revision is the session's
//!   fencing token ([`crate::store::Fence`]), carried by each of its
//!   journal writes, which the store refuses once another instance holds
//!   the lease;
//! - an instance that gets a request or a WebSocket for a session another
//!   live instance leases answers 409 `session_owned_elsewhere`, naming
//!   the owner and when its lease would expire. Behind HAProxy hashing the
//!   session id, requests normally reach the owner; when the owner dies,
//!   HAProxy re-hashes its sessions to the survivors, which take each one
//!   over once its lease expires and revive it from the store;
//! - [`spawn_renewer`] renews the leases of the live sessions every third
//!   of the lease lifetime; a session whose lease was lost (taken over
//!   while this instance could not renew) is closed here, not deleted;
//! - an instance refused a session records the request in the lease; the
//!   owner hands such sessions over at its next renewal (closes them and
//!   releases their leases). This is how sessions follow the load
//!   balancer's hash when an instance comes back or is added: without it,
//!   requests hashed to the newcomer would be refused as long as the old
//!   owner lives.
//!
//! Without a shared store there is one instance: no leases ([`NO_FENCE`]).

use std::sync::Arc;
use std::time::Duration;

use crate::error::ApiError;
use crate::session::SessionHandle;
use crate::store::{Fence, LeaseGrant, NO_FENCE};
use crate::AppState;

/// This instance's part in a shared-store deployment.
#[derive(Debug, Clone)]
pub struct Cluster {
    /// The instance id written in leases.
    pub instance: String,
    /// Lease lifetime.
    pub ttl: Duration,
}

impl Cluster {
    /// The instance settings from the configuration, when it names a
    /// shared store.
    pub fn from_config(config: &crate::Config) -> Option<Arc<Cluster>> {
        config.store.as_ref()?;
        let instance = config
            .instance_id
            .clone()
            .unwrap_or_else(|| format!("dend-{}", hex::encode(rand::random::<[u8; 4]>())));
        Some(Arc::new(Cluster {
            instance,
            ttl: config.lease_ttl(),
        }))
    }
}

/// Takes session `id`'s lease for this instance: its fence, or
/// [`NO_FENCE`] without a shared store; 409 `session_owned_elsewhere`
/// while another instance holds it.
pub(crate) async fn acquire(st: &AppState, id: &str) -> Result<Fence, ApiError> {
    let Some(cluster) = st.cluster.clone() else {
        return Ok(NO_FENCE);
    };
    let key = id.to_owned();
    let c = cluster.clone();
    let grant = st
        .store_call(move |s| s.acquire_lease(&key, &c.instance, c.ttl))
        .await?;
    match grant {
        LeaseGrant::Granted {
            revision,
            taken_over,
        } => {
            if taken_over {
                st.metrics.leases_taken_over.inc();
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

/// Gives up the leases of the live sessions (graceful shutdown), so that
/// other instances take them over at once instead of after the lifetime.
pub async fn release_all(st: &AppState) {
    let Some(cluster) = st.cluster.clone() else {
        return;
    };
    let held: Vec<(String, Fence)> = live_leases(st);
    let n = held.len();
    let r = st
        .store_call(move |s| {
            for (id, fence) in &held {
                s.release_lease(id, &cluster.instance, *fence)?;
            }
            Ok(())
        })
        .await;
    match r {
        Ok(()) => tracing::info!(sessions = n, "released the session leases"),
        Err(e) => tracing::warn!(error = %e, "releasing the session leases failed"),
    }
}

fn live_leases(st: &AppState) -> Vec<(String, Fence)> {
    st.sessions
        .read()
        .values()
        .filter(|s| !s.is_fenced())
        .map(|s| (s.id().to_owned(), s.fence()))
        .collect()
}

/// Forgets a live session here without touching the store (its lease is
/// another instance's now).
pub(crate) async fn drop_local(st: &AppState, s: &SessionHandle) {
    let removed = {
        let mut sessions = st.sessions.write();
        match sessions.get(s.id()) {
            Some(live) if live.fence() == s.fence() => sessions.remove(s.id()),
            _ => None,
        }
    };
    if removed.is_some() {
        s.close().await;
        st.metrics.sessions.set(st.sessions.read().len() as i64);
    }
}

/// Hands over the sessions another instance asked for (the load balancer
/// routes them there now): closes each here, then releases its lease, so
/// that the asking instance takes it at its clients' next attempt. The
/// clients of a closed session see it close and reconnect.
async fn hand_off(st: &AppState, cluster: &Arc<Cluster>) {
    let c = cluster.clone();
    let wanted = match st.store_call(move |s| s.handoffs_wanted(&c.instance)).await {
        Ok(w) => w,
        Err(e) => {
            tracing::warn!(error = %e, "reading hand-off requests failed");
            return;
        }
    };
    for id in wanted {
        let Some(h) = st.sessions.read().get(&id).cloned() else {
            continue;
        };
        tracing::info!(session = %id, "handing a session over to the instance that asked for it");
        hand_over(st, cluster, &h).await;
    }
}

/// Hands session `h` over: closes it here, its clients told to reconnect
/// at once (they reach the instance the load balancer routes them to
/// now), and releases its lease so that instance takes it at once.
pub(crate) async fn hand_over(st: &AppState, cluster: &Arc<Cluster>, h: &SessionHandle) {
    h.mark_moving();
    drop_local(st, h).await;
    let (c, fence, id) = (cluster.clone(), h.fence(), h.id().to_owned());
    if let Err(e) = st
        .store_call(move |s| s.release_lease(&id, &c.instance, fence))
        .await
    {
        tracing::warn!(error = %e, "releasing a handed-over lease failed");
    }
    st.metrics.leases_handed_over.inc();
}

/// A rolling restart's SIGTERM (docs/deployment.md): stops taking new
/// sessions (readiness and session creation answer 503 `draining`, so the
/// load balancer takes this instance out of its ring), waits `drain_wait`
/// for the load balancer to notice, then hands every live session over
/// (its clients reconnect at once and reach the instance the load balancer
/// routes them to now, which takes the released lease and revives the
/// session; a drag they send meanwhile is queued there until it is ready).
pub async fn drain(st: &AppState) {
    st.draining
        .store(true, std::sync::atomic::Ordering::Relaxed);
    let Some(cluster) = st.cluster.clone() else {
        return; // one instance: its sessions revive from the store on restart
    };
    tracing::info!(wait = ?st.config.drain_wait(), "draining: not ready, no new sessions");
    tokio::time::sleep(st.config.drain_wait()).await;
    let live: Vec<SessionHandle> = st.sessions.read().values().cloned().collect();
    tracing::info!(sessions = live.len(), "draining: handing the sessions over");
    for h in live.iter().filter(|h| !h.is_fenced()) {
        hand_over(st, &cluster, h).await;
    }
}

/// Renews the live sessions' leases every third of their lifetime until
/// the process ends; closes here the sessions whose lease was lost.
pub fn spawn_renewer(st: AppState) -> Option<tokio::task::JoinHandle<()>> {
    let cluster = st.cluster.clone()?;
    Some(tokio::spawn(async move {
        let mut tick = tokio::time::interval(cluster.ttl / 3);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            let _ = tick.tick().await;
            let held = live_leases(&st);
            if held.is_empty() {
                continue;
            }
            let c = cluster.clone();
            let lost = st
                .store_call(move |s| s.renew_leases(&c.instance, &held, c.ttl))
                .await;
            match lost {
                Ok(lost) => {
                    for id in lost {
                        let handle = st.sessions.read().get(&id).cloned();
                        if let Some(h) = handle {
                            tracing::warn!(session = %id, "session lease lost: closing it here");
                            drop_local(&st, &h).await;
                        }
                    }
                }
                // the leases stay valid in the store until they expire;
                // writes keep being fenced there
                Err(e) => tracing::warn!(error = %e, "renewing session leases failed"),
            }
            hand_off(&st, &cluster).await;
            st.metrics
                .sessions_owned
                .set(st.sessions.read().len() as i64);
        }
    }))
}
