//! The session socket's flow control, end to end over a real socket
//! (api/ws-protocol.md, protocol version 3): a slow client keeps a flat
//! drag→frame latency, declared frame rates cap the frames, refinements
//! give way to drags. The frame encodings are in `tests/it/ws_frames.rs`.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use dend_client::ws::{ServerMsg, StreamOptions};
use dend_client::{Client, FrameEncoding, SessionClient, SessionParams, WsFull};
use dend_server::Config;
use dend_testkit::server::{grid, grid_constraints, start};

pub(crate) type R = Result<(), Box<dyn std::error::Error>>;

/// A server, and a session on an `n`×`n` grid, ready to drag.
pub(crate) async fn ready_session(
    n: usize,
    params: SessionParams,
) -> Result<(Client, SessionClient), Box<dyn std::error::Error>> {
    let (base, _state) = start(Config {
        ws_max_messages_per_sec: 100_000,
        ..Config::default()
    })
    .await;
    let c = Client::new(&base);
    let (p, t) = grid(n);
    let mesh = c.upload_json(&p, &t).await?;
    let s = c.create_session(&mesh.id, params).await?;
    s.set_constraints(&grid_constraints(n)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    Ok((c, s))
}

pub(crate) fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// A client that spends 50 ms on each frame while it drags at 60 Hz for
/// 10 s: with a window of one frame, the latency of its last second is
/// the latency of its first (no queue builds up anywhere). Without flow
/// control the socket's buffers fill with frames the client reads late,
/// and the latency grows through the drag.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_slow_client_sees_a_flat_drag_to_frame_latency() -> R {
    let n = 30;
    let (_c, s) = ready_session(n, SessionParams::default()).await?;
    let mut ws = s
        .connect_with(StreamOptions::flow(1, FrameEncoding::Q16))
        .await?;
    let period = Duration::from_secs_f64(1.0 / 60.0);
    let length = Duration::from_secs(10);
    let start = Instant::now();
    let mut sent: BTreeMap<u64, Instant> = BTreeMap::new();
    // (seconds since the start when the drag was sent, its latency in ms)
    let mut samples: Vec<(f64, f64)> = vec![];
    let mut seq = 0u64;
    while start.elapsed() < length {
        while start + period * seq as u32 <= Instant::now() && start.elapsed() < length {
            seq += 1;
            // a slow circle in the grid's plane: the handle goes and comes back
            let a = seq as f64 * 0.05;
            ws.drag(0, [0.02 * a.cos(), 0.02 * a.sin(), 0.0], None, seq)
                .await?;
            sent.insert(seq, Instant::now());
        }
        let due = start + period * seq as u32;
        let Ok(msg) = tokio::time::timeout_at(due.into(), ws.next_full()).await else {
            continue;
        };
        match msg? {
            WsFull::Frame(f) => {
                let now = Instant::now();
                while let Some((&k, &t)) = sent.first_key_value() {
                    if k > f.header.ack_seq {
                        break;
                    }
                    samples.push(((t - start).as_secs_f64(), (now - t).as_secs_f64() * 1e3));
                    sent.remove(&k);
                }
                // the client draws the frame
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            WsFull::Event(e @ ServerMsg::Error { .. }) => return Err(format!("{e:?}").into()),
            WsFull::Event(_) => {}
            WsFull::Closed(c) => return Err(format!("closed {c:?}").into()),
        }
    }
    let window = |from: f64, to: f64| {
        median(
            samples
                .iter()
                .filter(|(t, _)| (from..to).contains(t))
                .map(|(_, l)| *l)
                .collect(),
        )
    };
    let (first, last) = (window(0.0, 1.0), window(8.5, 9.5));
    eprintln!(
        "drag->frame medians: first second {first:.1} ms, last second {last:.1} ms, {} samples",
        samples.len()
    );
    assert!(samples.len() > 300, "{} drags acknowledged", samples.len());
    assert!(
        last <= 2.0 * first + 50.0,
        "the latency grew through the drag: {first:.1} ms in the first second, {last:.1} ms at the end"
    );
    Ok(())
}

/// A client that declares `max_fps` gets no more frames than that rate
/// allows over the time it is connected, still gets the settled frame,
/// and gets fewer frames than a client without the cap on the same drags.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_declared_frame_rate_caps_the_frames_and_the_settled_one_still_comes() -> R {
    let (_c, s) = ready_session(
        30,
        SessionParams {
            tol: Some(1e-6),
            ..SessionParams::default()
        },
    )
    .await?;
    let max_fps = 20;
    let mut capped = s
        .connect_with(StreamOptions::flow(1, FrameEncoding::Delta).at_most_fps(max_fps))
        .await?;
    let mut free = s
        .connect_with(StreamOptions::flow(1, FrameEncoding::Delta))
        .await?;
    let start = Instant::now();
    let drags = 40u64;
    // (frames, whether the settled frame of the last drag came)
    let mut seen = [(0usize, false); 2];
    /// Reads what `c` gets until `until`, or until the settled frame of
    /// drag `last`.
    async fn read(
        c: &mut dend_client::WsClient,
        until: Instant,
        last: u64,
        seen: &mut (usize, bool),
    ) -> R {
        while !seen.1 {
            let Ok(msg) = tokio::time::timeout_at(until.into(), c.next_full()).await else {
                return Ok(());
            };
            match msg? {
                WsFull::Frame(f) => {
                    seen.0 += 1;
                    seen.1 = f.header.ack_seq >= last && f.header.settled;
                }
                WsFull::Event(e @ ServerMsg::Error { .. }) => return Err(format!("{e:?}").into()),
                WsFull::Event(_) => {}
                WsFull::Closed(c) => return Err(format!("closed {c:?}").into()),
            }
        }
        Ok(())
    }
    for seq in 1..=drags {
        capped.drag(0, [0.01, 0.02, 0.0], None, seq).await?;
        let until = Instant::now() + Duration::from_millis(10);
        read(&mut capped, until, drags, &mut seen[0]).await?;
        read(&mut free, until, drags, &mut seen[1]).await?;
    }
    // then each reads until the settled frame answering the last drag
    let mut counts = vec![];
    for (c, seen) in [&mut capped, &mut free].into_iter().zip(&mut seen) {
        read(c, Instant::now() + Duration::from_secs(60), drags, seen).await?;
        assert!(seen.1, "no settled frame for the last drag");
        counts.push((seen.0, start.elapsed().as_secs_f64()));
    }
    let ((capped_frames, capped_secs), (free_frames, _)) = (counts[0], counts[1]);
    eprintln!(
        "max_fps {max_fps}: {capped_frames} frames in {capped_secs:.2} s; without a cap {free_frames}"
    );
    // the state frame at connection plus one per interval at most
    let allowed = 2 + (capped_secs * f64::from(max_fps)).ceil() as usize;
    assert!(
        capped_frames <= allowed,
        "{capped_frames} frames in {capped_secs:.2} s at max_fps {max_fps}"
    );
    assert!(
        capped_frames < free_frames,
        "the cap did not reduce the frames: {capped_frames} against {free_frames}"
    );
    Ok(())
}

/// A client that declares `refine_fps` gets the frame answering each of
/// its drags without waiting for the refinement interval, and over the
/// settle at most one refinement per interval, then the settled frame;
/// a client without the cap gets every refinement.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn refinements_wait_for_refine_fps_and_drag_answers_do_not() -> R {
    let (_c, s) = ready_session(
        30,
        SessionParams {
            tol: Some(1e-9),
            ..SessionParams::default()
        },
    )
    .await?;
    // an answer held back like a refinement would make the drags below
    // take a tenth of a second each
    let refine_fps = 10;
    let interval = 1.0 / f64::from(refine_fps);
    let mut capped = s
        .connect_with(StreamOptions::flow(1, FrameEncoding::Delta).refining_at_most(refine_fps))
        .await?;
    // no flow control: every frame the session makes waits in its socket
    let mut free = s.connect_with(StreamOptions::default()).await?;
    let drags = 40u64;
    /// Reads `c` until a frame includes drag `seq` (and is settled, if
    /// asked); the number of frames before it that include it and are
    /// not settled.
    async fn until(
        c: &mut dend_client::WsClient,
        seq: u64,
        settled: bool,
    ) -> Result<usize, Box<dyn std::error::Error>> {
        let mut refinements = 0;
        loop {
            let msg = tokio::time::timeout(Duration::from_secs(120), c.next_full()).await??;
            match msg {
                WsFull::Frame(f) if f.header.ack_seq >= seq => {
                    if f.header.settled || !settled {
                        return Ok(refinements);
                    }
                    refinements += 1;
                }
                WsFull::Frame(_) => {}
                WsFull::Event(e @ ServerMsg::Error { .. }) => return Err(format!("{e:?}").into()),
                WsFull::Event(_) => {}
                WsFull::Closed(c) => return Err(format!("closed {c:?}").into()),
            }
        }
    }
    let start = Instant::now();
    for seq in 1..=drags {
        capped.drag(0, [0.0, 0.03, 0.01], None, seq).await?;
        until(&mut capped, seq, false).await?;
    }
    let drag_secs = start.elapsed().as_secs_f64();
    let settle_start = Instant::now();
    let capped_refinements = until(&mut capped, drags, true).await?;
    let settle_secs = settle_start.elapsed().as_secs_f64();
    let free_refinements = until(&mut free, drags, true).await?;
    eprintln!(
        "refine_fps {refine_fps}: {drags} drags in {drag_secs:.2} s; settle {settle_secs:.2} s \
         with {capped_refinements} refinement frames (without the cap: {free_refinements})"
    );
    assert!(
        drag_secs < drags as f64 * interval / 2.0,
        "{drags} drags, each answered at once, took {drag_secs:.2} s at refine_fps {refine_fps}"
    );
    let allowed = 1 + (settle_secs / interval).ceil() as usize;
    assert!(
        capped_refinements <= allowed,
        "{capped_refinements} refinements in {settle_secs:.2} s at refine_fps {refine_fps}"
    );
    assert!(
        free_refinements > capped_refinements,
        "the cap did not hold refinements back: {capped_refinements}, without it {free_refinements}"
    );
    Ok(())
}

/// The settled frame says `converged` only when the convergence test
/// held: a settle cut by `max_iters` ends settled and not converged, at
/// `max_iters` iterations; a settle that converged is a fixed point of the
/// iteration, so a drag that changes nothing from there converges again
/// at once (within two iterations) without moving the pose by more than
/// the tolerance.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_settled_frame_is_converged_only_when_the_convergence_test_held() -> R {
    let n = 24;
    /// Reads until the settled frame that includes drag `seq`.
    /// (converged, iterations, positions)
    type Settled = (bool, u32, Vec<[f32; 3]>);
    async fn settled(
        ws: &mut dend_client::WsClient,
        seq: u64,
    ) -> Result<Settled, Box<dyn std::error::Error>> {
        loop {
            let msg = tokio::time::timeout(Duration::from_secs(120), ws.next_full()).await??;
            match msg {
                WsFull::Frame(f) if f.header.ack_seq >= seq && f.header.settled => {
                    return Ok((f.header.converged, f.header.iteration, f.positions))
                }
                WsFull::Event(e @ ServerMsg::Error { .. }) => return Err(format!("{e:?}").into()),
                WsFull::Closed(c) => return Err(format!("closed {c:?}").into()),
                _ => {}
            }
        }
    }
    // a lift and a turn of the top row: tens of iterations to converge
    let turn = Some([0.0, (0.35f64).sin(), 0.0, (0.35f64).cos()]);
    // (the grid's edges are 1 long)
    let lift = [0.0, 0.0, 0.4 * (n - 1) as f64];

    let (_c, cut) = ready_session(
        n,
        SessionParams {
            max_iters: Some(3),
            tol: Some(1e-9),
            ..SessionParams::default()
        },
    )
    .await?;
    let mut ws = cut
        .connect_with(StreamOptions::flow(1, FrameEncoding::F32))
        .await?;
    ws.drag(0, lift, turn, 1).await?;
    let (converged, its, _) = settled(&mut ws, 1).await?;
    assert!(!converged, "a settle cut at max_iters says converged");
    assert_eq!(its, 3);

    let tol = 1e-4;
    let (_c, full) = ready_session(
        n,
        SessionParams {
            tol: Some(tol),
            ..SessionParams::default()
        },
    )
    .await?;
    let mut ws = full
        .connect_with(StreamOptions::flow(1, FrameEncoding::F32))
        .await?;
    ws.drag(0, lift, turn, 1).await?;
    let (converged, its, p1) = settled(&mut ws, 1).await?;
    assert!(
        converged && its > 3 && its < 100,
        "converged {converged} in {its}"
    );
    // a drag that changes nothing: the converged pose is a fixed point
    ws.drag(0, [0.0; 3], None, 2).await?;
    let (converged, its, p2) = settled(&mut ws, 2).await?;
    assert!(
        converged && its <= 2,
        "again: converged {converged} in {its}"
    );
    let edge = 1.0;
    let moved = p1
        .iter()
        .zip(&p2)
        .map(|(a, b)| {
            (0..3)
                .map(|k| f64::from(a[k] - b[k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max);
    assert!(
        moved <= 2.0 * tol * edge + 1e-6,
        "the converged pose moved {moved:.2e} (tolerance {:.2e})",
        tol * edge
    );
    Ok(())
}

/// A drag that arrives while the session refines does not wait for the
/// refinement (`Deformer::set_interrupt`). With 100 iterations per frame
/// and a tolerance that is never met, every solve runs 100 iterations:
/// the drag's own, then refinements of 100 each. A drag sent halfway
/// through a refinement stops it early: the last frame before the drag's
/// own shows a count of iterations since the targets changed that is not
/// a multiple of 100 (a whole refinement would end on one), and the
/// drag's frame shows 100 (its own solve, from a new sequence).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drag_stops_the_refinement_it_arrives_during() -> R {
    let n = 30;
    let (base, _state) = start(Config {
        ws_max_messages_per_sec: 100_000,
        iters_per_frame: 100,
        ..Config::default()
    })
    .await;
    let c = Client::new(&base);
    let (p, t) = grid(n);
    let mesh = c.upload_json(&p, &t).await?;
    let s = c
        .create_session(
            &mesh.id,
            SessionParams {
                tol: Some(1e-300),
                max_iters: Some(1_000_000),
                ..SessionParams::default()
            },
        )
        .await?;
    s.set_constraints(&grid_constraints(n)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    // every frame, no window: nothing is skipped
    let mut ws = s.connect_with(StreamOptions::default()).await?;
    let mut stopped = 0;
    for round in 1..=3u64 {
        let seq = 2 * round - 1;
        ws.drag(0, [0.0, 0.0, 0.01], None, seq).await?;
        // the drag's frame (400 iterations), then a refinement starts
        let t0 = Instant::now();
        loop {
            if let WsFull::Frame(f) = ws.next_full().await? {
                if f.header.ack_seq == seq {
                    assert_eq!(f.header.iteration, 100, "{:?}", f.header);
                    break;
                }
            }
        }
        let solve = t0.elapsed();
        // halfway through the refinement that follows
        tokio::time::sleep(solve / 2).await;
        let next = seq + 1;
        ws.drag(0, [0.0, 0.0, 0.01], None, next).await?;
        let mut before = vec![];
        loop {
            if let WsFull::Frame(f) = ws.next_full().await? {
                if f.header.ack_seq == next {
                    assert_eq!(f.header.iteration, 100, "{:?}", f.header);
                    break;
                }
                before.push(f.header.iteration);
            }
        }
        // (frames of the drag's solve and of finished refinements may have
        // been on their way; the one in flight ended early)
        if before.last().is_some_and(|&i| i % 100 != 0) {
            stopped += 1;
        }
        eprintln!("round {round}: drag solve {solve:?}, frames before the next drag's {before:?}");
    }
    assert!(
        stopped >= 2,
        "a refinement stopped early in {stopped} of 3 rounds"
    );
    Ok(())
}
