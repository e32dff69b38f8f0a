//! Persistence of meshes, sessions, constraints, poses and edit history.
//!
//! [`Store`] is the seam between the server and its storage. It is four
//! traits, one per concern: [`MeshStore`] (meshes and their source files),
//! [`SessionLog`] (session records, constraint sets, the journal and
//! checkpoints), [`LeaseStore`] (leases and liveness between instances) and
//! [`PoseStore`] (named poses). A wrapper that adds behaviour to every call
//! is a [`Layer`] on [`Layered`]: the timing of the `dend_store_seconds`
//! histogram (`timed_store.rs`) and the tests' fault injection ([`Faults`]). The server
//! writes through it *before* it acknowledges anything to a client:
//! - a mesh is stored before its id is returned;
//! - a session record (with the SHA-256 hash of its token, never the token)
//!   before the session id is returned;
//! - the constraints spec before `202 Accepted`;
//! - every drag delta is appended to the session's journal before the frame
//!   that acknowledges its sequence number is published (see
//!   [`SessionLog::append`]), so a crash-safe implementation that makes `append`
//!   durable (an fsynced WAL) loses no acknowledged drag;
//! - at each history commit point, and at every undo/redo/reset, a
//!   [`Checkpoint`] (pose + targets) replaces the journal up to it
//!   ([`SessionLog::checkpoint`]). The undo history itself is not persisted.
//!
//! Recovering a session = its record + its last checkpoint + replaying the
//! journal entries after it. [`SqliteStore`] (WAL, fsynced appends) is the
//! server's default; [`MemoryStore`] keeps nothing across restarts.
//!
//! All methods are synchronous and may block briefly (disk I/O); the server
//! calls the per-drag ones ([`SessionLog::append`]) from its blocking solver pool.
//!
//! [`PgStore`] (PostgreSQL) is the store several instances share. Each live
//! session is then *leased* by one instance ([`LeaseStore::acquire_lease`]): a
//! row naming the owner, an expiry the owner keeps pushing forward
//! ([`LeaseStore::renew_leases`]) and a revision that grows by one with every
//! new ownership. The revision is the session's fencing token: every
//! journal write ([`SessionLog::append`], [`SessionLog::checkpoint`],
//! [`SessionLog::set_constraints`]) carries it, and the store refuses it with
//! [`StoreError::Fenced`] once another instance has taken the lease over.
//! A fence of [`NO_FENCE`] (the single-instance stores' mode) skips the check.
//!
//! A session's [`NamedPose`]s (poses saved under a name, for restoring and
//! exporting as morph targets) are kept beside its journal: written
//! before the save, rename or delete is acknowledged, fenced like the
//! journal, deleted with the session, and kept across constraint edits.

mod codec;
mod faults;
mod lease_rule;
mod memory;
mod postgres;
mod sqlite;
#[cfg(test)]
mod suite;
mod traits;
mod types;

pub use codec::{decode_entry, encode_entry};
pub use faults::{with_faults, FaultStore, Faults};
pub use memory::MemoryStore;
pub use postgres::liveness_name;
pub use postgres::{PgStore, PG_SCHEMA_VERSION};
pub use sqlite::{SqliteStore, DB_FILE, SCHEMA_VERSION};
pub use traits::{Call, Layer, Layered, LeaseStore, MeshStore, PoseStore, SessionLog, Store};
pub use types::{
    Checkpoint, Fence, JournalEntry, LeaseGrant, NamedPose, SessionRecord, StoreError, StoredAsset,
    StoredTransform, NO_FENCE,
};
