//! The `mesh_assets` table of [`crate::store::SqliteStore`]: the uploaded file of a
//! mesh whose export keeps the file's layout (see [`crate::store::StoredAsset`]),
//! and the deletion of a mesh with its file.
//! The table was added without a schema version bump: `CREATE TABLE IF NOT
//! EXISTS` adds it to older databases, and older programs ignore it.

use rusqlite::{params, Connection, OptionalExtension};

use crate::store::types::{StoreError, StoredAsset};

/// Stores (or replaces) the asset of mesh `id`.
pub(super) fn put(conn: &Connection, id: &str, a: &StoredAsset) -> Result<(), StoreError> {
    conn.execute(
        "INSERT OR REPLACE INTO mesh_assets (id, format, bytes) VALUES (?1, ?2, ?3)",
        params![id, a.format, a.bytes],
    )
    .map(|_| ())
    .map_err(|e| StoreError::Backend(e.to_string()))
}

/// Deletes mesh `id` and its asset in one transaction; whether the mesh was there.
pub(super) fn delete_mesh(conn: &mut Connection, id: &str) -> Result<bool, StoreError> {
    let backend = |e: rusqlite::Error| StoreError::Backend(e.to_string());
    let tx = conn.transaction().map_err(backend)?;
    let _ = tx
        .execute("DELETE FROM mesh_assets WHERE id = ?1", params![id])
        .map_err(backend)?;
    let n = tx
        .execute("DELETE FROM meshes WHERE id = ?1", params![id])
        .map_err(backend)?;
    tx.commit().map_err(backend)?;
    Ok(n > 0)
}

/// The asset of mesh `id`.
pub(super) fn get(conn: &Connection, id: &str) -> Result<Option<StoredAsset>, StoreError> {
    conn.query_row(
        "SELECT format, bytes FROM mesh_assets WHERE id = ?1",
        params![id],
        |r| {
            Ok(StoredAsset {
                format: r.get(0)?,
                bytes: r.get(1)?,
            })
        },
    )
    .optional()
    .map_err(|e| StoreError::Backend(e.to_string()))
}
