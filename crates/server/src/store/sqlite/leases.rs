//! Session leases in [`crate::store::SqliteStore`] (the `leases` table, schema
//! version 2): the rule of [`crate::store::lease_rule`], shared with the other
//! backends, on rows of this table. A SQLite file serves one instance;
//! expiry uses this machine's wall clock (`expires_ms`, 0 once released).

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use rusqlite::{params, Connection, OptionalExtension, TransactionBehavior};

use crate::store::lease_rule::{self, Expiry, LeaseRow};
use crate::store::types::{Fence, LeaseGrant, StoreError};

/// The table (added by schema version 2).
pub(super) const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS leases (
    session TEXT PRIMARY KEY,
    owner TEXT NOT NULL,
    revision INTEGER NOT NULL,
    expires_ms INTEGER NOT NULL,
    wanted_by TEXT
);
";

fn backend(e: impl std::fmt::Display) -> StoreError {
    StoreError::Backend(e.to_string())
}

fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

fn ttl_ms(ttl: Duration) -> i64 {
    i64::try_from(ttl.as_millis()).unwrap_or(i64::MAX / 4)
}

/// Refuses a write fenced by `fence` unless it is `id`'s lease revision
/// (inside the write's transaction).
pub(super) fn check_fence(conn: &Connection, id: &str, fence: Fence) -> Result<(), StoreError> {
    if fence == crate::store::types::NO_FENCE {
        return Ok(()); // the unfenced mode reads nothing
    }
    let row: Option<(String, i64)> = conn
        .query_row(
            "SELECT owner, revision FROM leases WHERE session = ?1",
            [id],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .optional()
        .map_err(backend)?;
    let current = row.as_ref().map(|(o, rev)| (o.as_str(), *rev as Fence));
    lease_rule::check_fence(id, fence, current)
}

/// [`crate::store::Store::acquire_lease`].
pub(super) fn acquire(
    conn: &mut Connection,
    id: &str,
    owner: &str,
    ttl: Duration,
) -> Result<LeaseGrant, StoreError> {
    let tx = conn
        .transaction_with_behavior(TransactionBehavior::Immediate)
        .map_err(backend)?;
    let now = now_ms();
    let row: Option<(String, i64, i64)> = tx
        .query_row(
            "SELECT owner, revision, expires_ms FROM leases WHERE session = ?1",
            [id],
            |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)),
        )
        .optional()
        .map_err(backend)?;
    let grant = lease_rule::acquire(
        row.as_ref().map(|(holder, revision, expires_ms)| LeaseRow {
            owner: holder,
            revision: *revision as Fence,
            expiry: Expiry::from_left_ms((*expires_ms > 0).then(|| *expires_ms - now)),
        }),
        owner,
    );
    let _ = match &grant {
        LeaseGrant::HeldBy { .. } => tx.execute(
            "UPDATE leases SET wanted_by = ?2 WHERE session = ?1",
            params![id, owner],
        ),
        LeaseGrant::Granted { revision, .. } => tx.execute(
            "INSERT INTO leases (session, owner, revision, expires_ms) VALUES (?1, ?2, ?3, ?4)
             ON CONFLICT(session) DO UPDATE SET owner = excluded.owner,
               revision = excluded.revision, expires_ms = excluded.expires_ms, wanted_by = NULL",
            params![id, owner, *revision as i64, now.saturating_add(ttl_ms(ttl))],
        ),
    }
    .map_err(backend)?;
    tx.commit().map_err(backend)?;
    Ok(grant)
}

/// [`crate::store::Store::renew_leases`]: the leases [`lease_rule::holds`].
pub(super) fn renew(
    conn: &mut Connection,
    owner: &str,
    leases: &[(String, Fence)],
    ttl: Duration,
) -> Result<Vec<String>, StoreError> {
    let tx = conn.transaction().map_err(backend)?;
    let expires = now_ms().saturating_add(ttl_ms(ttl));
    let mut lost = vec![];
    for (id, rev) in leases {
        let n = tx
            .execute(
                "UPDATE leases SET expires_ms = ?1 WHERE session = ?2 AND owner = ?3 AND revision = ?4",
                params![expires, id, owner, *rev as i64],
            )
            .map_err(backend)?;
        if n == 0 {
            lost.push(id.clone());
        }
    }
    tx.commit().map_err(backend)?;
    Ok(lost)
}

/// [`crate::store::Store::release_lease`]: expires the lease, keeping its revision,
/// if `owner` [`lease_rule::holds`] it.
pub(super) fn release(
    conn: &Connection,
    id: &str,
    owner: &str,
    revision: Fence,
) -> Result<(), StoreError> {
    let _ = conn
        .execute(
            "UPDATE leases SET expires_ms = 0 WHERE session = ?1 AND owner = ?2 AND revision = ?3",
            params![id, owner, revision as i64],
        )
        .map_err(backend)?;
    Ok(())
}

/// [`crate::store::Store::handoffs_wanted`]: the rows of [`lease_rule::wants_handoff`].
pub(super) fn wanted(conn: &Connection, owner: &str) -> Result<Vec<String>, StoreError> {
    let mut stmt = conn
        .prepare(
            "SELECT session FROM leases
             WHERE owner = ?1 AND wanted_by IS NOT NULL AND expires_ms > ?2",
        )
        .map_err(backend)?;
    let rows = stmt
        .query_map(params![owner, now_ms()], |r| r.get(0))
        .map_err(backend)?;
    rows.collect::<Result<_, _>>().map_err(backend)
}
