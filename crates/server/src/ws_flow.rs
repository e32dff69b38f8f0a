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
use dend_protocol::{
    decode_frame, reencode_v2, DeltaEncoder, FrameEncoding, FrameHeader, StreamOptions,
};

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
    /// The shortest time between the last frame sent and a frame that
    /// only refines it (`refine_fps`).
    refine_interval: Option<Duration>,
    /// The header of the last frame sent.
    last_header: Option<FrameHeader>,
}

/// The time between two frames at `fps` per second.
fn interval_of(fps: Option<u32>) -> Option<Duration> {
    fps.map(|f| Duration::from_secs_f64(1.0 / f64::from(f.max(1))))
}

impl Flow {
    /// The flow of a connection that chose `opts` (validated).
    pub(super) fn new(opts: StreamOptions) -> Self {
        Flow {
            window: opts.window.map(|w| w.max(1) as usize),
            in_flight: VecDeque::new(),
            encoding: opts.encoding,
            delta: DeltaEncoder::new(),
            interval: interval_of(opts.max_fps),
            last_sent: None,
            refine_interval: interval_of(opts.refine_fps),
            last_header: None,
        }
    }

    /// Whether a frame with header `h` only refines the last frame sent:
    /// the same last drag (`ack_seq`), the same level, no fewer
    /// iterations since the targets changed (a coarse preview's stay at
    /// 0), and neither of them settled. Anything
    /// else answers new input and is not held back by `refine_fps`.
    fn refines_last(&self, h: &FrameHeader) -> bool {
        self.last_header.as_ref().is_some_and(|l| {
            !l.settled
                && !h.settled
                && h.ack_seq == l.ack_seq
                && h.level == l.level
                && h.iteration >= l.iteration
        })
    }

    /// Whether the window lets a frame go.
    pub(super) fn window_open(&self) -> bool {
        self.window.is_none_or(|w| self.in_flight.len() < w)
    }

    /// When the frame rate caps let the frame with header `h` go, if
    /// that is after `now`: `max_fps` for every frame, `refine_fps` too
    /// for a frame that only refines the last one sent.
    pub(super) fn rate_wait(&self, now: Instant, h: &FrameHeader) -> Option<Instant> {
        let refine = self.refine_interval.filter(|_| self.refines_last(h));
        let interval = match (self.interval, refine) {
            (Some(a), Some(b)) => a.max(b),
            (a, b) => a.or(b)?,
        };
        let next = self.last_sent? + interval;
        (next > now).then_some(next)
    }

    /// Whether the frame with header `h` may be sent at `now`.
    pub(super) fn open(&self, now: Instant, h: &FrameHeader) -> bool {
        self.window_open() && self.rate_wait(now, h).is_none()
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
        self.last_header = Some(f.header);
        Some(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dend_protocol::{FrameBody, LEVEL_COARSE, LEVEL_FULL};

    /// A version 2 frame of one vertex with these header fields.
    fn frame(revision: u64, ack_seq: u64, iteration: u32, level: u8, settled: bool) -> Frame {
        let header = FrameHeader {
            revision,
            ack_seq,
            iteration,
            converged: settled,
            settled,
            objective: 1.0,
            vertex_count: 1,
            level,
        };
        let bytes = FrameBody::from_pose(&[[0.0, 1.0, 2.0]]).finish(&header);
        Frame { header, bytes }
    }

    const REFINE_FPS: u32 = 10;

    fn refine_interval() -> Duration {
        Duration::from_secs_f64(1.0 / f64::from(REFINE_FPS))
    }

    /// After a frame answering drag 3 at iteration 2: what waits for
    /// `refine_fps` and what does not.
    #[tokio::test(start_paused = true)]
    async fn only_frames_that_refine_the_last_one_wait_for_refine_fps() {
        let opts = StreamOptions::default().refining_at_most(REFINE_FPS);
        let mut flow = Flow::new(opts);
        let first = frame(10, 3, 2, LEVEL_FULL, false);
        let now = Instant::now();
        assert!(flow.open(now, &first.header), "nothing was sent yet");
        assert!(flow.take(&first).is_some());
        let sent = Instant::now();
        let refines = [
            frame(11, 3, 3, LEVEL_FULL, false),
            // a coarse preview's iteration count stays at 0
            frame(11, 3, 2, LEVEL_FULL, false),
        ];
        for f in &refines {
            assert_eq!(
                flow.rate_wait(sent, &f.header),
                Some(sent + refine_interval())
            );
            assert!(!flow.open(sent, &f.header));
            assert!(flow.open(sent + refine_interval(), &f.header));
        }
        let answers = [
            // a new drag
            frame(11, 4, 0, LEVEL_FULL, false),
            // the settled frame
            frame(11, 3, 3, LEVEL_FULL, true),
            // another level
            frame(11, 3, 3, LEVEL_COARSE, false),
            // the targets changed without a drag (an undo, a constraint
            // edit): the iteration count starts again
            frame(11, 3, 0, LEVEL_FULL, false),
        ];
        for f in &answers {
            assert_eq!(flow.rate_wait(sent, &f.header), None, "{:?}", f.header);
        }
    }

    /// A settled frame is never refined: the next frame is sent at once.
    #[tokio::test(start_paused = true)]
    async fn the_frame_after_a_settled_one_does_not_wait() {
        let mut flow = Flow::new(StreamOptions::default().refining_at_most(REFINE_FPS));
        assert!(flow.take(&frame(5, 1, 7, LEVEL_FULL, true)).is_some());
        let next = frame(6, 1, 8, LEVEL_FULL, false);
        assert_eq!(flow.rate_wait(Instant::now(), &next.header), None);
    }

    /// With `max_fps` too, a refinement waits for the longer interval and
    /// an answer for `max_fps`'s.
    #[tokio::test(start_paused = true)]
    async fn max_fps_caps_answers_and_the_longer_interval_caps_refinements() {
        let max_fps = 40;
        let opts = StreamOptions::default()
            .at_most_fps(max_fps)
            .refining_at_most(REFINE_FPS);
        let mut flow = Flow::new(opts);
        assert!(flow.take(&frame(1, 1, 1, LEVEL_FULL, false)).is_some());
        let sent = Instant::now();
        let answer = frame(2, 2, 0, LEVEL_FULL, false);
        let refine = frame(2, 1, 2, LEVEL_FULL, false);
        let max_interval = Duration::from_secs_f64(1.0 / f64::from(max_fps));
        assert_eq!(
            flow.rate_wait(sent, &answer.header),
            Some(sent + max_interval)
        );
        assert_eq!(
            flow.rate_wait(sent, &refine.header),
            Some(sent + refine_interval())
        );
        // a refine cap below max_fps's interval: max_fps decides
        let mut fast = Flow::new(
            StreamOptions::default()
                .at_most_fps(5)
                .refining_at_most(100),
        );
        assert!(fast.take(&frame(1, 1, 1, LEVEL_FULL, false)).is_some());
        let sent = Instant::now();
        assert_eq!(
            fast.rate_wait(sent, &refine.header),
            Some(sent + Duration::from_millis(200))
        );
    }
}
