//! Session leases in [`super::SqliteStore`] (the `leases` table, schema
//! version 2): the same rules as the shared PostgreSQL store, so the one
//! store test suite checks them on every backend. A SQLite file serves one
//! instance; expiry uses this machine's wall clock.
//!
//! A lease row is never deleted while its session exists: releasing it
//! only expires it, so revisions keep growing and a fence handed out once
//! can never become valid again.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use rusqlite::{params, Connection, OptionalExtension, TransactionBehavior};

use super::{Fence, LeaseGrant, StoreError, NO_FENCE};

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
    if fence == NO_FENCE {
        return Ok(());
    }
    let row: Option<(String, i64)> = conn
        .query_row(
            "SELECT owner, revision FROM leases WHERE session = ?1",
            [id],
            |r| Ok((r.get(0)?, r.get(1)?)),
        )
        .optional()
        .map_err(backend)?;
    match row {
        Some((_, rev)) if rev as u64 == fence => Ok(()),
        other => Err(StoreError::Fenced {
            session: id.to_owned(),
            fence,
            current: other.as_ref().map(|r| r.1 as u64),
            owner: other.map(|r| r.0),
        }),
    }
}

/// [`super::Store::acquire_lease`].
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
    if let Some((holder, _, expires)) = &row {
        if holder != owner && *expires > now {
            let _ = tx
                .execute(
                    "UPDATE leases SET wanted_by = ?2 WHERE session = ?1",
                    params![id, owner],
                )
                .map_err(backend)?;
            tx.commit().map_err(backend)?;
            return Ok(LeaseGrant::HeldBy {
                owner: holder.clone(),
                expires_in_ms: (*expires - now) as u64,
            });
        }
    }
    let taken_over = row.as_ref().is_some_and(|r| r.0 != owner && r.2 > 0);
    let revision = row.map_or(1, |r| r.1 + 1);
    let _ = tx
        .execute(
            "INSERT INTO leases (session, owner, revision, expires_ms) VALUES (?1, ?2, ?3, ?4)
             ON CONFLICT(session) DO UPDATE SET owner = excluded.owner,
               revision = excluded.revision, expires_ms = excluded.expires_ms, wanted_by = NULL",
            params![id, owner, revision, now.saturating_add(ttl_ms(ttl))],
        )
        .map_err(backend)?;
    tx.commit().map_err(backend)?;
    Ok(LeaseGrant::Granted {
        revision: revision as u64,
        taken_over,
    })
}

/// [`super::Store::renew_leases`].
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

/// [`super::Store::release_lease`]: expires the lease, keeping its revision.
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

/// [`super::Store::handoffs_wanted`].
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
