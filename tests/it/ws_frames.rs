//! The session socket's compact frames and stream options, end to end
//! over a real socket (api/ws-protocol.md, protocol version 3): q16
//! frames are half the bytes of f32 and within 1e-4 of the diagonal of the
//! full-precision pose, delta frames cost what moved, a client that asks
//! for nothing still gets version 2 frames, and bad options are refused.

use dend_client::ws::StreamOptions;
use dend_client::{FrameEncoding, SessionParams, WsFull};

use super::ws_flow::{ready_session, R};

/// The frames up to the first settled one acknowledging drag 1, each with
/// its size in bytes.
async fn until_settled(
    c: &mut dend_client::WsClient,
) -> Result<Vec<(dend_protocol::DecodedFrame, u64)>, dend_client::ClientError> {
    let mut frames = vec![];
    loop {
        let before = c.frame_bytes();
        if let WsFull::Frame(f) = c.next_full().await? {
            let done = f.header.ack_seq >= 1 && f.header.settled;
            frames.push((f, c.frame_bytes() - before));
            if done {
                return Ok(frames);
            }
        }
    }
}

/// The largest distance between a frame's positions and the f64 pose.
fn frame_error(pose: &[[f64; 3]], frame: &[[f32; 3]]) -> f64 {
    pose.iter()
        .zip(frame)
        .map(|(a, q)| {
            (0..3)
                .map(|k| (a[k] - f64::from(q[k])).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max)
}

/// The error of version 3 frame `f` against the f32 frame of the same
/// revision in `by_revision`, if there is one, and the diagonal of `f`'s box.
fn error_against_twin(
    f: &dend_protocol::DecodedFrame,
    by_revision: &std::collections::HashMap<u64, &dend_protocol::DecodedFrame>,
) -> Option<(f64, f64)> {
    let b = f.bbox.expect("a version 3 frame has a box");
    let diag = (0..3)
        .map(|k| (b[1][k] - b[0][k]).powi(2))
        .sum::<f64>()
        .sqrt();
    let exact = by_revision.get(&f.header.revision)?;
    let exact: Vec<[f64; 3]> = exact.positions.iter().map(|p| p.map(f64::from)).collect();
    Some((frame_error(&exact, &f.positions), diag))
}

/// A q16 connection gets the frames of a drag in half the bytes of f32
/// (6 bytes per vertex against 12), each within 1e-4 of its box's diagonal
/// of the same frame in f32, and the settled frame in f32, exactly the
/// f64 pose (`GET /pose`) rounded to f32; a client that asks for nothing
/// gets version 2 frames of the same poses.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn q16_frames_are_half_the_bytes_and_the_settled_frame_is_exact() -> R {
    // a tolerance it does not reach: every frame of the drag's 100
    // iterations is one the pose moved in, and some reach the clients
    let n = 40;
    let (_c, s) = ready_session(
        n,
        SessionParams {
            tol: Some(1e-12),
            ..SessionParams::default()
        },
    )
    .await?;
    let mut q16 = s
        .connect_with(StreamOptions::flow(1, FrameEncoding::Q16))
        .await?;
    let mut f32s = s
        .connect_with(StreamOptions::flow(1, FrameEncoding::F32))
        .await?;
    let mut legacy = s.connect_with(StreamOptions::default()).await?;
    // a turn and a lift, so the pose leaves the rest mesh's plane and box
    let q = [0.0, 0.0, (0.25f64).sin(), (0.25f64).cos()];
    q16.drag(0, [0.0, 3.0, 5.0], Some(q), 1).await?;
    let fq = until_settled(&mut q16).await?;
    let ff = until_settled(&mut f32s).await?;
    let fl = until_settled(&mut legacy).await?;
    let v = (n * n) as u64;
    let ((sq, _), (sf, bf)) = (fq.last().unwrap(), ff.last().unwrap());
    assert_eq!(
        (sq.version, sq.encoding),
        (3, FrameEncoding::F32),
        "settled: f32"
    );
    assert_eq!((sf.version, sf.encoding), (3, FrameEncoding::F32));
    assert_eq!(
        fl.last().unwrap().0.version,
        2,
        "a client that asks for nothing gets version 2"
    );
    assert_eq!(sq.header.revision, sf.header.revision);
    assert_eq!(*bf, 96 + 12 * v);
    let pose = s.pose().await?;
    assert_eq!(
        pose.revision, sq.header.revision,
        "the pose of the settled frame"
    );
    assert_eq!(
        frame_error(&pose.positions, &sq.positions),
        frame_error(&pose.positions, &sf.positions)
    );
    assert!(
        frame_error(&pose.positions, &sq.positions) < 1e-6 * 10.0,
        "the settled frame is the pose in f32"
    );
    assert_eq!(
        fl.last().unwrap().0.positions,
        sf.positions,
        "f32 in both versions"
    );
    // the frames before it: q16, in 96 + 6 bytes per vertex, within 1e-4
    // of the diagonal of their box from the f32 frame of the same revision
    let by_revision: std::collections::HashMap<u64, &dend_protocol::DecodedFrame> =
        ff.iter().map(|(f, _)| (f.header.revision, f)).collect();
    let (mut moving, mut compared) = (0, 0);
    for (f, bytes) in &fq[..fq.len() - 1] {
        if f.header.settled {
            // the pose before the drag, settled: f32 as well
            assert_eq!((f.encoding, *bytes), (FrameEncoding::F32, 96 + 12 * v));
            continue;
        }
        moving += 1;
        assert_eq!((f.version, f.encoding), (3, FrameEncoding::Q16));
        assert_eq!(*bytes, 96 + 6 * v);
        if let Some((worst, diag)) = error_against_twin(f, &by_revision) {
            assert!(worst <= 1e-4 * diag, "q16 error {worst} of diagonal {diag}");
            compared += 1;
        }
    }
    eprintln!("{moving} q16 frames while the pose moved, {compared} compared with f32");
    assert!(moving > 0, "the drag took more than one frame");
    Ok(())
}

/// Bad stream options are refused before the upgrade, with the API's error.
#[tokio::test]
async fn bad_stream_options_are_refused_before_the_upgrade() -> R {
    let (_c, s) = ready_session(4, SessionParams::default()).await?;
    for opts in [
        StreamOptions {
            window: Some(0),
            ..StreamOptions::default()
        },
        StreamOptions {
            window: Some(1000),
            ..StreamOptions::default()
        },
        StreamOptions {
            max_fps: Some(0),
            ..StreamOptions::default()
        },
        StreamOptions {
            refine_fps: Some(1001),
            ..StreamOptions::default()
        },
    ] {
        let e = s.connect_with(opts).await.err().ok_or("connected")?;
        assert!(e.to_string().contains("422"), "{e}");
    }
    Ok(())
}

/// A `delta` connection (the editor's) decodes every frame of a drag,
/// each within 1e-4 of its box's diagonal of the f32 frame of the same
/// revision (a connection without flow control gets every frame), in
/// fewer bytes than a `q16` frame's fixed 6 per vertex (most of the grid
/// is still or moves a few grid steps between frames), and ends on the
/// settled frame in f32, exact.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn delta_frames_are_within_the_grid_and_cost_what_moved() -> R {
    let n = 40;
    let (_c, s) = ready_session(
        n,
        SessionParams {
            tol: Some(1e-12),
            ..SessionParams::default()
        },
    )
    .await?;
    let mut delta = s
        .connect_with(StreamOptions::flow(1, FrameEncoding::Delta))
        .await?;
    // no flow control: every frame, in f32, to compare with
    let mut every = s.connect_with(StreamOptions::default()).await?;
    let q = [0.0, 0.0, (0.25f64).sin(), (0.25f64).cos()];
    delta.drag(0, [0.0, 3.0, 5.0], Some(q), 1).await?;
    let fd = until_settled(&mut delta).await?;
    let ff = until_settled(&mut every).await?;
    let v = (n * n) as u64;
    let by_revision: std::collections::HashMap<u64, &dend_protocol::DecodedFrame> =
        ff.iter().map(|(f, _)| (f.header.revision, f)).collect();
    let (mut compared, mut delta_bytes, mut delta_frames) = (0, 0, 0);
    for (f, bytes) in &fd[..fd.len() - 1] {
        if f.header.settled {
            continue;
        }
        assert_eq!((f.version, f.encoding), (3, FrameEncoding::Delta));
        delta_bytes += bytes;
        delta_frames += 1;
        if let Some((worst, diag)) = error_against_twin(f, &by_revision) {
            assert!(
                worst <= 1e-4 * diag,
                "delta error {worst} of diagonal {diag}"
            );
            compared += 1;
        }
    }
    eprintln!(
        "{delta_frames} delta frames, {} B each on average (q16: {} B), {compared} compared with f32",
        delta_bytes / delta_frames.max(1),
        96 + 6 * v
    );
    assert!(delta_frames > 1, "the drag took frames");
    assert!(compared > 0, "some delta frame had an f32 twin");
    assert!(
        delta_bytes / delta_frames < 96 + 6 * v,
        "delta frames average {} B, q16's are {} B",
        delta_bytes / delta_frames,
        96 + 6 * v
    );
    let (last, _) = fd.last().unwrap();
    assert_eq!(
        last.encoding,
        FrameEncoding::F32,
        "the settled frame is f32"
    );
    let pose = s.pose().await?;
    assert!(frame_error(&pose.positions, &last.positions) < 1e-5);
    // a second drag after the settled f32 frame starts from a key frame
    delta.drag(0, [0.0, 1.0, 0.0], None, 2).await?;
    let again = until_settled(&mut delta).await?;
    assert!(again
        .iter()
        .any(|(f, _)| f.encoding == FrameEncoding::Delta));
    Ok(())
}
