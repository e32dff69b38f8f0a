//! Per-connection flow control of pose frames and their encoding (see
//! `api/ws-protocol.md`, "Flow control").
//!
//! The session publishes frames on a `watch` channel: a reader that looks
//! later sees only the latest one. That alone does not keep a slow client
//! current, because every frame the loop hands to the socket waits in the
//! socket's buffers (kernel and proxy), hundreds of kilobytes of them, and
//! the client reads those old frames first. With a declared window the
//! loop hands over a frame only while fewer than `window` frames are sent
//! and not acknowledged, so what waits in the buffers is bounded by the
//! window and the frame the client gets next is the latest one.

use std::collections::VecDeque;
use std::time::Duration;

use tokio::time::Instant;

use bytes::Bytes;
use dend_protocol::{decode_frame, reencode_v2, DeltaEncoder, FrameEncoding, StreamOptions};

use crate::session::Frame;

/// The frames one connection has in flight, and how it wants them encoded.
#[derive(Debug)]
pub(super) struct Flow {
    /// Frames sent and not acknowledged at most (`None`: no flow control).
    window: Option<usize>,
    /// The revisions of the frames sent and not acknowledged, oldest first.
    in_flight: VecDeque<u64>,
    /// Version 3 frames in this encoding (`None`: the session's version 2 frames).
    encoding: Option<FrameEncoding>,
    /// In `delta`: the grid indices of the last frame sent, which the
    /// next frame's changes apply to.
    delta: DeltaEncoder,
    /// The shortest time between two frames (`max_fps`), and when the
    /// last one was sent.
    interval: Option<Duration>,
    last_sent: Option<Instant>,
}

impl Flow {
    /// The flow of a connection that chose `opts` (validated).
    pub(super) fn new(opts: StreamOptions) -> Self {
        Flow {
            window: opts.window.map(|w| w.max(1) as usize),
            in_flight: VecDeque::new(),
            encoding: opts.encoding,
            delta: DeltaEncoder::new(),
            interval: opts
                .max_fps
                .map(|f| Duration::from_secs_f64(1.0 / f64::from(f.max(1)))),
            last_sent: None,
        }
    }

    /// Whether the window lets a frame go.
    pub(super) fn window_open(&self) -> bool {
        self.window.is_none_or(|w| self.in_flight.len() < w)
    }

    /// When the frame rate cap lets the next frame go, if that is after
    /// `now`.
    pub(super) fn rate_wait(&self, now: Instant) -> Option<Instant> {
        let next = self.last_sent? + self.interval?;
        (next > now).then_some(next)
    }

    /// Whether a frame may be sent at `now`.
    pub(super) fn open(&self, now: Instant) -> bool {
        self.window_open() && self.rate_wait(now).is_none()
    }

    /// The client took every frame up to `revision`.
    pub(super) fn ack(&mut self, revision: u64) {
        while self.in_flight.front().is_some_and(|r| *r <= revision) {
            self.in_flight.pop_front();
        }
    }

    /// The bytes to send for `f` (re-encoded when the client asked for
    /// version 3 frames), counted as in flight. A settled frame goes out
    /// in `f32` whatever the encoding: the pose a client keeps showing
    /// once the solver stops is exact to `f32`, and it is one frame per
    /// gesture. `None` when the session's frame does not decode, which
    /// its own encoder never produces.
    pub(super) fn take(&mut self, f: &Frame) -> Option<Bytes> {
        let encoding = match self.encoding {
            Some(FrameEncoding::Q16 | FrameEncoding::Delta) if f.header.settled => {
                Some(FrameEncoding::F32)
            }
            e => e,
        };
        let encoded = match encoding {
            None => Ok(f.bytes.clone()),
            Some(FrameEncoding::Delta) => decode_frame(&f.bytes)
                .map(|(_, positions)| self.delta.encode(&f.header, &positions)),
            Some(e) => reencode_v2(&f.bytes, &f.header, e),
        };
        if encoding != Some(FrameEncoding::Delta) {
            // the client's pose is not the last delta frame any more
            self.delta.reset();
        }
        let bytes = match encoded {
            Ok(b) => b,
            Err(err) => {
                tracing::error!(%err, "a session frame does not decode");
                return None;
            }
        };
        if self.window.is_some() {
            self.in_flight.push_back(f.header.revision);
        }
        self.last_sent = Some(Instant::now());
        Some(bytes)
    }
}
