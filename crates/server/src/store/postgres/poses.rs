//! The named poses of [`PgStore`](crate::store::PgStore): table `named_poses`
//! (schema migration 3), one row per pose, deleted with their session;
//! writes fenced like the journal's.

use super::conn::{pg_err, Conn};
use super::leases;
use crate::store::codec::{NamedPoseRow, SELECT_NAMED_POSE};
use crate::store::types::{Fence, NamedPose, StoreError};

/// Migration 3: the table.
pub(super) const MIGRATION: &str = "CREATE TABLE named_poses (
     session TEXT NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
     name TEXT NOT NULL, ordinal BIGINT NOT NULL, revision BIGINT NOT NULL,
     created_unix BIGINT NOT NULL, constraints TEXT,
     pose BYTEA NOT NULL, targets BYTEA NOT NULL,
     PRIMARY KEY (session, name));";

/// Runs `write` in a transaction on session `id`'s rows, after checking
/// that the session exists and that `fence` still holds its lease.
fn fenced_write(
    c: &mut Conn,
    id: &str,
    fence: Fence,
    write: impl FnOnce(&mut postgres::Transaction<'_>) -> Result<u64, postgres::Error>,
) -> Result<(), StoreError> {
    let mut tx = c.transaction().map_err(pg_err)?;
    if tx
        .query_opt("SELECT 1 FROM sessions WHERE id = $1", &[&id])
        .map_err(pg_err)?
        .is_none()
    {
        return Err(StoreError::Missing(id.to_string()));
    }
    leases::check_fence(&mut tx, id, fence)?;
    let _ = write(&mut tx).map_err(pg_err)?;
    tx.commit().map_err(pg_err)
}

/// [`crate::store::Store::put_named_pose`].
pub(super) fn put(c: &mut Conn, id: &str, fence: Fence, p: &NamedPose) -> Result<(), StoreError> {
    let r = NamedPoseRow::encode(p);
    fenced_write(c, id, fence, |tx| {
        tx.execute(
            "INSERT INTO named_poses
               (session, name, ordinal, revision, created_unix, constraints, pose, targets)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8)
             ON CONFLICT (session, name) DO UPDATE SET ordinal = excluded.ordinal,
               revision = excluded.revision, created_unix = excluded.created_unix,
               constraints = excluded.constraints, pose = excluded.pose,
               targets = excluded.targets",
            &[
                &id,
                &r.name,
                &r.ordinal,
                &r.revision,
                &r.created_unix,
                &r.constraints,
                &r.pose,
                &r.targets,
            ],
        )
    })
}

/// [`crate::store::Store::rename_named_pose`].
pub(super) fn rename(
    c: &mut Conn,
    id: &str,
    fence: Fence,
    from: &str,
    to: &str,
) -> Result<(), StoreError> {
    fenced_write(c, id, fence, |tx| {
        tx.execute(
            "UPDATE named_poses SET name = $3 WHERE session = $1 AND name = $2",
            &[&id, &from, &to],
        )
    })
}

/// [`crate::store::Store::delete_named_pose`].
pub(super) fn delete(c: &mut Conn, id: &str, fence: Fence, name: &str) -> Result<(), StoreError> {
    fenced_write(c, id, fence, |tx| {
        tx.execute(
            "DELETE FROM named_poses WHERE session = $1 AND name = $2",
            &[&id, &name],
        )
    })
}

/// [`crate::store::Store::named_poses`].
pub(super) fn list(c: &mut Conn, id: &str) -> Result<Vec<NamedPose>, StoreError> {
    c.query(
        &format!("{SELECT_NAMED_POSE} WHERE session = $1 ORDER BY ordinal, name"),
        &[&id],
    )
    .map_err(pg_err)?
    .iter()
    .map(|r| {
        NamedPoseRow {
            name: r.get(0),
            ordinal: r.get(1),
            revision: r.get(2),
            created_unix: r.get(3),
            constraints: r.get(4),
            pose: r.get(5),
            targets: r.get(6),
        }
        .decode(id)
    })
    .collect()
}
