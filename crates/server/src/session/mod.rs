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
pub(crate) mod error;
mod handle;
mod poses;
mod recovery;
mod shared;
mod timing;
mod types;

pub use dend_protocol as frame;
pub use dend_protocol::ws::{ClientId, HandleRef, PeerEvent, SessionInfo, SessionState};
pub use dend_protocol::{decode_frame, FrameError, FrameHeader};
pub use handle::{SessionHandle, SessionOptions};
pub use poses::{check_pose_name, pose_list, PoseInfo, MAX_NAMED_POSES, MAX_POSE_NAME_BYTES};
pub use recovery::{transform, Recovered};
pub(crate) use timing::sleep_until_or_never;
pub use timing::{CORRECTION_QUIET, DRAGS_SHOWN_WAIT};
pub use types::{wire_stage, Delta, Event, Frame, NoObserver, Observer, PoseSnapshot};

pub use dend::deform::BuildStage;
pub use error::SessionError;

#[allow(unused_imports)] // doc links
use dend::deform::{Deformer, Params, Rest};
