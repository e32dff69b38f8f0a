//! What clients see while a session is revived on another instance or its
//! factor rebuilt, in process (docs/reliability.md; tests/system/ runs the same with
//! real processes, PostgreSQL and HAProxy):
//! - every pose read during a takeover holds every acknowledged drag: the
//!   reads wait for the revived pose (checkpoint plus journal), never the
//!   checkpoint pose alone, and never flag as settled a pose the solver
//!   has not settled;
//! - a drag that reaches the session while it is revived or its factor is
//!   rebuilt is queued and applied once it is ready (HTTP answers with
//!   it, a WebSocket drag is acknowledged by a frame), not refused.

use std::sync::Arc;
use std::time::{Duration, Instant};

use dend_client::ws::{ClientMsg, DeltaJson, ServerMsg};
use dend_client::{
    Client, ClientError, ErrorCode, Pose, SessionClient, SessionParams, VertexSet, WsEvent,
};
use dend_server::lease::Cluster;
use dend_server::store::{MemoryStore, Store};
use dend_server::{app, AppState, Config};
use dend_testkit::server::{grid, grid_constraints};

const N: usize = 6;

async fn start(store: Arc<dyn Store>, id: &str, ttl_ms: u64) -> (String, AppState) {
    let config = Config {
        addr: ([127, 0, 0, 1], 0).into(),
        ..Config::default()
    };
    let listener = tokio::net::TcpListener::bind(config.addr)
        .await
        .expect("bind");
    let addr = listener.local_addr().expect("addr");
    let cluster = Some(Arc::new(Cluster {
        instance: id.to_owned(),
        ttl: Duration::from_millis(ttl_ms),
    }));
    let state = AppState::with_cluster(config, store, cluster).expect("state");
    let router = app(state.clone());
    drop(tokio::spawn(async move {
        axum::serve(dend_server::no_delay(listener), router).await
    }));
    (format!("http://{addr}"), state)
}

/// The handle row's offset from rest in x on an `n`×`n` grid, checked
/// equal on every handle vertex.
fn offset_on(p: &Pose, n: usize) -> f64 {
    let first = p.positions[n * (n - 1)][0];
    for i in 0..n {
        let x = p.positions[n * (n - 1) + i][0] - i as f64;
        assert!((x - first).abs() < 1e-9, "the handle row moved as one");
    }
    first
}

fn offset(p: &Pose) -> f64 {
    offset_on(p, N)
}

fn owned_elsewhere(e: &ClientError) -> bool {
    matches!(
        e,
        ClientError::Api {
            code: ErrorCode::SessionOwnedElsewhere,
            ..
        }
    )
}

/// Reads the pose on `s` in a loop until `end`, failing on any pose whose
/// handle offset is not one of `allowed` or that is flagged settled at
/// iteration 0 (no solve settled it); the number of poses read.
async fn read_loop(s: SessionClient, allowed: Vec<f64>, end: Instant) -> Result<usize, String> {
    let mut read = 0;
    while Instant::now() < end {
        match s.pose().await {
            Ok(p) => {
                let x = offset(&p);
                if !allowed.iter().any(|a| (x - a).abs() < 1e-6) {
                    return Err(format!(
                        "read {read} served a pose without the acknowledged drags: handle offset \
                         {x}, expected one of {allowed:?} (ack_seq {}, revision {}, iteration {}, \
                         settled {})",
                        p.ack_seq, p.revision, p.iteration, p.settled
                    ));
                }
                if p.settled && p.iteration == 0 && p.objective.is_none() {
                    return Err(format!(
                        "read {read}: a pose flagged settled before any solve"
                    ));
                }
                read += 1;
            }
            Err(e) if owned_elsewhere(&e) => {}
            Err(e) => return Err(format!("pose read failed: {e}")),
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    Ok(read)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn reads_through_a_takeover_hold_every_acknowledged_drag_and_drags_then_are_applied(
) -> Result<(), ClientError> {
    let store: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let (a_url, a) = start(store.clone(), "a", 300).await;
    let (b_url, _b) = start(store.clone(), "b", 300).await;
    let renew_a = dend_server::lease::spawn_renewer(a).expect("cluster");
    let (ca, cb) = (Client::new(&a_url), Client::new(&b_url));
    let (p, t) = grid(N);
    let mesh = ca.upload_json(&p, &t).await?;
    let s = ca
        .create_session(&mesh.id, SessionParams::default())
        .await?;
    let sa = ca.session(&s.id, &s.token);
    sa.set_constraints(&grid_constraints(N)).await?;
    sa.wait_ready(Duration::from_secs(20)).await?;
    // ten drags in one gesture (the handle held, as the editor does): no
    // checkpoint after them, they are in the journal only
    let mut ws = sa.connect().await?;
    ws.send(&ClientMsg::Grab { handle: 0.into() }).await?;
    for seq in 1..=10 {
        ws.drag(0, [0.01, 0.0, 0.0], None, seq).await?;
        let _ = ws.frame_acking(seq, false).await?;
    }
    // a stops renewing, as if it died: b takes the session over once the
    // lease expired, while readers poll b and one HTTP drag is sent to b
    renew_a.abort();
    let sb = cb.session(&s.id, &s.token);
    let end = Instant::now() + Duration::from_secs(2);
    let readers: Vec<_> = (0..4)
        .map(|_| tokio::spawn(read_loop(sb.clone(), vec![0.1, 0.15], end)))
        .collect();
    let dragged = loop {
        match sb
            .drag(0, DeltaJson::new([0.05, 0.0, 0.0], None), None)
            .await
        {
            Ok(p) => break p,
            Err(e) if owned_elsewhere(&e) => {
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
            // a 409 `not_ready` while the factor is rebuilt would drop the drag
            Err(e) => panic!("a drag during the takeover was refused: {e}"),
        }
    };
    assert!(
        (offset(&dragged) - 0.15).abs() < 1e-6,
        "the drag sent during the takeover is applied on the acknowledged ones"
    );
    let mut total = 0;
    for r in readers {
        total += r.await.expect("reader").map_err(ClientError::Protocol)?;
    }
    assert!(total > 0, "the readers read the pose after the takeover");
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn drags_during_a_factor_rebuild_are_queued_and_applied() -> Result<(), ClientError> {
    // big enough that its factor takes a while to build
    const BIG: usize = 60;
    let store: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let (url, _st) = start(store, "a", 10_000).await;
    let c = Client::new(&url);
    let (p, t) = grid(BIG);
    let mesh = c.upload_json(&p, &t).await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    s.set_constraints(&grid_constraints(BIG)).await?;
    s.wait_ready(Duration::from_secs(20)).await?;
    let mut ws = s.connect().await?;
    // a new constraint set (building), then at once a WebSocket drag and an
    // HTTP drag: both wait for the factor and are applied, in order
    let mut other = grid_constraints(BIG);
    other.fixed = VertexSet::indices(0..BIG - 1);
    s.set_constraints(&other).await?;
    ws.drag(0, [0.25, 0.0, 0.0], None, 1).await?;
    let http = s
        .drag(0, DeltaJson::new([0.5, 0.0, 0.0], None), None)
        .await?;
    assert!(
        (offset_on(&http, BIG) - 0.75).abs() < 1e-6,
        "both drags applied"
    );
    let t0 = Instant::now();
    loop {
        match ws.next().await? {
            WsEvent::Frame(h, _) if h.ack_seq >= 1 => break,
            WsEvent::Event(e @ ServerMsg::Error { .. }) => {
                panic!("the WebSocket drag was refused: {e:?}")
            }
            WsEvent::Closed(c) => panic!("closed ({c:?})"),
            _ => assert!(t0.elapsed() < Duration::from_secs(20), "no frame acked it"),
        }
    }
    Ok(())
}

/// What one read on the survivor got, and when.
enum Read {
    /// A pose.
    Pose(Instant, Pose),
    /// 409 `session_owned_elsewhere` with its retry hint.
    Refused(Instant, Duration),
}

/// The retry hint of a `session_owned_elsewhere` message ("retry in N ms").
fn retry_hint(message: &str) -> Option<Duration> {
    let rest = message.split("retry in ").nth(1)?;
    let ms = rest.split(' ').next()?.parse::<u64>().ok()?;
    Some(Duration::from_millis(ms))
}

/// Reads the pose on `s` in a loop until `end`; every answer, in order.
async fn record_reads(s: SessionClient, end: Instant) -> Result<Vec<Read>, String> {
    let mut reads = vec![];
    while Instant::now() < end {
        match s.pose().await {
            Ok(p) => reads.push(Read::Pose(Instant::now(), p)),
            Err(ClientError::Api {
                code: ErrorCode::SessionOwnedElsewhere,
                message,
                ..
            }) => {
                let hint = retry_hint(&message).ok_or(format!("no retry hint in {message:?}"))?;
                reads.push(Read::Refused(Instant::now(), hint));
            }
            Err(e) => return Err(format!("pose read failed: {e}")),
        }
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
    Ok(reads)
}

/// The largest distance between two poses' vertices.
fn distance(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

/// A takeover through the lease's expiry (the owner stopped renewing: dead
/// but not seen as dead, CPU-starved or cut off), read throughout on the
/// survivor. The owner's last drags are in the journal only, so the
/// survivor's revival solves from the checkpoint (the rest pose) towards
/// them, one iteration per frame. Every pose served is the settled revived
/// pose: flagged settled and, vertex by vertex, the owner's settled pose
/// (the same targets solved to the end), never an iterate on the way there
/// (those are off by up to the whole drag). Every refusal's retry hint is
/// no longer than the wait that followed it.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn reads_through_a_lease_expiry_takeover_get_the_settled_revived_pose(
) -> Result<(), ClientError> {
    const M: usize = 8;
    let store: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let (a_url, a) = start(store.clone(), "a", 400).await;
    let (b_url, _b) = start(store.clone(), "b", 400).await;
    let renew_a = dend_server::lease::spawn_renewer(a).expect("cluster");
    let (ca, cb) = (Client::new(&a_url), Client::new(&b_url));
    let (p, t) = grid(M);
    let mesh = ca.upload_json(&p, &t).await?;
    let s = ca
        .create_session(&mesh.id, SessionParams::default())
        .await?;
    let sa = ca.session(&s.id, &s.token);
    sa.set_constraints(&grid_constraints(M)).await?;
    sa.wait_ready(Duration::from_secs(20)).await?;
    // one gesture of ten drags, the handle held: journaled, no checkpoint
    let mut ws = sa.connect().await?;
    ws.send(&ClientMsg::Grab { handle: 0.into() }).await?;
    for seq in 1..=10 {
        ws.drag(0, [0.15, 0.0, 0.0], None, seq).await?;
        let _ = ws.frame_acking(seq, false).await?;
    }
    // the owner's settled pose of those targets
    let deadline = Instant::now() + Duration::from_secs(20);
    let settled = loop {
        let p = sa.pose().await?;
        if p.settled {
            break p;
        }
        assert!(Instant::now() < deadline, "the owner never settled");
        tokio::time::sleep(Duration::from_millis(10)).await;
    };
    assert!((offset_on(&settled, M) - 1.5).abs() < 1e-6);

    renew_a.abort();
    let taken_from = Instant::now();
    let sb = cb.session(&s.id, &s.token);
    let end = taken_from + Duration::from_secs(3);
    let readers: Vec<_> = (0..3)
        .map(|_| tokio::spawn(record_reads(sb.clone(), end)))
        .collect();
    let mut reads = vec![];
    for r in readers {
        reads.extend(r.await.expect("reader").map_err(ClientError::Protocol)?);
    }
    let first_pose = reads
        .iter()
        .filter_map(|r| match r {
            Read::Pose(at, _) => Some(*at),
            Read::Refused(..) => None,
        })
        .min()
        .expect("the survivor served the session within 3 s");
    let mut poses = 0;
    for r in &reads {
        match r {
            Read::Pose(_, p) => {
                poses += 1;
                assert!(
                    (offset_on(p, M) - 1.5).abs() < 1e-6,
                    "a pose without the acknowledged drags"
                );
                let off = distance(&p.positions, &settled.positions);
                assert!(
                    p.settled && off < 0.02,
                    "an iterate was served during the revival: settled {}, iteration {}, \
                     {off} from the settled pose",
                    p.settled,
                    p.iteration
                );
            }
            Read::Refused(at, hint) => {
                let waited = first_pose.saturating_duration_since(*at);
                assert!(
                    *hint <= waited + Duration::from_millis(50),
                    "a refusal said to retry in {hint:?}, the session was served {waited:?} later"
                );
            }
        }
    }
    assert!(poses > 0);
    Ok(())
}
