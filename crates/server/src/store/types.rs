//! The records the store keeps and its errors.

use serde::{Deserialize, Serialize};

/// Errors of a store.
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

/// The answer to [`LeaseStore::acquire_lease`](super::traits::LeaseStore::acquire_lease).
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
