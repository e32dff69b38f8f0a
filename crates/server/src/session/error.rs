//! Why a session operation failed ([`SessionError`]), in a leaf that the
//! session's files and the server's error mapping import directly, not
//! through `session/mod.rs` (docs/architecture.md, "Layering").

use std::sync::Arc;

use crate::store::StoreError;
use dend::deform::DeformError;
use dend_protocol::ws::{HandleRef, SessionState};

/// Errors of session operations. Each maps to one API error code.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// A drag or solve before the factor is ready. Fix: wait for `ready`.
    #[error("the session is not ready (state {state:?}); wait for the `ready` event")]
    NotReady {
        /// The current state.
        state: SessionState,
    },
    /// The handle does not exist in the current constraints.
    #[error("unknown handle {handle}")]
    UnknownHandle {
        /// The handle as given.
        handle: HandleRef,
    },
    /// A delta or parameter is NaN or infinite, or a rotation is degenerate.
    #[error("non-finite or degenerate value in {what}")]
    NonFinite {
        /// Which field.
        what: String,
    },
    /// Another client holds the handle. Fix: wait for `handle_released`.
    #[error("handle {handle} is grabbed by another client")]
    HandleGrabbed {
        /// The handle.
        handle: HandleRef,
    },
    /// Undo with no earlier history entry.
    #[error("nothing to undo")]
    NothingToUndo,
    /// Redo with no later history entry.
    #[error("nothing to redo")]
    NothingToRedo,
    /// A constraint edit based on a constraint set that another client has
    /// replaced since. Fix: read the session's `constraints` again.
    #[error("the constraints changed (revision {current}, the edit was based on {given}); reload them and edit again")]
    StaleConstraints {
        /// The session's constraints revision.
        current: u64,
        /// The revision the edit was based on.
        given: u64,
    },
    /// No named pose of this name. Fix: list the session's `poses`.
    #[error("no pose named `{name}`")]
    UnknownPose {
        /// The name as given.
        name: String,
    },
    /// A save or a rename onto a name another pose has. Fix: save with
    /// `replace` to overwrite it, delete or rename that pose first, or
    /// choose another name.
    #[error("a pose named `{name}` exists already")]
    PoseExists {
        /// The name.
        name: String,
    },
    /// A pose name that is empty, too long or has control characters.
    #[error("invalid pose name: {reason}")]
    InvalidPoseName {
        /// What is wrong with it.
        reason: String,
    },
    /// A save beyond the session's pose limit. Fix: delete a pose (or save
    /// over an existing name).
    #[error("the session has {limit} named poses already (the limit)")]
    TooManyPoses {
        /// [`MAX_NAMED_POSES`](super::MAX_NAMED_POSES).
        limit: usize,
    },
    /// The constraints JSON does not parse as a constraints spec.
    #[error("invalid constraints: {0}")]
    InvalidConstraints(String),
    /// The solver rejected the input or failed (constraints, factor, solve).
    #[error(transparent)]
    Deform(#[from] DeformError),
    /// The store failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// A failure shared by several waiters (a solve that failed for all of them).
    #[error(transparent)]
    Shared(Arc<SessionError>),
    /// The session was closed (deleted or expired) during the call.
    #[error("the session is closed")]
    Closed,
}
