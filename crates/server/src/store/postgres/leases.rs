//! Session leases in [`crate::store::PgStore`] (the `leases` table, migration 2).
//!
//! Expiry uses the database's clock (`now()`), so instances' clocks need
//! not agree. A fenced write reads the lease row `FOR SHARE` in its own
//! transaction and a takeover updates it (`FOR UPDATE`): a takeover waits
//! for a fenced write in flight, and a write that starts after a takeover
//! sees the new revision and is refused. If the writer froze inside its
//! transaction, the server ends that connection after
//! [`crate::store::IDLE_IN_TRANSACTION_TIMEOUT`], which lets the
//! takeover through and makes the frozen write fail when it wakes. A
//! released lease keeps its row (expired, `expires` NULL), so revisions
//! only grow. The rule itself is [`crate::store::lease_rule`]'s, shared with the
//! other backends.

use std::time::Duration;

use super::conn::{pg_err, Conn};
use super::liveness::{holder_liveness, Holder};
use crate::store::lease_rule::{self, Expiry, LeaseRow};
use crate::store::types::{Fence, LeaseGrant, StoreError, NO_FENCE};

/// The lifetime in milliseconds, as the `FLOAT8` that multiplies an interval.
fn ttl_ms(ttl: Duration) -> f64 {
    ttl.as_secs_f64() * 1000.0
}

/// Refuses a write fenced by `fence` unless it is `id`'s lease revision;
/// locks the lease row until the write's transaction ends.
pub(super) fn check_fence(
    tx: &mut postgres::Transaction<'_>,
    id: &str,
    fence: Fence,
) -> Result<(), StoreError> {
    if fence == NO_FENCE {
        return Ok(()); // the unfenced mode reads nothing
    }
    let row = tx
        .query_opt(
            "SELECT owner, revision FROM leases WHERE session = $1 FOR SHARE",
            &[&id],
        )
        .map_err(pg_err)?;
    let current: Option<(String, i64)> = row.map(|r| (r.get(0), r.get(1)));
    let current = current.as_ref().map(|(o, rev)| (o.as_str(), *rev as Fence));
    lease_rule::check_fence(id, fence, current)
}

/// [`crate::store::Store::acquire_lease`].
pub(super) fn acquire(
    c: &mut Conn,
    id: &str,
    owner: &str,
    ttl: Duration,
) -> Result<LeaseGrant, StoreError> {
    let mut tx = c.transaction().map_err(pg_err)?;
    // a placeholder row (revision 0, released) so that there is a row to lock
    let _ = tx
        .execute(
            "INSERT INTO leases (session, owner, revision, expires) VALUES ($1, '', 0, NULL)
             ON CONFLICT (session) DO NOTHING",
            &[&id],
        )
        .map_err(pg_err)?;
    let r = tx
        .query_one(
            "SELECT owner, revision, expires IS NOT NULL AND expires > now(),
                    COALESCE((EXTRACT(EPOCH FROM (expires - now())) * 1000)::BIGINT, 0),
                    expires IS NOT NULL
             FROM leases WHERE session = $1 FOR UPDATE",
            &[&id],
        )
        .map_err(pg_err)?;
    let (holder, revision, live, left_ms, held): (String, i64, bool, i64, bool) =
        (r.get(0), r.get(1), r.get(2), r.get(3), r.get(4));
    // `live` by the database's clock, even where less than a millisecond is left
    let expiry = match (held, live) {
        (false, _) => Expiry::Released,
        (true, false) => Expiry::Expired,
        (true, true) if holder != owner => {
            let left_ms = left_ms.max(0) as u64;
            match holder_liveness(&mut tx, owner, &holder)? {
                // a live lease of a dead owner (its liveness connection is
                // gone): as good as expired
                Holder::Gone => Expiry::Expired,
                // the owner may be gone, which is known when the grace
                // ends: the refusal's retry hint is then, not the expiry
                Holder::Unknown { left_ms: grace } => Expiry::Live {
                    left_ms: left_ms.min(grace),
                },
                Holder::Present => Expiry::Live { left_ms },
            }
        }
        (true, true) => Expiry::Live {
            left_ms: left_ms.max(0) as u64,
        },
    };
    let current = LeaseRow {
        owner: &holder,
        revision: revision as Fence,
        expiry,
    };
    let grant = lease_rule::acquire(Some(current), owner);
    let _ = match &grant {
        LeaseGrant::HeldBy { .. } => tx.execute(
            "UPDATE leases SET wanted_by = $2 WHERE session = $1",
            &[&id, &owner],
        ),
        LeaseGrant::Granted { revision, .. } => tx.execute(
            "UPDATE leases SET owner = $2, revision = $3,
                 expires = now() + $4::FLOAT8 * INTERVAL '1 millisecond', wanted_by = NULL
             WHERE session = $1",
            &[&id, &owner, &(*revision as i64), &ttl_ms(ttl)],
        ),
    }
    .map_err(pg_err)?;
    tx.commit().map_err(pg_err)?;
    Ok(grant)
}

/// [`crate::store::Store::renew_leases`]: one statement for all of them (the
/// leases [`lease_rule::holds`]).
pub(super) fn renew(
    c: &mut Conn,
    owner: &str,
    leases: &[(String, Fence)],
    ttl: Duration,
) -> Result<Vec<String>, StoreError> {
    if leases.is_empty() {
        return Ok(vec![]);
    }
    let ids: Vec<&str> = leases.iter().map(|l| l.0.as_str()).collect();
    let revs: Vec<i64> = leases.iter().map(|l| l.1 as i64).collect();
    let renewed: Vec<String> = c
        .query(
            "UPDATE leases l SET expires = now() + $3::FLOAT8 * INTERVAL '1 millisecond'
             FROM unnest($1::TEXT[], $2::BIGINT[]) AS h(session, revision)
             WHERE l.session = h.session AND l.revision = h.revision AND l.owner = $4
             RETURNING l.session",
            &[&ids, &revs, &ttl_ms(ttl), &owner],
        )
        .map_err(pg_err)?
        .iter()
        .map(|r| r.get(0))
        .collect();
    Ok(leases
        .iter()
        .filter(|l| !renewed.contains(&l.0))
        .map(|l| l.0.clone())
        .collect())
}

/// [`crate::store::Store::release_lease`]: expires the lease, keeping its revision,
/// if `owner` [`lease_rule::holds`] it.
pub(super) fn release(
    c: &mut Conn,
    id: &str,
    owner: &str,
    revision: Fence,
) -> Result<(), StoreError> {
    let _ = c
        .execute(
            "UPDATE leases SET expires = NULL WHERE session = $1 AND owner = $2 AND revision = $3",
            &[&id, &owner, &(revision as i64)],
        )
        .map_err(pg_err)?;
    Ok(())
}

/// [`crate::store::Store::handoffs_wanted`]: the rows of [`lease_rule::wants_handoff`].
pub(super) fn wanted(c: &mut Conn, owner: &str) -> Result<Vec<String>, StoreError> {
    Ok(c.query(
        "SELECT session FROM leases
         WHERE owner = $1 AND wanted_by IS NOT NULL AND expires > now()",
        &[&owner],
    )
    .map_err(pg_err)?
    .iter()
    .map(|r| r.get(0))
    .collect())
}
