//! [`SqliteStore`]: the crash-safe embedded [`Store`], one SQLite database
//! file (`dend.sqlite3`) in the server's data directory.
//!
//! - WAL journal mode with `synchronous=FULL`: every transaction (one per
//!   [`Store::append`], one per [`Store::checkpoint`]) is fsynced before it
//!   returns, so an acknowledged drag survives `kill -9` and power loss.
//! - Compact binary blobs, little-endian: mesh positions as `f64` triples
//!   (bit-exact), triangles as `u32` triples, checkpoint poses as `f64`
//!   triples, targets as 10 `f64` each (quaternion, translation, pivot),
//!   journal entries as one fixed 73-byte record (see [`encode_entry`]).
//! - The token is kept only as its SHA-256 (32 raw bytes).
//! - The schema is versioned by `PRAGMA user_version` ([`SCHEMA_VERSION`]);
//!   a database written by a newer version is refused.
//! - Every decode failure is a [`StoreError::Corrupt`] naming the record.
//!
//! One connection behind a mutex: the server's store calls are short and
//! the per-drag append is dominated by its fsync.

mod assets;
mod leases;
mod poses;
mod tx;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use parking_lot::Mutex;
use rusqlite::{params, Connection, OptionalExtension, TransactionBehavior};

use super::codec::{
    corrupt, decode_checkpoint, decode_entry, decode_points, decode_triangles, encode_entry,
    encode_points, encode_targets, encode_triangles, RecordRow, SELECT_SESSION,
};
use super::traits::{LeaseStore, MeshStore, PoseStore, SessionLog};
use super::types::{
    Checkpoint, Fence, JournalEntry, LeaseGrant, NamedPose, SessionRecord, StoreError, StoredAsset,
};
use dend::mesh::Mesh;
use tx::{backend, fenced, missing};

/// Version of the schema below (`PRAGMA user_version`): 1 the tables
/// below, 2 added `leases` (see `leases`).
pub const SCHEMA_VERSION: i64 = 2;

/// The database file name inside the data directory.
pub const DB_FILE: &str = "dend.sqlite3";

const SCHEMA: &str = "
CREATE TABLE IF NOT EXISTS meshes (
    id TEXT PRIMARY KEY,
    positions BLOB NOT NULL,
    triangles BLOB NOT NULL
);
CREATE TABLE IF NOT EXISTS mesh_assets (id TEXT PRIMARY KEY, format TEXT NOT NULL, bytes BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS sessions (
    id TEXT PRIMARY KEY,
    mesh_id TEXT NOT NULL,
    token_sha256 BLOB NOT NULL,
    params TEXT NOT NULL,
    constraints TEXT,
    created_unix INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS journal (
    n INTEGER PRIMARY KEY AUTOINCREMENT,
    session TEXT NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
    entry BLOB NOT NULL
);
CREATE INDEX IF NOT EXISTS journal_session ON journal(session, n);
CREATE TABLE IF NOT EXISTS checkpoints (
    session TEXT PRIMARY KEY REFERENCES sessions(id) ON DELETE CASCADE,
    revision INTEGER NOT NULL,
    ack_seq INTEGER NOT NULL,
    pose BLOB NOT NULL,
    targets BLOB NOT NULL
);
";

/// A [`Store`] in one SQLite database file (see the module docs).
pub struct SqliteStore {
    conn: Mutex<Connection>,
    path: PathBuf,
}

impl SqliteStore {
    /// Opens (creating if needed) the database in directory `dir` (created
    /// too), in WAL mode with `synchronous=FULL`, and migrates the schema.
    pub fn open(dir: &Path) -> Result<SqliteStore, StoreError> {
        std::fs::create_dir_all(dir)
            .map_err(|e| backend(format!("cannot create `{}`: {e}", dir.display())))?;
        let path = dir.join(DB_FILE);
        let conn = Connection::open(&path)
            .map_err(|e| backend(format!("cannot open `{}`: {e}", path.display())))?;
        conn.busy_timeout(std::time::Duration::from_secs(10))
            .map_err(backend)?;
        let mode: String = conn
            .query_row("PRAGMA journal_mode=WAL", [], |r| r.get(0))
            .map_err(backend)?;
        if !mode.eq_ignore_ascii_case("wal") {
            return Err(backend(format!(
                "`{}` cannot use WAL mode (got `{mode}`)",
                path.display()
            )));
        }
        conn.execute_batch("PRAGMA synchronous=FULL; PRAGMA foreign_keys=ON;")
            .map_err(backend)?;
        let version: i64 = conn
            .query_row("PRAGMA user_version", [], |r| r.get(0))
            .map_err(backend)?;
        if version > SCHEMA_VERSION {
            return Err(corrupt(
                path.display().to_string(),
                format!("schema version {version} is newer than this program's {SCHEMA_VERSION}"),
            ));
        }
        conn.execute_batch(SCHEMA).map_err(backend)?;
        conn.execute_batch(leases::SCHEMA).map_err(backend)?;
        conn.execute_batch(poses::SCHEMA).map_err(backend)?;
        conn.pragma_update(None, "user_version", SCHEMA_VERSION)
            .map_err(backend)?;
        Ok(SqliteStore {
            conn: Mutex::new(conn),
            path,
        })
    }

    /// The database file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Runs SQLite's `PRAGMA integrity_check`; any finding is
    /// [`StoreError::Corrupt`].
    pub fn integrity_check(&self) -> Result<(), StoreError> {
        let conn = self.conn.lock();
        let mut stmt = conn.prepare("PRAGMA integrity_check").map_err(backend)?;
        let rows: Vec<String> = stmt
            .query_map([], |r| r.get(0))
            .map_err(backend)?
            .collect::<Result<_, _>>()
            .map_err(backend)?;
        if rows == ["ok"] {
            Ok(())
        } else {
            Err(corrupt(self.path.display().to_string(), rows.join("; ")))
        }
    }
}

/// A [`SELECT_SESSION`] row.
fn record_row(r: &rusqlite::Row<'_>) -> rusqlite::Result<RecordRow> {
    Ok(RecordRow {
        id: r.get(0)?,
        mesh_id: r.get(1)?,
        token_sha256: r.get(2)?,
        params: r.get(3)?,
        constraints: r.get(4)?,
        created_unix: r.get(5)?,
    })
}

impl MeshStore for SqliteStore {
    fn put_mesh(&self, id: &str, mesh: Arc<Mesh>) -> Result<(), StoreError> {
        let (p, t) = (
            encode_points(mesh.positions()),
            encode_triangles(mesh.triangles()),
        );
        self.conn
            .lock()
            .execute(
                "INSERT OR REPLACE INTO meshes (id, positions, triangles) VALUES (?1, ?2, ?3)",
                params![id, p, t],
            )
            .map_err(backend)?;
        Ok(())
    }

    fn get_mesh(&self, id: &str) -> Result<Option<Arc<Mesh>>, StoreError> {
        let row: Option<(Vec<u8>, Vec<u8>)> = self
            .conn
            .lock()
            .query_row(
                "SELECT positions, triangles FROM meshes WHERE id = ?1",
                [id],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
            .map_err(backend)?;
        let Some((p, t)) = row else { return Ok(None) };
        let what = format!("mesh `{id}`");
        let mesh = Mesh::new(decode_points(&p, &what)?, decode_triangles(&t, &what)?)
            .map_err(|e| corrupt(&what, e.to_string()))?;
        Ok(Some(Arc::new(mesh)))
    }

    fn mesh_count(&self) -> Result<usize, StoreError> {
        let n: i64 = self
            .conn
            .lock()
            .query_row("SELECT COUNT(*) FROM meshes", [], |r| r.get(0))
            .map_err(backend)?;
        Ok(n as usize)
    }

    fn put_asset(&self, id: &str, asset: &StoredAsset) -> Result<(), StoreError> {
        assets::put(&self.conn.lock(), id, asset)
    }

    fn get_asset(&self, id: &str) -> Result<Option<StoredAsset>, StoreError> {
        assets::get(&self.conn.lock(), id)
    }

    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError> {
        assets::delete_mesh(&mut self.conn.lock(), id)
    }
}

impl SessionLog for SqliteStore {
    fn put_session(&self, r: &SessionRecord) -> Result<(), StoreError> {
        let row = RecordRow::encode(r)?;
        // An upsert, not INSERT OR REPLACE: a replace would delete the row and
        // cascade to its journal and checkpoint.
        self.conn
            .lock()
            .execute(
                "INSERT INTO sessions (id, mesh_id, token_sha256, params, constraints, created_unix)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6)
                 ON CONFLICT(id) DO UPDATE SET mesh_id = excluded.mesh_id, token_sha256 = excluded.token_sha256,
                   params = excluded.params, constraints = excluded.constraints,
                   created_unix = excluded.created_unix",
                params![
                    row.id,
                    row.mesh_id,
                    row.token_sha256,
                    row.params,
                    row.constraints,
                    row.created_unix
                ],
            )
            .map_err(backend)?;
        Ok(())
    }

    fn get_session(&self, id: &str) -> Result<Option<SessionRecord>, StoreError> {
        let row = self
            .conn
            .lock()
            .query_row(&format!("{SELECT_SESSION} WHERE id = ?1"), [id], record_row)
            .optional()
            .map_err(backend)?;
        row.map(RecordRow::decode).transpose()
    }

    fn list_sessions(&self) -> Result<Vec<SessionRecord>, StoreError> {
        let rows: Vec<RecordRow> = {
            let conn = self.conn.lock();
            let mut stmt = conn
                .prepare(&format!("{SELECT_SESSION} ORDER BY created_unix, id"))
                .map_err(backend)?;
            let rows = stmt.query_map([], record_row).map_err(backend)?;
            rows.collect::<Result<_, _>>().map_err(backend)?
        };
        rows.into_iter().map(RecordRow::decode).collect()
    }

    fn delete_session(&self, id: &str) -> Result<(), StoreError> {
        let mut conn = self.conn.lock();
        let tx = conn.transaction().map_err(backend)?;
        let _ = tx
            .execute("DELETE FROM sessions WHERE id = ?1", [id])
            .map_err(backend)?;
        let _ = tx
            .execute("DELETE FROM leases WHERE session = ?1", [id])
            .map_err(backend)?;
        tx.commit().map_err(backend)
    }

    fn set_constraints(
        &self,
        id: &str,
        fence: Fence,
        spec: &serde_json::Value,
    ) -> Result<(), StoreError> {
        let mut conn = self.conn.lock();
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(backend)?;
        leases::check_fence(&tx, id, fence)?;
        let n = tx.execute(
            "UPDATE sessions SET constraints = ?2 WHERE id = ?1",
            params![id, spec.to_string()],
        );
        if n.map_err(backend)? == 0 {
            return Err(missing(id));
        }
        let _ = tx
            .execute("DELETE FROM journal WHERE session = ?1", [id])
            .map_err(backend)?;
        let _ = tx
            .execute("DELETE FROM checkpoints WHERE session = ?1", [id])
            .map_err(backend)?;
        tx.commit().map_err(backend)
    }

    fn append(&self, id: &str, fence: Fence, entries: &[JournalEntry]) -> Result<(), StoreError> {
        let mut conn = self.conn.lock();
        let tx = fenced(&mut conn, id, fence)?;
        {
            let mut stmt = tx
                .prepare_cached("INSERT INTO journal (session, entry) VALUES (?1, ?2)")
                .map_err(backend)?;
            for e in entries {
                let _ = stmt
                    .execute(params![id, encode_entry(e)])
                    .map_err(backend)?;
            }
        }
        tx.commit().map_err(backend)
    }

    fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError> {
        let blobs: Vec<(i64, Vec<u8>)> = {
            let conn = self.conn.lock();
            let mut stmt = conn
                .prepare_cached("SELECT n, entry FROM journal WHERE session = ?1 ORDER BY n")
                .map_err(backend)?;
            let rows = stmt
                .query_map([id], |r| Ok((r.get(0)?, r.get(1)?)))
                .map_err(backend)?;
            rows.collect::<Result<_, _>>().map_err(backend)?
        };
        blobs
            .iter()
            .map(|(n, b)| decode_entry(b, &format!("journal entry {n} of session `{id}`")))
            .collect()
    }

    fn checkpoint(&self, id: &str, fence: Fence, cp: &Checkpoint) -> Result<(), StoreError> {
        let (pose, targets) = (encode_points(&cp.pose), encode_targets(&cp.targets));
        let revision = i64::try_from(cp.revision).unwrap_or(i64::MAX);
        let ack_seq = cp.ack_seq as i64; // the u64's bits, cast back on read
        let mut conn = self.conn.lock();
        let tx = fenced(&mut conn, id, fence)?;
        let _ = tx
            .execute(
                "INSERT OR REPLACE INTO checkpoints (session, revision, ack_seq, pose, targets)
                 VALUES (?1, ?2, ?3, ?4, ?5)",
                params![id, revision, ack_seq, pose, targets],
            )
            .map_err(backend)?;
        let _ = tx
            .execute("DELETE FROM journal WHERE session = ?1", [id])
            .map_err(backend)?;
        tx.commit().map_err(backend)
    }

    fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError> {
        let row: Option<(i64, i64, Vec<u8>, Vec<u8>)> = self
            .conn
            .lock()
            .query_row(
                "SELECT revision, ack_seq, pose, targets FROM checkpoints WHERE session = ?1",
                [id],
                |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?, r.get(3)?)),
            )
            .optional()
            .map_err(backend)?;
        let Some((revision, ack_seq, pose, targets)) = row else {
            return Ok(None);
        };
        decode_checkpoint(revision, ack_seq, &pose, &targets, id).map(Some)
    }
}

impl LeaseStore for SqliteStore {
    fn acquire_lease(
        &self,
        id: &str,
        owner: &str,
        ttl: std::time::Duration,
    ) -> Result<LeaseGrant, StoreError> {
        leases::acquire(&mut self.conn.lock(), id, owner, ttl)
    }

    fn renew_leases(
        &self,
        owner: &str,
        leases: &[(String, Fence)],
        ttl: std::time::Duration,
    ) -> Result<Vec<String>, StoreError> {
        leases::renew(&mut self.conn.lock(), owner, leases, ttl)
    }

    fn release_lease(&self, id: &str, owner: &str, revision: Fence) -> Result<(), StoreError> {
        leases::release(&self.conn.lock(), id, owner, revision)
    }

    fn handoffs_wanted(&self, owner: &str) -> Result<Vec<String>, StoreError> {
        leases::wanted(&self.conn.lock(), owner)
    }
    fn ping(&self) -> Result<(), StoreError> {
        Ok(())
    }
    /// One process uses this store: there is no owner liveness to announce.
    fn announce_liveness(&self, _instance: &str) -> Result<(), StoreError> {
        Ok(())
    }
}

impl PoseStore for SqliteStore {
    fn put_named_pose(&self, id: &str, fence: Fence, pose: &NamedPose) -> Result<(), StoreError> {
        poses::put(&mut self.conn.lock(), id, fence, pose)
    }

    fn rename_named_pose(
        &self,
        id: &str,
        fence: Fence,
        from: &str,
        to: &str,
    ) -> Result<(), StoreError> {
        poses::rename(&mut self.conn.lock(), id, fence, from, to)
    }

    fn delete_named_pose(&self, id: &str, fence: Fence, name: &str) -> Result<(), StoreError> {
        poses::delete(&mut self.conn.lock(), id, fence, name)
    }

    fn named_poses(&self, id: &str) -> Result<Vec<NamedPose>, StoreError> {
        poses::list(&self.conn.lock(), id)
    }
}

#[cfg(test)]
mod tests;
