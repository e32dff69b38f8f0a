//! The store's traits, one per concern, and [`Layered`]: any store wrapped
//! by a [`Layer`] (timing, fault injection) that sees every call.
//!
//! The traits are declared once, by `store_traits!`, which also writes
//! [`Layered`]'s implementation of each: a method forwards to the wrapped
//! store through [`Layer::around`]. A method added to a trait is therefore
//! forwarded by every wrapper, and no wrapper can drop one silently.

use std::sync::Arc;
use std::time::Duration;

use super::types::{
    Checkpoint, Fence, JournalEntry, LeaseGrant, NamedPose, SessionRecord, StoreError, StoredAsset,
};
use dend::mesh::Mesh;

/// One store call as a [`Layer`] sees it.
#[derive(Debug, Clone, Copy)]
pub struct Call<'a> {
    /// The method's name (`append`, `journal`, …).
    pub op: &'static str,
    /// The id of the mesh or session the call is about, when it has one.
    pub id: Option<&'a str>,
}

/// What a [`Layered`] store does around each call of the store it wraps.
pub trait Layer: Send + Sync + 'static {
    /// Runs `call` (the wrapped store's method, as `f`), with whatever this
    /// layer adds before or after it.
    fn around<T>(
        &self,
        call: Call<'_>,
        f: impl FnOnce() -> Result<T, StoreError>,
    ) -> Result<T, StoreError>;
}

/// A store wrapped by a [`Layer`].
pub struct Layered<L> {
    inner: Arc<dyn Store>,
    layer: L,
}

impl<L: Layer> Layered<L> {
    /// `inner` with `layer` around each of its calls.
    pub fn new(inner: Arc<dyn Store>, layer: L) -> Self {
        Layered { inner, layer }
    }

    /// The layer.
    pub fn layer(&self) -> &L {
        &self.layer
    }
}

/// The id a call is about: its first argument when that is named `id`.
macro_rules! call_id {
    ($first:ident $(, $rest:ident)*) => {
        call_id!(@pick $first, $first)
    };
    () => {
        None
    };
    (@pick id, $x:ident) => {
        Some($x)
    };
    (@pick $other:ident, $x:ident) => {
        None
    };
}

/// Declares each store trait and [`Layered`]'s forwarding implementation
/// of it.
macro_rules! store_traits {
    ($(
        $(#[$tm:meta])*
        pub trait $trait:ident {
            $(
                $(#[$mm:meta])*
                fn $name:ident(&self $(, $arg:ident: $ty:ty)* $(,)?) -> $ret:ty;
            )*
        }
    )*) => {
        $(
            $(#[$tm])*
            pub trait $trait: Send + Sync + 'static {
                $(
                    $(#[$mm])*
                    fn $name(&self $(, $arg: $ty)*) -> $ret;
                )*
            }

            impl<L: Layer> $trait for Layered<L> {
                $(
                    fn $name(&self $(, $arg: $ty)*) -> $ret {
                        let call = Call { op: stringify!($name), id: call_id!($($arg),*) };
                        self.layer.around(call, || self.inner.$name($($arg),*))
                    }
                )*
            }
        )*
    };
}

store_traits! {
    /// Meshes and the files they were uploaded from.
    pub trait MeshStore {
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
    }

    /// The session log: each session's record, constraint set, journal of
    /// drags and last checkpoint.
    pub trait SessionLog {
        /// Stores or replaces a session record.
        fn put_session(&self, record: &SessionRecord) -> Result<(), StoreError>;
        /// The session record stored under `id`.
        fn get_session(&self, id: &str) -> Result<Option<SessionRecord>, StoreError>;
        /// All stored session records (to re-open sessions after a restart).
        fn list_sessions(&self) -> Result<Vec<SessionRecord>, StoreError>;
        /// Deletes a session with its journal, checkpoint and named poses (a
        /// no-op if absent).
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
        /// unless `fence` is [`NO_FENCE`](super::types::NO_FENCE), it must be
        /// the session's current lease revision, else
        /// [`StoreError::Fenced`] and nothing is written.
        fn append(&self, id: &str, fence: Fence, entries: &[JournalEntry]) -> Result<(), StoreError>;
        /// The journal entries after the last checkpoint, oldest first.
        fn journal(&self, id: &str) -> Result<Vec<JournalEntry>, StoreError>;
        /// Replaces the checkpoint and truncates the journal (atomically). Fenced.
        fn checkpoint(&self, id: &str, fence: Fence, checkpoint: &Checkpoint) -> Result<(), StoreError>;
        /// The last checkpoint.
        fn get_checkpoint(&self, id: &str) -> Result<Option<Checkpoint>, StoreError>;
    }

    /// Session leases between instances sharing the store, and their
    /// liveness (docs/deployment.md).
    pub trait LeaseStore {
        /// Takes the lease of session `id` for instance `owner` for `ttl`: when
        /// there is none, it expired, its owner is no longer announced alive,
        /// or `owner` already holds it, the revision grows by one and is
        /// returned; otherwise the holder is named and the request recorded
        /// (see [`handoffs_wanted`](LeaseStore::handoffs_wanted)). Taking the
        /// lease waits for a write fenced by the old revision that is in
        /// flight, so a journal read after it sees every acknowledged write.
        fn acquire_lease(&self, id: &str, owner: &str, ttl: Duration) -> Result<LeaseGrant, StoreError>;
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
        /// [`acquire_lease`](LeaseStore::acquire_lease) that found them held
        /// by `owner` (the load balancer routes them elsewhere now, e.g. to an
        /// instance that came back). The owner hands them over: it closes them
        /// and releases their leases. A grant clears the request.
        fn handoffs_wanted(&self, owner: &str) -> Result<Vec<String>, StoreError>;
        /// Checks that the store answers (the readiness probe).
        fn ping(&self) -> Result<(), StoreError>;
        /// Announces `instance` as alive for as long as this store lives (the
        /// shared store's owner liveness: a lease whose owner is no longer
        /// announced is taken over without waiting for it to expire). A no-op
        /// for stores without leases shared between processes.
        fn announce_liveness(&self, instance: &str) -> Result<(), StoreError>;
    }

    /// A session's named poses: written before the save, rename or delete is
    /// acknowledged, fenced like the journal, deleted with the session, and
    /// kept across constraint edits.
    pub trait PoseStore {
        /// Stores a named pose of session `id`, replacing the one of the same
        /// name if any. Fenced. [`StoreError::Missing`] without the session.
        fn put_named_pose(&self, id: &str, fence: Fence, pose: &NamedPose) -> Result<(), StoreError>;
        /// Renames named pose `from` of session `id` to `to` (the caller checked
        /// that `to` is free; a no-op when there is no `from`). Fenced.
        fn rename_named_pose(&self, id: &str, fence: Fence, from: &str, to: &str) -> Result<(), StoreError>;
        /// Deletes named pose `name` of session `id` (a no-op if absent). Fenced.
        fn delete_named_pose(&self, id: &str, fence: Fence, name: &str) -> Result<(), StoreError>;
        /// The named poses of session `id`, by [`NamedPose::ordinal`] (none
        /// for an unknown session).
        fn named_poses(&self, id: &str) -> Result<Vec<NamedPose>, StoreError>;
    }
}

/// Storage of meshes and sessions, every concern (see the module docs of
/// `store` for when the server calls what). Implemented by every type that
/// implements the four concern traits; shared as `Arc<dyn Store>`.
pub trait Store: MeshStore + SessionLog + LeaseStore + PoseStore {}

impl<T: MeshStore + SessionLog + LeaseStore + PoseStore> Store for T {}
