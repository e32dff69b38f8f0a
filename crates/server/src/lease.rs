//! Session ownership across instances sharing one store (docs/deployment.md).
//!
//! With a shared store (`--store postgres://…`) every live session is
//! leased by the instance that drives it:
//! - a session is opened (created, or revived from the store) only after
//!   the registry got its lease (`registry/open.rs`); the lease revision is the session's
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
//! Without a shared store there is one instance: no leases
//! ([`NO_FENCE`](crate::store::NO_FENCE)).

use std::sync::Arc;

pub use crate::cluster::Cluster;
use crate::session::SessionHandle;
use crate::state::AppState;
use crate::store::Fence;

/// Gives up the leases of the live sessions (graceful shutdown), so that
/// other instances take them over at once instead of after the lifetime.
pub async fn release_all(st: &AppState) {
    let Some(cluster) = st.cluster().cloned() else {
        return;
    };
    let held: Vec<(String, Fence)> = st.registry.leases();
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
        let Some(h) = st.registry.get(&id) else {
            continue;
        };
        tracing::info!(session = %id, "handing a session over to the instance that asked for it");
        st.registry.hand_over(&h).await;
    }
}

/// A rolling restart's SIGTERM (docs/deployment.md): stops taking new
/// sessions (readiness and session creation answer 503 `draining`, so the
/// load balancer takes this instance out of its ring), waits `drain_wait`
/// for the load balancer to notice, then hands every live session over
/// (its clients reconnect at once and reach the instance the load balancer
/// routes them to now, which takes the released lease and revives the
/// session; a drag they send meanwhile is queued there until it is ready).
pub async fn drain(st: &AppState) {
    st.registry.start_draining();
    if st.cluster().is_none() {
        return; // one instance: its sessions revive from the store on restart
    }
    tracing::info!(wait = ?st.config.drain_wait(), "draining: not ready, no new sessions");
    tokio::time::sleep(st.config.drain_wait()).await;
    let live: Vec<SessionHandle> = st.registry.all();
    tracing::info!(sessions = live.len(), "draining: handing the sessions over");
    for h in live.iter().filter(|h| !h.is_fenced()) {
        st.registry.hand_over(h).await;
    }
}

/// Renews the live sessions' leases every third of their lifetime until
/// the process ends; closes here the sessions whose lease was lost.
pub fn spawn_renewer(st: AppState) -> Option<tokio::task::JoinHandle<()>> {
    let cluster = st.cluster()?.clone();
    Some(tokio::spawn(async move {
        let mut tick = tokio::time::interval(cluster.ttl / 3);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            let _ = tick.tick().await;
            let held = st.registry.leases();
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
                        if let Some(h) = st.registry.get(&id) {
                            tracing::warn!(session = %id, "session lease lost: closing it here");
                            st.registry.drop_local(&h).await;
                        }
                    }
                }
                // the leases stay valid in the store until they expire;
                // writes keep being fenced there
                Err(e) => tracing::warn!(error = %e, "renewing session leases failed"),
            }
            hand_off(&st, &cluster).await;
            st.registry.update_gauges();
        }
    }))
}
