//! The values a session's actor and its handles exchange: drag deltas,
//! poses and frames, events, the solver observer, and a build stage's
//! wire name. A leaf below the session's files (docs/architecture.md,
//! "Layering").

use std::sync::Arc;

use bytes::Bytes;
use nalgebra::UnitQuaternion;

use super::error::SessionError;
use dend::deform::BuildStage;
use dend_protocol::ws::PeerEvent;
use dend_protocol::FrameHeader;

/// A drag delta: rotate about the handle's current pivot, then translate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Delta {
    /// Delta rotation.
    pub rotation: UnitQuaternion<f64>,
    /// Delta translation (mesh units).
    pub translation: [f64; 3],
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

/// One binary pose frame (see [`frame`](super::frame) for the layout).
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
    /// A constraint set's coarse levels were built ahead of its first
    /// solve, beside its factor, in `seconds`.
    fn levels_ready(&self, seconds: f64) {
        let _ = seconds;
    }
}

/// An [`Observer`] that ignores everything.
pub struct NoObserver;

impl Observer for NoObserver {
    fn solved(&self, _: usize, _: f64, _: bool) {}
}

/// A factor build's stage as the wire names it.
pub fn wire_stage(s: BuildStage) -> dend_protocol::BuildStage {
    match s {
        BuildStage::Assembly => dend_protocol::BuildStage::Assembly,
        BuildStage::Symbolic => dend_protocol::BuildStage::Symbolic,
        BuildStage::Numeric => dend_protocol::BuildStage::Numeric,
    }
}
