//! [`PgStore`]: the [`Store`] several `dend serve` instances share, in one
//! PostgreSQL database.
//!
//! - The synchronous `postgres` client pooled by r2d2 (the trait is
//!   synchronous and the server calls it from blocking threads). Checkout
//!   waits at most [`POOL_TIMEOUT`] and tests the connection first, so a
//!   restarted server costs one failed call per pooled connection at most.
//! - Versioned migrations ([`MIGRATIONS`]) applied at open under an
//!   advisory lock (instances starting together apply each once), recorded
//!   in `dend_schema_migrations`; a database migrated by a newer program
//!   (a version this one does not know) is refused.
//! - The same binary encodings as the SQLite store (`codec`), in `bytea`.
//! - Every commit is durable when it returns (PostgreSQL's default
//!   `synchronous_commit=on`), so an acknowledged drag is on disk.
//! - Errors: a lost or refused connection, a server shutting down or a pool
//!   timeout is [`StoreError::Unavailable`]; other failures `Backend`.

mod conn;
mod leases;
mod liveness;
mod poses;

pub use liveness::liveness_name;

use std::sync::Arc;
use std::time::Duration;

use postgres::NoTls;
use r2d2_postgres::PostgresConnectionManager;

use super::codec::{
    corrupt, decode_checkpoint, decode_entry, decode_points, decode_triangles, encode_entry,
    encode_points, encode_targets, encode_triangles, RecordRow, SELECT_SESSION,
};
use super::traits::{LeaseStore, MeshStore, PoseStore, SessionLog};
use super::types::{
    Checkpoint, Fence, JournalEntry, LeaseGrant, NamedPose, SessionRecord, StoreError, StoredAsset,
};
use conn::{pg_err, Conn};
use dend::mesh::Mesh;

/// The newest schema version this program knows (the last of [`MIGRATIONS`]).
pub const PG_SCHEMA_VERSION: i32 = 3;

/// How long a store call waits for a pooled connection (or a new one).
pub const POOL_TIMEOUT: Duration = Duration::from_secs(2);

/// How long the readiness ping waits for a connection.
pub const PING_TIMEOUT: Duration = Duration::from_millis(500);

/// How long the server lets one of our connections sit idle inside a
/// transaction before it ends that connection
/// (`idle_in_transaction_session_timeout`). Our transactions are a few
/// statements sent back to back, so only a frozen or stalled instance
/// (SIGSTOP, a long GC-like pause, a half-dead network) ever reaches it;
/// without it, a fenced write frozen after its `FOR SHARE` would hold the
/// lease row, and every other instance's takeover would wait for the frozen
/// one to wake up: the lease would not protect against a frozen owner.
pub const IDLE_IN_TRANSACTION_TIMEOUT: Duration = Duration::from_secs(5);

/// How long a statement waits for a row lock (`lock_timeout`) before it
/// fails as [`StoreError::Unavailable`] (SQLSTATE 55P03) and the caller
/// retries: a backstop above [`IDLE_IN_TRANSACTION_TIMEOUT`].
pub const LOCK_TIMEOUT: Duration = Duration::from_secs(15);

/// The server settings every pooled connection starts with, appended to
/// the `options` the URL may already carry.
fn session_options(existing: Option<&str>) -> String {
    let ours = format!(
        "-c idle_in_transaction_session_timeout={} -c lock_timeout={}",
        IDLE_IN_TRANSACTION_TIMEOUT.as_millis(),
        LOCK_TIMEOUT.as_millis()
    );
    match existing {
        Some(o) if !o.trim().is_empty() => format!("{o} {ours}"),
        _ => ours,
    }
}

/// The migrations, in order: `(version, SQL)`.
pub const MIGRATIONS: &[(i32, &str)] = &[
    (
        1,
        "CREATE TABLE meshes (id TEXT PRIMARY KEY, positions BYTEA NOT NULL, triangles BYTEA NOT NULL);
         CREATE TABLE mesh_assets (id TEXT PRIMARY KEY, format TEXT NOT NULL, bytes BYTEA NOT NULL);
         CREATE TABLE sessions (
             id TEXT PRIMARY KEY, mesh_id TEXT NOT NULL, token_sha256 BYTEA NOT NULL,
             params TEXT NOT NULL, constraints TEXT, created_unix BIGINT NOT NULL);
         CREATE TABLE journal (
             n BIGSERIAL PRIMARY KEY,
             session TEXT NOT NULL REFERENCES sessions(id) ON DELETE CASCADE,
             entry BYTEA NOT NULL);
         CREATE INDEX journal_session ON journal(session, n);
         CREATE TABLE checkpoints (
             session TEXT PRIMARY KEY REFERENCES sessions(id) ON DELETE CASCADE,
             revision BIGINT NOT NULL, ack_seq BIGINT NOT NULL,
             pose BYTEA NOT NULL, targets BYTEA NOT NULL);",
    ),
    (
        2,
        "CREATE TABLE leases (
             session TEXT PRIMARY KEY, owner TEXT NOT NULL,
             revision BIGINT NOT NULL, expires TIMESTAMPTZ, wanted_by TEXT);",
    ),
    (3, poses::MIGRATION),
];

type Pool = r2d2::Pool<PostgresConnectionManager<NoTls>>;

/// A [`Store`] in a PostgreSQL database (see the module docs).
pub struct PgStore {
    /// `Some` until dropped (see `Drop`).
    pool: Option<Pool>,
    /// The pool's connection settings (for the liveness connection).
    config: postgres::Config,
    /// The liveness connection, once announced ([`Store::announce_liveness`]).
    liveness: parking_lot::Mutex<Option<liveness::Liveness>>,
}

fn missing(id: &str) -> StoreError {
    StoreError::Missing(id.to_string())
}

impl PgStore {
    /// Connects to `url` (`postgres://user@host:port/db`), builds a pool of
    /// up to `max_connections` and applies the pending migrations.
    pub fn open(url: &str, max_connections: u32) -> Result<PgStore, StoreError> {
        let config: postgres::Config = url
            .parse()
            .map_err(|e| StoreError::Backend(format!("bad PostgreSQL URL: {e}")))?;
        Self::open_config(config, max_connections)
    }

    /// [`open`](Self::open) with a parsed client configuration.
    pub fn open_config(
        mut config: postgres::Config,
        max_connections: u32,
    ) -> Result<PgStore, StoreError> {
        if config.get_connect_timeout().is_none() {
            let _ = config.connect_timeout(POOL_TIMEOUT);
        }
        let _ = config.application_name("dend");
        let options = session_options(config.get_options());
        let _ = config.options(&options);
        let manager = PostgresConnectionManager::new(config.clone(), NoTls);
        let pool = r2d2::Pool::builder()
            .max_size(max_connections.max(1))
            .min_idle(Some(1))
            .connection_timeout(POOL_TIMEOUT)
            .test_on_check_out(true)
            .build(manager)
            .map_err(|e| StoreError::Unavailable(format!("cannot connect to PostgreSQL: {e}")))?;
        let store = PgStore {
            pool: Some(pool),
            config,
            liveness: parking_lot::Mutex::new(None),
        };
        store.migrate()?;
        Ok(store)
    }

    /// A pooled connection, or [`StoreError::Unavailable`].
    pub(super) fn conn(&self) -> Result<Conn, StoreError> {
        let pool = self
            .pool
            .as_ref()
            .ok_or_else(|| StoreError::Unavailable("store closed".into()))?;
        pool.get()
            .map_err(|e| StoreError::Unavailable(format!("no PostgreSQL connection: {e}")))
    }

    /// Applies every migration newer than the database's version, each in
    /// its own transaction, under a transaction-level advisory lock.
    fn migrate(&self) -> Result<(), StoreError> {
        let mut c = self.conn()?;
        let mut tx = c.transaction().map_err(pg_err)?;
        let _ = tx
            .execute("SELECT pg_advisory_xact_lock(7720211)", &[])
            .map_err(pg_err)?;
        let _ = tx
            .execute(
                "CREATE TABLE IF NOT EXISTS dend_schema_migrations (
                     version INT PRIMARY KEY, applied_at TIMESTAMPTZ NOT NULL DEFAULT now())",
                &[],
            )
            .map_err(pg_err)?;
        let current: i32 = tx
            .query_one(
                "SELECT COALESCE(MAX(version), 0) FROM dend_schema_migrations",
                &[],
            )
            .map_err(pg_err)?
            .get(0);
        if current > PG_SCHEMA_VERSION {
            return Err(corrupt(
                "PostgreSQL schema",
                format!("version {current} is newer than this program's {PG_SCHEMA_VERSION}"),
            ));
        }
        for (version, sql) in MIGRATIONS.iter().filter(|(v, _)| *v > current) {
            tx.batch_execute(sql).map_err(pg_err)?;
            let _ = tx
                .execute(
                    "INSERT INTO dend_schema_migrations (version) VALUES ($1)",
                    &[version],
                )
                .map_err(pg_err)?;
            tracing::info!(version, "applied a PostgreSQL schema migration");
        }
        tx.commit().map_err(pg_err)
    }

    /// The schema version the database is at.
    pub fn schema_version(&self) -> Result<i32, StoreError> {
        Ok(self
            .conn()?
            .query_one("SELECT MAX(version) FROM dend_schema_migrations", &[])
            .map_err(pg_err)?
            .get(0))
    }

    /// Runs SQL statements as they are (tests and maintenance).
    pub fn execute_batch(&self, sql: &str) -> Result<(), StoreError> {
        self.conn()?.batch_execute(sql).map_err(pg_err)
    }
}

impl Drop for PgStore {
    /// Drops the pool on a plain thread: each `postgres` client owns a small
    /// tokio runtime, which must not be dropped inside an async context
    /// (the server drops its state at the end of its runtime).
    fn drop(&mut self) {
        if let Some(pool) = self.pool.take() {
            let _ = std::thread::spawn(move || drop(pool)).join();
        }
    }
}

/// Whether session `id` exists; inside a transaction.
fn session_exists(tx: &mut postgres::Transaction<'_>, id: &str) -> Result<bool, StoreError> {
    Ok(tx
        .query_opt("SELECT 1 FROM sessions WHERE id = $1", &[&id])
        .map_err(pg_err)?
        .is_some())
}

/// The record of a [`SELECT_SESSION`] row.
fn row_record(r: &postgres::Row) -> Result<SessionRecord, StoreError> {
    RecordRow {
        id: r.get(0),
        mesh_id: r.get(1),
        token_sha256: r.get(2),
        params: r.get(3),
        constraints: r.get(4),
        created_unix: r.get(5),
    }
    .decode()
}

impl MeshStore for PgStore {
    fn put_mesh(&self, id: &str, mesh: Arc<Mesh>) -> Result<(), StoreError> {
        let (p, t) = (
            encode_points(mesh.positions()),
            encode_triangles(mesh.triangles()),
        );
        let _ = self
            .conn()?
            .execute(
                "INSERT INTO meshes (id, positions, triangles) VALUES ($1, $2, $3)
                 ON CONFLICT (id) DO UPDATE SET positions = excluded.positions,
                   triangles = excluded.triangles",
                &[&id, &p, &t],
            )
            .map_err(pg_err)?;
        Ok(())
    }

    fn get_mesh(&self, id: &str) -> Result<Option<Arc<Mesh>>, StoreError> {
        let Some(row) = self
            .conn()?
            .query_opt(
                "SELECT positions, triangles FROM meshes WHERE id = $1",
                &[&id],
            )
            .map_err(pg_err)?
        else {
            return Ok(None);
        };
        let (p, t): (Vec<u8>, Vec<u8>) = (row.get(0), row.get(1));
        let what = format!("mesh `{id}`");
        let mesh = Mesh::new(decode_points(&p, &what)?, decode_triangles(&t, &what)?)
            .map_err(|e| corrupt(&what, e.to_string()))?;
        Ok(Some(Arc::new(mesh)))
    }

    fn mesh_count(&self) -> Result<usize, StoreError> {
        let n: i64 = self
            .conn()?
            .query_one("SELECT COUNT(*) FROM meshes", &[])
            .map_err(pg_err)?
            .get(0);
        Ok(n as usize)
    }

    fn put_asset(&self, id: &str, a: &StoredAsset) -> Result<(), StoreError> {
        let _ = self
            .conn()?
            .execute(
                "INSERT INTO mesh_assets (id, format, bytes) VALUES ($1, $2, $3)
                 ON CONFLICT (id) DO UPDATE SET format = excluded.format, bytes = excluded.bytes",
                &[&id, &a.format, &a.bytes],
            )
            .map_err(pg_err)?;
        Ok(())
    }

    fn get_asset(&self, id: &str) -> Result<Option<StoredAsset>, StoreError> {
        Ok(self
            .conn()?
            .query_opt(
                "SELECT format, bytes FROM mesh_assets WHERE id = $1",
                &[&id],
            )
            .map_err(pg_err)?
            .map(|r| StoredAsset {
                format: r.get(0),
                bytes: r.get(1),
            }))
    }

    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError> {
        let mut c = self.conn()?;
        let mut tx = c.transaction().map_err(pg_err)?;
        let _ = tx
            .execute("DELETE FROM mesh_assets WHERE id = $1", &[&id])
            .map_err(pg_err)?;
        let n = tx
            .execute("DELETE FROM meshes WHERE id = $1", &[&id])
            .map_err(pg_err)?;
        tx.commit().map_err(pg_err)?;
        Ok(n > 0)
    }
}

impl SessionLog for PgStore {
    fn put_session(&self, r: &SessionRecord) -> Result<(), StoreError> {
        let row = RecordRow::encode(r)?;
        let _ = self
            .conn()?
            .execute(
                "INSERT INTO sessions (id, mesh_id, token_sha256, params, constraints, created_unix)
                 VALUES ($1, $2, $3, $4, $5, $6)
                 ON CONFLICT (id) DO UPDATE SET mesh_id = excluded.mesh_id,
                   token_sha256 = excluded.token_sha256, params = excluded.params,
                   constraints = excluded.constraints, created_unix = excluded.created_unix",
                &[
                    &row.id,
                    &row.mesh_id,
                    &row.token_sha256,
                    &row.params,
                    &row.constraints,
                    &row.created_unix,
                ],
            )
            .map_err(pg_err)?;
        Ok(())
    }

    fn get_session(&self, id: &str) -> Result<Option<SessionRecord>, StoreError> {
        self.conn()?
            .query_opt(&format!("{SELECT_SESSION} WHERE id = $1"), &[&id])
            .map_err(pg_err)?
            .map(|r| row_record(&r))
            .transpose()
    }

    fn list_sessions(&self) -> Result<Vec<SessionRecord>, StoreError> {
        self.conn()?
            .query(&format!("{SELECT_SESSION} ORDER BY created_unix, id"), &[])
            .map_err(pg_err)?
            .iter()
            .map(row_record)
            .collect()
    }

    fn delete_session(&self, id: &str) -> Result<(), StoreError> {
        let mut c = self.conn()?;
        let mut tx = c.transaction().map_err(pg_err)?;
        let _ = tx
            .execute("DELETE FROM sessions WHERE id = $1", &[&id])
            .map_err(pg_err)?;
        let _ = tx
            .execute("DELETE FROM leases WHERE session = $1", &[&id])
            .map_err(pg_err)?;
        tx.commit().map_err(pg_err)
    }

    fn set_constraints(
        &self,
        id: &str,
        fence: Fence,
        spec: &serde_json::Value,
    ) -> Result<(), StoreError> {
        let mut c = self.conn()?;
        let mut tx = c.transaction().map_err(pg_err)?;
        leases::check_fence(&mut tx, id, fence)?;
        let n = tx
            .execute(
                "UPDATE sessions SET constraints = $2 WHERE id = $1",
                &[&id, &spec.to_string()],
            )
            .map_err(pg_err)?;
        if n == 0 {
            return Err(missing(id));
        }
        let _ = tx
            .execute("DELETE FROM journal WHERE session = $1", &[&id])
            .map_err(pg_err)?;
        let _ = tx
            .execute("DELETE FROM checkpoints WHERE session = $1", &[&id])
            .map_err(pg_err)?;
        tx.commit().map_err(pg_err)
    }

    fn append(&self, id: &str, fence: Fence, entries: &[JournalEntry]) -> Result<(), StoreError> {
        let mut c = self.conn()?;
        let mut tx = c.transaction().map_err(pg_err)?;
        if !session_exists(&mut tx, id)? {
            return Err(missing(id));
        }
        leases::check_fence(&mut tx, id, fence)?;
        let stmt = tx
            .prepare("INSERT INTO journal (session, entry) VALUES ($1, $2)")
            .map_err(pg_err)?;
        for e in entries {
            let _ = tx
                .execute(&stmt, &[&id, &encode_entry(e)])
                .map_err(pg_err)?;
        }
        tx.commit().map_err(pg_err)
    }

    fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError> {
        self.conn()?
            .query(
                "SELECT n, entry FROM journal WHERE session = $1 ORDER BY n",
                &[&id],
            )
            .map_err(pg_err)?
            .iter()
            .map(|r| {
                let n: i64 = r.get(0);
                let b: Vec<u8> = r.get(1);
                decode_entry(&b, &format!("journal entry {n} of session `{id}`"))
            })
            .collect()
    }

    fn checkpoint(&self, id: &str, fence: Fence, cp: &Checkpoint) -> Result<(), StoreError> {
        let (pose, targets) = (encode_points(&cp.pose), encode_targets(&cp.targets));
        let revision = i64::try_from(cp.revision).unwrap_or(i64::MAX);
        let ack_seq = cp.ack_seq as i64; // the u64's bits, cast back on read
        let mut c = self.conn()?;
        let mut tx = c.transaction().map_err(pg_err)?;
        if !session_exists(&mut tx, id)? {
            return Err(missing(id));
        }
        leases::check_fence(&mut tx, id, fence)?;
        let _ = tx
            .execute(
                "INSERT INTO checkpoints (session, revision, ack_seq, pose, targets)
                 VALUES ($1, $2, $3, $4, $5)
                 ON CONFLICT (session) DO UPDATE SET revision = excluded.revision,
                   ack_seq = excluded.ack_seq, pose = excluded.pose, targets = excluded.targets",
                &[&id, &revision, &ack_seq, &pose, &targets],
            )
            .map_err(pg_err)?;
        let _ = tx
            .execute("DELETE FROM journal WHERE session = $1", &[&id])
            .map_err(pg_err)?;
        tx.commit().map_err(pg_err)
    }

    fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError> {
        let Some(r) = self
            .conn()?
            .query_opt(
                "SELECT revision, ack_seq, pose, targets FROM checkpoints WHERE session = $1",
                &[&id],
            )
            .map_err(pg_err)?
        else {
            return Ok(None);
        };
        let (pose, targets): (Vec<u8>, Vec<u8>) = (r.get(2), r.get(3));
        decode_checkpoint(r.get(0), r.get(1), &pose, &targets, id).map(Some)
    }
}

impl LeaseStore for PgStore {
    fn acquire_lease(
        &self,
        id: &str,
        owner: &str,
        ttl: Duration,
    ) -> Result<LeaseGrant, StoreError> {
        leases::acquire(&mut self.conn()?, id, owner, ttl)
    }

    fn renew_leases(
        &self,
        owner: &str,
        leases: &[(String, Fence)],
        ttl: Duration,
    ) -> Result<Vec<String>, StoreError> {
        leases::renew(&mut self.conn()?, owner, leases, ttl)
    }

    fn release_lease(&self, id: &str, owner: &str, revision: Fence) -> Result<(), StoreError> {
        leases::release(&mut self.conn()?, id, owner, revision)
    }

    fn handoffs_wanted(&self, owner: &str) -> Result<Vec<String>, StoreError> {
        leases::wanted(&mut self.conn()?, owner)
    }

    fn ping(&self) -> Result<(), StoreError> {
        let pool = self
            .pool
            .as_ref()
            .ok_or_else(|| StoreError::Unavailable("store closed".into()))?;
        let mut c = pool
            .get_timeout(PING_TIMEOUT)
            .map_err(|e| StoreError::Unavailable(format!("no PostgreSQL connection: {e}")))?;
        let _ = c.query_one("SELECT 1", &[]).map_err(pg_err)?;
        Ok(())
    }

    /// Opens the liveness connection (`liveness`) on a thread of
    /// its own; call it outside an async runtime's worker.
    fn announce_liveness(&self, instance: &str) -> Result<(), StoreError> {
        let live = liveness::start(&self.config, instance)?;
        *self.liveness.lock() = Some(live);
        Ok(())
    }
}

impl PoseStore for PgStore {
    /// A connection within [`PING_TIMEOUT`] (tested on checkout), so that
    /// readiness answers fast when the server is gone.
    fn put_named_pose(&self, id: &str, fence: Fence, pose: &NamedPose) -> Result<(), StoreError> {
        poses::put(&mut self.conn()?, id, fence, pose)
    }

    fn rename_named_pose(
        &self,
        id: &str,
        fence: Fence,
        from: &str,
        to: &str,
    ) -> Result<(), StoreError> {
        poses::rename(&mut self.conn()?, id, fence, from, to)
    }

    fn delete_named_pose(&self, id: &str, fence: Fence, name: &str) -> Result<(), StoreError> {
        poses::delete(&mut self.conn()?, id, fence, name)
    }

    fn named_poses(&self, id: &str) -> Result<Vec<NamedPose>, StoreError> {
        poses::list(&mut self.conn()?, id)
    }
}

#[cfg(test)]
mod tests;
