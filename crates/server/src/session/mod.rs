//! A live editing session: one mesh's [`Rest`] precomputation, solver
//! [`Params`], a constraint set, a [`Deformer`] holding the current pose,
//! an undo/redo history and a revision counter.
//!
//! Each session is an actor task (see `actor.rs`) owning that state; a
//! cheap, cloneable [`SessionHandle`] talks to it. The actor runs at most one
//! solve at a time, on tokio's blocking pool. Drag deltas that arrive while a
//! solve runs are composed into the handle targets at once
//! (`RigidTransform::then`; none is dropped) and the next solve uses the
//! composition. After the last delta the actor keeps iterating
//! (`iters_per_frame` iterations per frame) until converged or
//! `params.max_iters` iterations after the last change, then waits idle.
//! Frames go out on a `watch` channel (latest frame wins for a slow
//! reader), events on a bounded `broadcast` channel.

mod actor;
mod handle;
mod poses;
mod recovery;
mod shared;

pub use dend_protocol as frame;
pub use dend_protocol::ws::{ClientId, HandleRef, PeerEvent, SessionInfo, SessionState};
pub use dend_protocol::{decode_frame, FrameError, FrameHeader};
pub use handle::{SessionHandle, SessionOptions};
pub use poses::{check_pose_name, pose_list, PoseInfo, MAX_NAMED_POSES, MAX_POSE_NAME_BYTES};
pub use recovery::{transform, Recovered};

use std::sync::Arc;

use bytes::Bytes;
use nalgebra::UnitQuaternion;

use crate::store::StoreError;
pub use dend::deform::BuildStage;

/// How long after a WebSocket drag the session treats drags as one
/// gesture: coarse previews answer them on large meshes, and the solves
/// that answer a drag hold the coarse corrections
/// (`Deformer::hold_corrections`). A refinement's corrections run (a drag
/// that arrives stops them, `Actor::interrupt`): camel closed loop, settle
/// 37–39 → 21 iterations, 560–604 → 501–510 ms. 150 ms: drags 125 ms apart (a
/// person dragging slowly, 8 mouse moves a second) stay on coarse previews
/// on the feline (drag→frame p50 26.8 ms, p99 59 ms; at 100 ms the full
/// mesh iterated between them: 48.1 and 104 ms), for a settle that starts
/// 50 ms later (docs/performance.md).
pub const CORRECTION_QUIET: std::time::Duration = std::time::Duration::from_millis(150);

/// Sleeps until `at`; never when `None` (for a `select!` branch that is
/// disabled then: the session's wake-up, a connection's rate interval).
pub(crate) async fn sleep_until_or_never(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => std::future::pending().await,
    }
}

/// A factor build's stage as the wire names it.
pub fn wire_stage(s: BuildStage) -> dend_protocol::BuildStage {
    match s {
        BuildStage::Assembly => dend_protocol::BuildStage::Assembly,
        BuildStage::Symbolic => dend_protocol::BuildStage::Symbolic,
        BuildStage::Numeric => dend_protocol::BuildStage::Numeric,
    }
}
use dend::deform::DeformError;

#[allow(unused_imports)] // doc links
use dend::deform::{Deformer, Params, Rest};

/// A drag delta: rotate about the handle's current pivot, then translate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Delta {
    /// Delta rotation.
    pub rotation: UnitQuaternion<f64>,
    /// Delta translation (mesh units).
    pub translation: [f64; 3],
}

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
        /// [`MAX_NAMED_POSES`].
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

/// A pose as returned to HTTP callers: the header of the frame that
/// carried it (revision, acknowledged seq, iteration, convergence, objective;
/// `vertex_count` is `positions.len()`) and its positions.
#[derive(Debug, Clone)]
pub struct PoseSnapshot {
    /// The pose's frame header.
    pub header: FrameHeader,
    /// Vertex positions (mesh units), `#V×3`.
    pub positions: Arc<Vec<[f64; 3]>>,
}

/// One binary pose frame (see [`frame`] for the layout).
#[derive(Debug, Clone)]
pub struct Frame {
    /// Its header fields.
    pub header: FrameHeader,
    /// The encoded frame, shared by every receiver.
    pub bytes: Bytes,
}

/// Events pushed to every client of a session.
#[derive(Debug, Clone)]
pub enum Event {
    /// The factor is ready; drags are accepted.
    Ready {
        /// Revision at that moment.
        revision: u64,
    },
    /// The state changed (constraints set, build failed, undo...).
    State,
    /// A failure not tied to one request (factor build, solve).
    Error(Arc<SessionError>),
    /// A client grabbed or released a handle, joined or left.
    Peer(PeerEvent),
    /// A stage of the constraint set's factor build started.
    BuildProgress {
        /// The stage.
        stage: BuildStage,
    },
    /// The session was closed (deleted or expired).
    Closed,
}

/// Receives solver statistics (the server's metrics implement it).
pub trait Observer: Send + Sync + 'static {
    /// One solve finished: `iterations` DEND iterations in `seconds`.
    fn solved(&self, iterations: usize, seconds: f64, converged: bool);
    /// A constraint set's factor became available `seconds` after the
    /// set was submitted (built, or found in the factor cache).
    fn factor_ready(&self, seconds: f64) {
        let _ = seconds;
    }
}

/// An [`Observer`] that ignores everything.
pub struct NoObserver;

impl Observer for NoObserver {
    fn solved(&self, _: usize, _: f64, _: bool) {}
}
