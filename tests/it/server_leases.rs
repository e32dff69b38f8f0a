//! Session leases and an unreachable store, in process (docs/deployment.md;
//! tests/system/failover.rs runs the same rules with real processes, PostgreSQL
//! and HAProxy):
//! - two instances sharing one store: a session leased by one is refused
//!   by the other with 409 `session_owned_elsewhere` naming the owner; when
//!   the owner stops renewing, the other takes it over with every
//!   acknowledged drag, and the old owner's next write is fenced (refused,
//!   applied nowhere);
//! - a store that stops answering: `/healthz/ready` 503, writes refused
//!   with 503 `store_unavailable`, a WebSocket drag refused with an `error`
//!   event and not applied, and after the store is back no acknowledged
//!   drag is missing and no refused one present.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use dend_client::ws::{DeltaJson, ServerMsg};
use dend_client::{Client, ClientError, ErrorCode, SessionParams, WsEvent};
use dend_server::lease::Cluster;
use dend_server::store::{with_faults, JournalEntry, MemoryStore, SessionLog, Store, StoreError};
use dend_server::{app, AppState, Config};
use dend_testkit::server::{grid, grid_constraints};

const N: usize = 5;

async fn start(store: Arc<dyn Store>, cluster: Option<(&str, u64)>) -> (String, AppState) {
    let config = Config {
        addr: ([127, 0, 0, 1], 0).into(),
        ..Config::default()
    };
    let listener = tokio::net::TcpListener::bind(config.addr)
        .await
        .expect("bind");
    let addr = listener.local_addr().expect("addr");
    let cluster = cluster.map(|(id, ttl_ms)| {
        Arc::new(Cluster {
            instance: id.to_owned(),
            ttl: Duration::from_millis(ttl_ms),
        })
    });
    let state = AppState::with_cluster(config, store, cluster).expect("state");
    let router = app(state.clone());
    drop(tokio::spawn(async move {
        axum::serve(dend_server::no_delay(listener), router).await
    }));
    (format!("http://{addr}"), state)
}

fn api_code(r: &Result<impl std::fmt::Debug, ClientError>) -> Option<(u16, ErrorCode, String)> {
    match r {
        Err(ClientError::Api {
            status,
            code,
            message,
        }) => Some((*status, code.clone(), message.clone())),
        _ => None,
    }
}

/// x of the first handle vertex (rest x = 0).
async fn handle_x(s: &dend_client::SessionClient) -> Result<f64, ClientError> {
    Ok(s.pose().await?.positions[N * (N - 1)][0])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn leased_elsewhere_is_refused_then_taken_over_and_the_old_owner_fenced(
) -> Result<(), ClientError> {
    let store: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let (a_url, a) = start(store.clone(), Some(("a", 400))).await;
    let (b_url, b) = start(store.clone(), Some(("b", 400))).await;
    let renew_b = dend_server::lease::spawn_renewer(b.clone()).expect("cluster");
    let (ca, cb) = (Client::new(&a_url), Client::new(&b_url));
    let (p, t) = grid(N);
    let mesh = ca.upload_json(&p, &t).await?;
    // created on a, opened (and leased) by b, where its first request goes
    let s = ca
        .create_session(&mesh.id, SessionParams::default())
        .await?;
    assert!(a.registry.is_empty(), "creation does not open it");
    let sb = cb.session(&s.id, &s.token);
    let sa = ca.session(&s.id, &s.token);
    sb.set_constraints(&grid_constraints(N)).await?;
    sb.wait_ready(Duration::from_secs(20)).await?;
    let _ = sb
        .drag(0, DeltaJson::translate([0.5, 0.0, 0.0]), None)
        .await?;
    // a never drives it while b's lease lives: 409 naming b, HTTP and WebSocket
    let r = sa.info().await;
    let (status, code, message) = api_code(&r).expect("refused");
    assert_eq!((status, code), (409, ErrorCode::SessionOwnedElsewhere));
    assert!(message.contains("`b`"), "{message}");
    assert!(sa.connect().await.is_err(), "no WebSocket on a");
    assert!(a.registry.is_empty());
    // b stops renewing (as if it died, before it could hand the session
    // over): once the lease expired, a takes over
    renew_b.abort();
    tokio::time::sleep(Duration::from_millis(600)).await;
    sa.wait_ready(Duration::from_secs(20)).await?;
    assert!(
        (handle_x(&sa).await? - 0.5).abs() < 1e-9,
        "b's drag is there"
    );
    assert_eq!(ca.metric("dend_leases_taken_over_total").await?, Some(1.0));
    // b's next write is fenced: refused, applied nowhere, and b lets go
    let r = sb
        .drag(0, DeltaJson::translate([1.0, 0.0, 0.0]), None)
        .await;
    let (status, code, message) = api_code(&r).expect("fenced");
    assert_eq!(
        (status, code),
        (409, ErrorCode::SessionOwnedElsewhere),
        "{message}"
    );
    assert!(message.contains("`a`"), "{message}");
    let r = sb.info().await;
    assert_eq!(
        api_code(&r).map(|c| c.1),
        Some(ErrorCode::SessionOwnedElsewhere)
    );
    assert!(b.registry.get(&s.id).is_none_or(|h| h.is_fenced()));
    // and no longer counts it as its own
    assert_eq!(cb.metric("dend_sessions_owned").await?, Some(0.0));
    assert!(
        (handle_x(&sa).await? - 0.5).abs() < 1e-9,
        "the fenced drag is nowhere"
    );
    // a drives it
    let pose = sa
        .drag(0, DeltaJson::translate([0.25, 0.0, 0.0]), None)
        .await?;
    assert!((pose.positions[N * (N - 1)][0] - 0.75).abs() < 1e-9);
    Ok(())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn the_owner_hands_a_session_over_to_the_instance_that_asks() -> Result<(), ClientError> {
    // as when an instance comes back and the load balancer routes the
    // session to it again while its current owner lives
    let store: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let (a_url, a) = start(store.clone(), Some(("a", 600))).await;
    let (b_url, b) = start(store.clone(), Some(("b", 600))).await;
    let _renew_b = dend_server::lease::spawn_renewer(b.clone()).expect("cluster");
    let (ca, cb) = (Client::new(&a_url), Client::new(&b_url));
    let (p, t) = grid(N);
    let mesh = ca.upload_json(&p, &t).await?;
    let s = ca
        .create_session(&mesh.id, SessionParams::default())
        .await?;
    let sb = cb.session(&s.id, &s.token);
    sb.set_constraints(&grid_constraints(N)).await?;
    sb.wait_ready(Duration::from_secs(20)).await?;
    let mut ws = sb.connect().await?;
    ws.drag(0, [0.5, 0.0, 0.0], None, 1).await?;
    let _ = ws.frame_acking(1, false).await?;
    let sa = ca.session(&s.id, &s.token);
    let first = sa.info().await;
    assert_eq!(
        api_code(&first).map(|c| c.1),
        Some(ErrorCode::SessionOwnedElsewhere)
    );
    // b hands it over at its next renewal (a third of the lifetime), long
    // before the lease would expire; b's client sees the session close
    let t0 = std::time::Instant::now();
    loop {
        match sa.info().await {
            Ok(_) => break,
            Err(e) if t0.elapsed() > Duration::from_millis(550) => return Err(e),
            Err(_) => tokio::time::sleep(Duration::from_millis(20)).await,
        }
    }
    loop {
        if let WsEvent::Closed(_) = ws.next().await? {
            break;
        }
    }
    assert!(b.registry.get(&s.id).is_none(), "closed on b");
    sa.wait_ready(Duration::from_secs(20)).await?;
    assert!(
        (handle_x(&sa).await? - 0.5).abs() < 1e-9,
        "the acknowledged drag moved with it"
    );
    assert_eq!(cb.metric("dend_leases_handed_over_total").await?, Some(1.0));
    assert_eq!(ca.metric("dend_leases_taken_over_total").await?, Some(0.0));
    assert!(a.registry.contains(&s.id));
    Ok(())
}

/// A memory store that can be made unreachable: every call fails with
/// `Unavailable` while `down` is set.
/// Returns the memory store too, to read what it holds.
fn flaky_store(down: &Arc<AtomicBool>) -> (Arc<MemoryStore>, Arc<dyn Store>) {
    let down = down.clone();
    let inner = Arc::new(MemoryStore::new());
    let flaky = Arc::new(with_faults(inner.clone(), move |_| {
        if down.load(Ordering::SeqCst) {
            Err(StoreError::Unavailable("connection refused".into()))
        } else {
            Ok(())
        }
    }));
    (inner, flaky)
}

async fn status_code(url: &str) -> Result<(u16, serde_json::Value), ClientError> {
    let r = reqwest::get(url).await?;
    let status = r.status().as_u16();
    Ok((status, r.json().await.unwrap_or_default()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn an_unreachable_store_refuses_writes_and_loses_no_acknowledged_drag(
) -> Result<(), ClientError> {
    let down = Arc::new(AtomicBool::new(false));
    let (inner, flaky) = flaky_store(&down);
    let (url, _st) = start(flaky, None).await;
    let c = Client::new(&url);
    let (p, t) = grid(N);
    let mesh = c.upload_json(&p, &t).await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    s.set_constraints(&grid_constraints(N)).await?;
    s.wait_ready(Duration::from_secs(20)).await?;
    assert_eq!(status_code(&format!("{url}/healthz/ready")).await?.0, 200);
    let mut ws = s.connect().await?;
    ws.drag(0, [0.5, 0.0, 0.0], None, 1).await?;
    let _ = ws.frame_acking(1, false).await?;

    down.store(true, Ordering::SeqCst);
    let (status, body) = status_code(&format!("{url}/healthz/ready")).await?;
    assert_eq!(
        (status, body["code"].as_str()),
        (503, Some("store_unavailable"))
    );
    assert_eq!(
        status_code(&format!("{url}/healthz")).await?.0,
        200,
        "still live"
    );
    let r = c.upload_json(&p, &t).await;
    assert_eq!(
        api_code(&r).map(|c| (c.0, c.1)),
        Some((503, ErrorCode::StoreUnavailable))
    );
    // a WebSocket drag: refused with an error event, frames keep ack 1
    ws.drag(0, [0.25, 0.0, 0.0], None, 2).await?;
    let mut refused = false;
    while !refused {
        match ws.next().await? {
            WsEvent::Event(ServerMsg::Error { code, message, .. }) => {
                assert_eq!(code, ErrorCode::StoreUnavailable, "{message}");
                refused = true;
            }
            WsEvent::Frame(h, _) => assert!(h.ack_seq <= 1, "seq 2 acknowledged"),
            WsEvent::Closed(c) => panic!("closed {c:?}"),
            WsEvent::Event(_) => {}
        }
    }
    // an HTTP drag: 503, not applied either
    let r = s.drag(0, DeltaJson::translate([4.0, 0.0, 0.0]), None).await;
    assert_eq!(api_code(&r).map(|c| c.0), Some(503));

    down.store(false, Ordering::SeqCst);
    assert_eq!(status_code(&format!("{url}/healthz/ready")).await?.0, 200);
    // the client sends the refused drag again
    // (the HTTP drag's refusal reached this client as an event too)
    ws.drag(0, [0.25, 0.0, 0.0], None, 2).await?;
    loop {
        match ws.next().await? {
            WsEvent::Frame(h, _) if h.ack_seq >= 2 && h.converged => break,
            WsEvent::Closed(c) => panic!("closed {c:?}"),
            _ => {}
        }
    }
    let x = handle_x(&s).await?;
    assert!(
        (x - 0.75).abs() < 1e-9,
        "acknowledged drags 0.5 + 0.25, got {x}"
    );
    // and what the store holds revives to the same: journal and checkpoint
    let j = inner
        .journal(&s.id)
        .map_err(|e| ClientError::Protocol(e.to_string()))?;
    let cp = inner
        .get_checkpoint(&s.id)
        .map_err(|e| ClientError::Protocol(e.to_string()))?;
    let journaled: f64 = j
        .iter()
        .map(|JournalEntry::Drag { translation, .. }| translation[0])
        .sum();
    let checkpointed = cp.map_or(0.0, |c| c.targets[0].translation[0]);
    assert!(
        (checkpointed + journaled - 0.75).abs() < 1e-9,
        "store: checkpoint {checkpointed} + journal {journaled}"
    );
    Ok(())
}
