//! One loadtest session's drag: the path the handle follows, the pace of
//! the drags, the client's own time per frame, and what it saw.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use dend_client::ws::ServerMsg;
use dend_client::{WsClient, WsFull};

pub use dend_client::gesture::DragPath;
use dend_client::gesture::Gesture;

/// The geometry of a drag: where the handle is and where it goes, and
/// what "the pose has arrived" is measured against.
#[derive(Debug, Clone, Copy)]
pub struct Path {
    /// The gesture's drags (`dend_client::gesture`).
    pub gesture: Gesture,
    /// The mesh's bounding-box diagonal ([`VISIBLE_SHARE`]).
    pub diagonal: f64,
}

/// How the client drags and reads.
#[derive(Debug, Clone, Copy)]
pub struct Pace {
    /// Drags per second sent on a clock (a mouse); 0: closed loop (the
    /// next drag when a frame acknowledges the last one).
    pub drag_hz: f64,
    /// Time the client spends on each frame (drawing it), ms.
    pub slow_ms: u64,
}

/// What one session's client saw.
#[derive(Debug, Default)]
pub struct Seen {
    /// Drag sent → the first frame acknowledging it, per drag.
    pub latencies: Vec<Duration>,
    /// Frames received while dragging (first drag sent → the frame
    /// acknowledging the last).
    pub drag_frames: u64,
    /// Frame bytes received while dragging.
    pub drag_bytes: u64,
    /// That drag phase's length.
    pub drag_time: Duration,
    /// Frames received in all.
    pub frames: u64,
    /// Frames per level (0 full, 1 coarse).
    pub levels: [u64; 2],
    /// Last drag sent → the settled frame after it.
    pub settle: Duration,
    /// Last drag sent → the first frame from which on every frame is
    /// within [`VISIBLE_SHARE`] of the diagonal of the settled frame's
    /// pose ([`visible_settle`]): when the pose a person is shown stops
    /// moving, which can be well before the solver's convergence test
    /// says settled.
    pub settle_visible: Duration,
    /// Iterations since the last change in the settled frame.
    pub settle_iterations: u32,
    /// Whether the settled frame converged.
    pub settle_converged: bool,
}

/// Drags the handle along `path` at `pace` (gesture `gesture`, 0-based:
/// [`Path::delta_of`]; its drags' `seq` follow the gestures before it) and
/// reads frames until the one after the last drag that says settled.
/// Every acknowledged drag is counted in `progress` (shared by the
/// sessions of a run).
pub async fn drag(
    ws: &mut WsClient,
    (path, gesture): (&Path, u64),
    pace: Pace,
    progress: &AtomicU64,
) -> anyhow::Result<Seen> {
    let mut seen = Seen::default();
    let mut sent: BTreeMap<u64, Instant> = BTreeMap::new();
    let start = Instant::now();
    let period = (pace.drag_hz > 0.0).then(|| Duration::from_secs_f64(1.0 / pace.drag_hz));
    let first = gesture * path.gesture.drags;
    let last = first + path.gesture.drags;
    let (mut next_seq, mut acked) = (first + 1, first);
    let mut last_sent = start;
    let bytes0 = ws.frame_bytes();
    // the frames after the last drag was sent: when each came, and every
    // `stride`-th vertex of its pose
    let mut track: Vec<(Duration, Vec<[f32; 3]>)> = Vec::new();
    loop {
        // send what is due: on the clock, or (closed loop) once acknowledged
        while next_seq <= last {
            let due = match period {
                Some(p) => Instant::now() >= start + p * (next_seq - first - 1) as u32,
                None => acked + 1 >= next_seq,
            };
            if !due {
                break;
            }
            let (t, q) = path.gesture.delta_of(gesture, next_seq - first - 1);
            ws.drag(0, t, q, next_seq).await?;
            last_sent = Instant::now();
            sent.insert(next_seq, last_sent);
            next_seq += 1;
        }
        let wait = match period {
            Some(p) if next_seq <= last => start + p * (next_seq - first - 1) as u32,
            _ => Instant::now() + Duration::from_secs(600),
        };
        let msg = match tokio::time::timeout_at(wait.into(), ws.next_full()).await {
            Err(_) => continue,
            Ok(m) => m?,
        };
        match msg {
            WsFull::Frame(f) => {
                let now = Instant::now();
                let h = f.header;
                seen.frames += 1;
                seen.levels[usize::from(h.level.min(1))] += 1;
                let dragging = acked < last;
                if dragging {
                    seen.drag_frames += 1;
                }
                while let Some((&s, &t)) = sent.first_key_value() {
                    if s > h.ack_seq {
                        break;
                    }
                    seen.latencies.push(now - t);
                    sent.remove(&s);
                    let _ = progress.fetch_add(1, Ordering::Relaxed);
                }
                acked = acked.max(h.ack_seq);
                if dragging && acked >= last {
                    seen.drag_time = now - start;
                    seen.drag_bytes = ws.frame_bytes() - bytes0;
                }
                if next_seq > last {
                    let stride = f.positions.len().div_ceil(TRACKED_VERTICES).max(1);
                    let sample = f.positions.iter().step_by(stride).copied().collect();
                    track.push((now - last_sent, sample));
                }
                if acked >= last && h.settled {
                    seen.settle = now - last_sent;
                    seen.settle_visible = visible_settle(&track, VISIBLE_SHARE * path.diagonal);
                    seen.settle_iterations = h.iteration;
                    seen.settle_converged = h.converged;
                    return Ok(seen);
                }
                if pace.slow_ms > 0 {
                    tokio::time::sleep(Duration::from_millis(pace.slow_ms)).await;
                }
            }
            WsFull::Event(e @ ServerMsg::Error { .. }) => anyhow::bail!("server error: {e:?}"),
            WsFull::Closed(c) => anyhow::bail!("connection closed ({c:?})"),
            WsFull::Event(_) => {}
        }
    }
}

/// The share of the mesh's diagonal within which a pose counts as the
/// settled one for [`Seen::settle_visible`]: about one pixel of a view a
/// thousand pixels across that frames the whole mesh, so a smaller move
/// is not seen.
pub const VISIBLE_SHARE: f64 = 1e-3;

/// The most vertices of a frame that [`Seen::settle_visible`] compares
/// (every `⌈n / this⌉`-th vertex): a settle of igea_134k sends hundreds of
/// frames, whose whole poses would take hundreds of MB per session.
const TRACKED_VERTICES: usize = 4096;

/// When a settle's frames arrived at the last one's pose: the time of the
/// first frame of `track` (times and poses, the settled frame last) from
/// which on every frame's largest vertex distance to the last frame's is
/// at most `tolerance`; zero for an empty track.
pub fn visible_settle(track: &[(Duration, Vec<[f32; 3]>)], tolerance: f64) -> Duration {
    let Some((_, last)) = track.last() else {
        return Duration::ZERO;
    };
    let far = |pose: &[[f32; 3]]| {
        pose.iter().zip(last).any(|(p, q)| {
            let d2: f64 = (0..3)
                .map(|k| (f64::from(p[k]) - f64::from(q[k])).powi(2))
                .sum();
            d2 > tolerance * tolerance
        })
    };
    let first_near = track
        .iter()
        .rposition(|(_, pose)| far(pose))
        .map_or(0, |i| i + 1);
    track[first_near].0
}

/// Summary statistics of the sessions' drags, as the report prints them.
#[derive(Debug, Default)]
pub struct Summary {
    /// Every drag's latency, sorted.
    pub latencies: Vec<Duration>,
    /// Frames per second while dragging, per session, sorted.
    pub fps: Vec<f64>,
    /// Bytes per second to one client while dragging, per session, sorted.
    pub bytes_per_sec: Vec<f64>,
    /// Bytes per frame, per session, sorted.
    pub bytes_per_frame: Vec<f64>,
    /// Settle times, sorted.
    pub settles: Vec<Duration>,
    /// When each session's shown pose arrived ([`Seen::settle_visible`]),
    /// sorted.
    pub settles_visible: Vec<Duration>,
    /// Settle iterations, sorted.
    pub settle_iterations: Vec<u32>,
    /// Sessions whose settled frame converged.
    pub converged: usize,
    /// Frames per level, all sessions.
    pub levels: [u64; 2],
    /// Frames in all.
    pub frames: u64,
    /// Each session's median drag→frame latency, sorted.
    pub medians: Vec<Duration>,
}

impl Summary {
    /// Adds one session.
    pub fn add(&mut self, s: Seen) {
        let secs = s.drag_time.as_secs_f64().max(1e-9);
        self.fps.push(s.drag_frames as f64 / secs);
        self.bytes_per_sec.push(s.drag_bytes as f64 / secs);
        self.bytes_per_frame
            .push(s.drag_bytes as f64 / s.drag_frames.max(1) as f64);
        let mut own = s.latencies.clone();
        own.sort();
        self.medians
            .push(own.get(own.len() / 2).copied().unwrap_or_default());
        self.latencies.extend(s.latencies);
        self.settles.push(s.settle);
        self.settles_visible.push(s.settle_visible);
        self.settle_iterations.push(s.settle_iterations);
        self.converged += usize::from(s.settle_converged);
        self.levels[0] += s.levels[0];
        self.levels[1] += s.levels[1];
        self.frames += s.frames;
    }

    /// Sorts every list (before reading percentiles).
    pub fn sort(&mut self) {
        self.latencies.sort();
        self.medians.sort();
        self.settles.sort();
        self.settles_visible.sort();
        self.settle_iterations.sort();
        for v in [
            &mut self.fps,
            &mut self.bytes_per_sec,
            &mut self.bytes_per_frame,
        ] {
            v.sort_by(f64::total_cmp);
        }
    }
}

/// The median of sorted values (0 when there are none).
pub fn median(sorted: &[f64]) -> f64 {
    sorted.get(sorted.len() / 2).copied().unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::visible_settle;

    fn at(ms: u64, x: f32) -> (Duration, Vec<[f32; 3]>) {
        (
            Duration::from_millis(ms),
            vec![[0.0, 0.0, 0.0], [x, 1.0, 0.0]],
        )
    }

    #[test]
    fn the_pose_arrives_at_the_first_frame_after_the_last_one_that_was_far() {
        // a creep: 0.5, 0.1, then within 0.01 of the last from 30 ms on,
        // though a frame between moved back out (at 40 ms)
        let track = [
            at(10, 0.5),
            at(20, 0.1),
            at(30, 0.005),
            at(40, 0.02),
            at(50, 0.003),
            at(60, 0.0),
        ];
        assert_eq!(visible_settle(&track, 0.01), Duration::from_millis(50));
        assert_eq!(visible_settle(&track, 0.05), Duration::from_millis(30));
        // every frame near: the first frame's time; none far with a
        // large tolerance either
        assert_eq!(visible_settle(&track, 1.0), Duration::from_millis(10));
        assert_eq!(visible_settle(&track[5..], 0.0), Duration::from_millis(60));
        assert_eq!(visible_settle(&[], 0.01), Duration::ZERO);
    }
}
