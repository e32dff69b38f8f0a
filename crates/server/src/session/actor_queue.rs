//! What waits for a session to be ready: drags that arrive while its
//! factor is being built (applied once it is ready, refused past
//! `SessionOptions::build_wait`) and pose reads during a revival (answered
//! with the revival's settled pose: never the checkpoint pose, which lacks
//! the journaled drags, nor an iterate of the solve towards them).

use std::sync::Arc;
use std::time::Instant;

use super::{Actor, Phase, Step};
use crate::session::error::SessionError;
use crate::session::types::Event;
use dend_protocol::FrameHeader;

impl Actor {
    /// The factor is ready: applies the queued drags in their order.
    pub(super) fn apply_queued(&mut self) {
        while let Some(q) = self.flow.queued.pop_front() {
            self.on_drag(q.handle, q.delta, q.seq, q.reply);
        }
    }

    /// Refuses every queued drag with `error()` (HTTP callers get it; the
    /// WebSocket clients get it as an `error` event).
    pub(super) fn refuse_queued(&mut self, error: impl Fn() -> SessionError) {
        let mut told = false;
        for q in self.flow.queued.drain(..) {
            match q.reply {
                Some((_, r)) => {
                    let _ = r.send(Err(error()));
                }
                None if !told => {
                    told = true;
                    let _ = self.inner.events.send(Event::Error(Arc::new(error())));
                }
                None => {}
            }
        }
    }

    /// Refuses the queued drags that waited longer than `build_wait`.
    pub(super) fn expire_queued(&mut self) {
        let wait = self.opts.build_wait;
        let state = self.state();
        let now = Instant::now();
        let keep = self
            .flow
            .queued
            .iter()
            .position(|q| now.duration_since(q.at) < wait)
            .unwrap_or(self.flow.queued.len());
        let expired: Vec<_> = self.flow.queued.drain(..keep).collect();
        let mut told = false;
        for q in expired {
            let e = SessionError::NotReady { state };
            match q.reply {
                Some((_, r)) => {
                    let _ = r.send(Err(e));
                }
                None if !told => {
                    told = true;
                    let _ = self.inner.events.send(Event::Error(Arc::new(e)));
                }
                None => {}
            }
        }
    }

    /// A revival's solve settled: its pose (checkpoint plus every journaled
    /// drag, as the solver settled it) is the session's; the reads that
    /// waited get it.
    pub(super) fn end_revival(&mut self, header: &FrameHeader) {
        if self.phase != Phase::Reviving {
            return;
        }
        self.go(Step::Settled);
        for w in std::mem::take(&mut self.flow.pose_waiters) {
            let _ = w.send(Ok(self.snapshot_for(header)));
        }
    }

    /// A revival's factor build failed: the reads that waited get the
    /// error (later reads are refused until a constraint set is solved).
    pub(super) fn fail_revival(&mut self, e: &Arc<SessionError>) {
        for w in std::mem::take(&mut self.flow.pose_waiters) {
            let _ = w.send(Err(SessionError::Shared(e.clone())));
        }
    }
}
