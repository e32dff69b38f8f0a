//! What clients see while a session is revived on another instance or its
//! factor rebuilt, in process (issue 36; tests/system/ runs the same with
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
use dend_client::{Client, ClientError, Pose, SessionClient, WsEvent};
use dend_server::lease::Cluster;
use dend_server::store::{MemoryStore, Store};
use dend_server::{app, AppState, Config};
use dend_testkit::server::{grid, grid_constraints};
use serde_json::json;

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
    let mut state = AppState::with_store(config, store).expect("state");
    state.cluster = Some(Arc::new(Cluster {
        instance: id.to_owned(),
        ttl: Duration::from_millis(ttl_ms),
    }));
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
    matches!(e, ClientError::Api { code, .. } if code == "session_owned_elsewhere")
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
    let s = ca.create_session(&mesh.id, json!({})).await?;
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
            // before issue 36: 409 `not_ready` while the factor was rebuilt
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
    let s = c.create_session(&mesh.id, json!({})).await?;
    s.set_constraints(&grid_constraints(BIG)).await?;
    s.wait_ready(Duration::from_secs(20)).await?;
    let mut ws = s.connect().await?;
    // a new constraint set (building), then at once a WebSocket drag and an
    // HTTP drag: both wait for the factor and are applied, in order
    let mut other = grid_constraints(BIG);
    other["fixed"] = json!((0..BIG - 1).collect::<Vec<usize>>());
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
