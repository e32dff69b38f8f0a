//! The named poses of [`SqliteStore`](crate::store::SqliteStore): one row per
//! pose in table `named_poses` (pose and targets as the checkpoints'
//! blobs), deleted with their session. The table is additive (created if
//! missing at open): a database of an older program gains it, and an older
//! program ignores it.

use rusqlite::{params, Connection};

use super::tx::{backend, fenced};
use crate::store::codec::{NamedPoseRow, SELECT_NAMED_POSE};
use crate::store::types::{Fence, NamedPose, StoreError};

/// The table, created at open.
pub(super) const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS named_poses (
    session TEXT NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    name TEXT NOT NULL,
    ordinal INTEGER NOT NULL,
    revision INTEGER NOT NULL,
    created_unix INTEGER NOT NULL,
    constraints TEXT,
    pose BLOB NOT NULL,
    targets BLOB NOT NULL,
    PRIMARY KEY (session, name)
);
";

/// [`crate::store::Store::put_named_pose`].
pub(super) fn put(
    conn: &mut Connection,
    id: &str,
    fence: Fence,
    p: &NamedPose,
) -> Result<(), StoreError> {
    let row = NamedPoseRow::encode(p);
    let tx = fenced(conn, id, fence)?;
    let _ = tx
        .execute(
            "INSERT OR REPLACE INTO named_poses
               (session, name, ordinal, revision, created_unix, constraints, pose, targets)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
            params![
                id,
                row.name,
                row.ordinal,
                row.revision,
                row.created_unix,
                row.constraints,
                row.pose,
                row.targets
            ],
        )
        .map_err(backend)?;
    tx.commit().map_err(backend)
}

/// [`crate::store::Store::rename_named_pose`].
pub(super) fn rename(
    conn: &mut Connection,
    id: &str,
    fence: Fence,
    from: &str,
    to: &str,
) -> Result<(), StoreError> {
    let tx = fenced(conn, id, fence)?;
    let _ = tx
        .execute(
            "UPDATE named_poses SET name = ?3 WHERE session = ?1 AND name = ?2",
            params![id, from, to],
        )
        .map_err(backend)?;
    tx.commit().map_err(backend)
}

/// [`crate::store::Store::delete_named_pose`].
pub(super) fn delete(
    conn: &mut Connection,
    id: &str,
    fence: Fence,
    name: &str,
) -> Result<(), StoreError> {
    let tx = fenced(conn, id, fence)?;
    let _ = tx
        .execute(
            "DELETE FROM named_poses WHERE session = ?1 AND name = ?2",
            params![id, name],
        )
        .map_err(backend)?;
    tx.commit().map_err(backend)
}

/// [`crate::store::Store::named_poses`].
pub(super) fn list(conn: &Connection, id: &str) -> Result<Vec<NamedPose>, StoreError> {
    let rows: Vec<NamedPoseRow> = {
        let mut stmt = conn
            .prepare_cached(&format!(
                "{SELECT_NAMED_POSE} WHERE session = ?1 ORDER BY ordinal, name"
            ))
            .map_err(backend)?;
        let rows = stmt
            .query_map([id], |r| {
                Ok(NamedPoseRow {
                    name: r.get(0)?,
                    ordinal: r.get(1)?,
                    revision: r.get(2)?,
                    created_unix: r.get(3)?,
                    constraints: r.get(4)?,
                    pose: r.get(5)?,
                    targets: r.get(6)?,
                })
            })
            .map_err(backend)?;
        rows.collect::<Result<_, _>>().map_err(backend)?
    };
    rows.into_iter().map(|r| r.decode(id)).collect()
}
