//! Persistence of meshes, sessions, constraints, poses and edit history.
//!
//! [`Store`] is the seam between the server and its storage. The server
//! writes through it *before* it acknowledges anything to a client:
//! - a mesh is stored before its id is returned;
//! - a session record (with the SHA-256 hash of its token, never the token)
//!   before the session id is returned;
//! - the constraints spec before `202 Accepted`;
//! - every drag delta is appended to the session's journal before the frame
//!   that acknowledges its sequence number is published (see
//!   [`Store::append`]), so a crash-safe implementation that makes `append`
//!   durable (an fsynced WAL) loses no acknowledged drag;
//! - at each history commit point, and at every undo/redo/reset, a
//!   [`Checkpoint`] (pose + targets) replaces the journal up to it
//!   ([`Store::checkpoint`]). The undo history itself is not persisted.
//!
//! Recovering a session = its record + its last checkpoint + replaying the
//! journal entries after it. [`SqliteStore`] (WAL, fsynced appends) is the
//! server's default; [`MemoryStore`] keeps nothing across restarts.
//!
//! All methods are synchronous and may block briefly (disk I/O); the server
//! calls the per-drag ones ([`Store::append`]) from its blocking solver pool.
//!
//! [`PgStore`] (PostgreSQL) is the store several instances share. Each live
//! session is then *leased* by one instance ([`Store::acquire_lease`]): a
//! row naming the owner, an expiry the owner keeps pushing forward
//! ([`Store::renew_leases`]) and a revision that grows by one with every
//! new ownership. The revision is the session's fencing token: every
//! journal write ([`Store::append`], [`Store::checkpoint`],
//! [`Store::set_constraints`]) carries it, and the store refuses it with
//! [`StoreError::Fenced`] once another instance has taken the lease over.
//! A fence of [`NO_FENCE`] (the single-instance stores' mode) skips the check.
//!
//! A session's [`NamedPose`]s (poses saved under a name, for restoring and
//! exporting as morph targets) are kept beside its journal: written
//! before the save, rename or delete is acknowledged, fenced like the
//! journal, deleted with the session, and kept across constraint edits.

mod codec;
mod lease_rule;
mod memory;
mod postgres;
mod sqlite;
#[cfg(test)]
mod suite;

pub use codec::{decode_entry, encode_entry};
pub use memory::MemoryStore;
pub use postgres::liveness_name;
pub use postgres::{PgStore, PG_SCHEMA_VERSION};
pub use sqlite::{SqliteStore, DB_FILE, SCHEMA_VERSION};

use std::sync::Arc;
use std::time::Duration;

use serde::{Deserialize, Serialize};

use dend::mesh::Mesh;

/// Errors of a [`Store`].
#[derive(Debug, Clone, thiserror::Error)]
pub enum StoreError {
    /// The backend failed (I/O, database); the message says how. Fix: check
    /// the storage (disk full, permissions) — the request can be retried.
    #[error("storage backend failed: {0}")]
    Backend(String),
    /// A stored record could not be decoded (corruption or a format change).
    #[error("stored record `{what}` is corrupt: {reason}")]
    Corrupt {
        /// Which record.
        what: String,
        /// Why it could not be decoded.
        reason: String,
    },
    /// The store holds no session with this id (never created, or deleted,
    /// possibly by a request racing this one). Nothing was written.
    #[error("no session `{0}` in the store")]
    Missing(String),
    /// The store cannot be reached (connection refused or lost, server
    /// restarting, pool exhausted). Nothing was written; retry later.
    #[error("store unavailable: {0}")]
    Unavailable(String),
    /// A write carried a fencing token that is no longer the session's
    /// lease revision: another instance owns the session now. Nothing was
    /// written; this instance must stop driving the session.
    #[error(
        "session `{session}`: lease revision {fence} is stale (now {current:?}, held by {owner:?})"
    )]
    Fenced {
        /// The session.
        session: String,
        /// The revision the writer held.
        fence: Fence,
        /// The lease's current revision, if a lease exists.
        current: Option<Fence>,
        /// The current owner, if a lease exists.
        owner: Option<String>,
    },
}

/// A lease revision used as a fencing token (see the module docs).
pub type Fence = u64;

/// The fence of a writer that holds no lease (single-instance stores): the
/// store does not check it.
pub const NO_FENCE: Fence = 0;

/// The answer to [`Store::acquire_lease`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LeaseGrant {
    /// The caller owns the session now, under this revision.
    Granted {
        /// The new lease revision (the fencing token of its writes).
        revision: Fence,
        /// Whether another instance's expired lease was taken over.
        taken_over: bool,
    },
    /// Another instance holds an unexpired lease.
    HeldBy {
        /// The owner's instance id.
        owner: String,
        /// Milliseconds until the lease expires unless renewed.
        expires_in_ms: u64,
    },
}

/// The file a mesh was uploaded from, kept for the formats whose export
/// writes the pose back into the file's own layout (glTF/GLB, OBJ and PLY
/// assets, `dend::mesh::asset`): its bytes as received and its format name.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StoredAsset {
    /// The format's name (`glb`, `gltf`, `obj`, `ply`).
    pub format: String,
    /// The uploaded bytes.
    pub bytes: Vec<u8>,
}

/// A session as stored: everything needed to re-open it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionRecord {
    /// Session id (public).
    pub id: String,
    /// Id of the mesh the session edits.
    pub mesh_id: String,
    /// Lower-case hex SHA-256 of the access token (the token itself is never stored).
    pub token_sha256: String,
    /// Solver parameters, as the `dend::deform::Params` JSON.
    pub params: serde_json::Value,
    /// The constraints spec last set (the CLI's constraints JSON), if any.
    pub constraints: Option<serde_json::Value>,
    /// Creation time, seconds since the Unix epoch.
    pub created_unix: u64,
}

/// A rigid transform in storable form: unit quaternion `[x, y, z, w]`,
/// translation and pivot in mesh units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StoredTransform {
    /// Unit quaternion, `[x, y, z, w]`.
    pub rotation: [f64; 4],
    /// Translation.
    pub translation: [f64; 3],
    /// Pivot.
    pub pivot: [f64; 3],
}

/// One journaled event of a session, in arrival order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum JournalEntry {
    /// A drag delta on handle `handle` (index into the constraints' handles):
    /// target ← target.then(rotation, translation).
    Drag {
        /// Handle index.
        handle: usize,
        /// Delta rotation, unit quaternion `[x, y, z, w]`.
        rotation: [f64; 4],
        /// Delta translation (mesh units).
        translation: [f64; 3],
        /// The client's sequence number (0 for HTTP drags).
        seq: u64,
    },
}

/// A full snapshot of a session's editing state at a history commit point.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// Session revision at the snapshot.
    pub revision: u64,
    /// The last client sequence number included in `targets` (acknowledged
    /// in frames; 0 when none).
    #[serde(default)]
    pub ack_seq: u64,
    /// Current pose (mesh units), `#V×3`.
    pub pose: Vec<[f64; 3]>,
    /// Current handle targets, one per handle.
    pub targets: Vec<StoredTransform>,
}

/// A pose saved under a name in a session: the settled pose and handle
/// targets at the save, with the constraint set the targets belong to, so
/// that restoring it is exact and drags continue from it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NamedPose {
    /// The name (unique within the session).
    pub name: String,
    /// Save order within the session (larger: saved later); the order of
    /// the list, of the morph targets and of the export's animation.
    pub ordinal: u64,
    /// The session revision of the saved pose.
    pub revision: u64,
    /// When it was saved, seconds since the Unix epoch.
    pub created_unix: u64,
    /// The constraint set as stored (anchored) when the pose was saved;
    /// None when the session had none.
    pub constraints: Option<serde_json::Value>,
    /// The pose (mesh units), `#V×3`.
    pub pose: Vec<[f64; 3]>,
    /// The handle targets of `constraints`, one per handle.
    pub targets: Vec<StoredTransform>,
}

/// The error of a store that keeps no named poses (the default methods
/// below, kept for test doubles).
fn no_named_poses() -> StoreError {
    StoreError::Backend("this store keeps no named poses".into())
}

/// Storage of meshes and sessions (see the module docs for when the server
/// calls what). Implementations are shared as `Arc<dyn Store>`.
pub trait Store: Send + Sync + 'static {
    /// Stores a mesh under `id` (ids are unique; an existing id is replaced).
    fn put_mesh(&self, id: &str, mesh: Arc<Mesh>) -> Result<(), StoreError>;
    /// The mesh stored under `id`.
    fn get_mesh(&self, id: &str) -> Result<Option<Arc<Mesh>>, StoreError>;
    /// Number of stored meshes.
    fn mesh_count(&self) -> Result<usize, StoreError>;
    /// Stores the source file of mesh `id` (the server puts it before the
    /// mesh, so a stored mesh whose upload kept its file always has it).
    fn put_asset(&self, id: &str, asset: &StoredAsset) -> Result<(), StoreError>;
    /// The source file of mesh `id`, if one was kept.
    fn get_asset(&self, id: &str) -> Result<Option<StoredAsset>, StoreError>;
    /// Deletes mesh `id` and its source file (atomically); false when there
    /// was no such mesh. The server refuses while sessions use it.
    fn delete_mesh(&self, id: &str) -> Result<bool, StoreError>;
    /// Stores or replaces a session record.
    fn put_session(&self, record: &SessionRecord) -> Result<(), StoreError>;
    /// The session record stored under `id`.
    fn get_session(&self, id: &str) -> Result<Option<SessionRecord>, StoreError>;
    /// All stored session records (to re-open sessions after a restart).
    fn list_sessions(&self) -> Result<Vec<SessionRecord>, StoreError>;
    /// Deletes a session with its journal and checkpoint (a no-op if absent).
    fn delete_session(&self, id: &str) -> Result<(), StoreError>;
    /// Sets the constraints spec of a session and clears its journal and
    /// checkpoint (a new constraint set starts a new history). Fenced.
    fn set_constraints(
        &self,
        id: &str,
        fence: Fence,
        spec: &serde_json::Value,
    ) -> Result<(), StoreError>;
    /// Appends journal entries; must be durable when it returns. Fenced:
    /// unless `fence` is [`NO_FENCE`], it must be the session's current
    /// lease revision, else [`StoreError::Fenced`] and nothing is written.
    fn append(&self, id: &str, fence: Fence, entries: &[JournalEntry]) -> Result<(), StoreError>;
    /// The journal entries after the last checkpoint, oldest first.
    fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError>;
    /// Replaces the checkpoint and truncates the journal (atomically). Fenced.
    fn checkpoint(&self, id: &str, fence: Fence, checkpoint: &Checkpoint)
        -> Result<(), StoreError>;
    /// The last checkpoint.
    fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError>;
    /// Takes the lease of session `id` for instance `owner` for `ttl`: when
    /// there is none, it expired, or `owner` already holds it, the revision
    /// grows by one and is returned; otherwise the holder is named and the
    /// request recorded (see [`handoffs_wanted`](Store::handoffs_wanted)). Taking
    /// the lease waits for a write fenced by the old revision that is in
    /// flight, so a journal read after it sees every acknowledged write.
    fn acquire_lease(&self, id: &str, owner: &str, ttl: Duration)
        -> Result<LeaseGrant, StoreError>;
    /// Pushes the expiry of `owner`'s leases `(session, revision)` to now +
    /// `ttl`; returns the sessions whose lease `owner` no longer holds
    /// under that revision (taken over or deleted).
    fn renew_leases(
        &self,
        owner: &str,
        leases: &[(String, Fence)],
        ttl: Duration,
    ) -> Result<Vec<String>, StoreError>;
    /// Gives up `owner`'s lease of `id` under `revision` (a no-op when it is
    /// no longer held so).
    fn release_lease(&self, id: &str, owner: &str, revision: Fence) -> Result<(), StoreError>;
    /// The sessions `owner` leases that another instance asked for: an
    /// [`acquire_lease`](Store::acquire_lease) that found them held by
    /// `owner` (the load balancer routes them elsewhere now, e.g. to an
    /// instance that came back). The owner hands them over: it closes them
    /// and releases their leases. A grant clears the request.
    fn handoffs_wanted(&self, owner: &str) -> Result<Vec<String>, StoreError>;
    /// Stores a named pose of session `id`, replacing the one of the same
    /// name if any. Fenced. [`StoreError::Missing`] without the session.
    fn put_named_pose(&self, id: &str, fence: Fence, pose: &NamedPose) -> Result<(), StoreError> {
        let _ = (id, fence, pose);
        Err(no_named_poses())
    }
    /// Renames named pose `from` of session `id` to `to` (the caller checked
    /// that `to` is free; a no-op when there is no `from`). Fenced.
    fn rename_named_pose(
        &self,
        id: &str,
        fence: Fence,
        from: &str,
        to: &str,
    ) -> Result<(), StoreError> {
        let _ = (id, fence, from, to);
        Err(no_named_poses())
    }
    /// Deletes named pose `name` of session `id` (a no-op if absent). Fenced.
    fn delete_named_pose(&self, id: &str, fence: Fence, name: &str) -> Result<(), StoreError> {
        let _ = (id, fence, name);
        Err(no_named_poses())
    }
    /// The named poses of session `id`, by [`NamedPose::ordinal`] (none
    /// for an unknown session).
    fn named_poses(&self, id: &str) -> Result<Vec<NamedPose>, StoreError> {
        let _ = id;
        Ok(vec![])
    }
    /// Checks that the store answers (the readiness probe).
    fn ping(&self) -> Result<(), StoreError> {
        Ok(())
    }
    /// Announces `instance` as alive for as long as this store lives (the
    /// shared store's owner liveness: a lease whose owner is no longer
    /// announced is taken over without waiting for it to expire). A no-op
    /// for stores without leases shared between processes.
    fn announce_liveness(&self, instance: &str) -> Result<(), StoreError> {
        let _ = instance;
        Ok(())
    }
}

impl From<&dend::deform::RigidTransform> for StoredTransform {
    /// The stored form of a handle transform (quaternion `[x, y, z, w]`).
    fn from(t: &dend::deform::RigidTransform) -> Self {
        let q = t.rotation.coords;
        StoredTransform {
            rotation: [q.x, q.y, q.z, q.w],
            translation: t.translation,
            pivot: t.pivot,
        }
    }
}
