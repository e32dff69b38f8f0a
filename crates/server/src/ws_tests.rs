//! Unit tests of the WebSocket logic over in-memory channels (no sockets).

use std::sync::Arc;
use std::time::Duration;

use futures_channel::mpsc;
use futures_util::{SinkExt, StreamExt};

use super::*;
use crate::session::{decode_frame, NoObserver, PeerEvent, SessionOptions};
use crate::store::MemoryStore;
use dend::deform::{FactorCache, Params, Rest};
use dend_protocol::{decode_frame_full, FrameEncoding};

const TOKEN: &str = "secret-token";
const MAX_ITERS: usize = 40;

fn session() -> SessionHandle {
    let rest = Arc::new(Rest::new(dend_testkit::unit_grid(6)).expect("rest"));
    let opts = SessionOptions {
        cache: Arc::new(FactorCache::new(1 << 30)),
        store: Arc::new(MemoryStore::new()),
        observer: Arc::new(NoObserver),
        iters_per_frame: 1,
        preview_above_ms: -1.0,
        build_wait: std::time::Duration::from_secs(30),
        scheduler: Arc::new(crate::scheduler::Scheduler::new(1, None)),
        fence: crate::store::NO_FENCE,
    };
    let store_record = crate::store::SessionRecord {
        id: "s".into(),
        mesh_id: "m".into(),
        token_sha256: hex::encode([0u8; 32]),
        params: serde_json::json!({}),
        constraints: None,
        created_unix: 0,
    };
    opts.store.put_session(&store_record).expect("store");
    let params = Params {
        max_iters: MAX_ITERS,
        ..Params::default()
    };
    SessionHandle::spawn(
        "s".into(),
        "m".into(),
        crate::auth::token_hash(TOKEN),
        rest,
        params,
        opts,
    )
}

fn constraints() -> serde_json::Value {
    serde_json::json!({"fixed": [0, 1, 2, 3, 4, 5], "handles": [{"name": "top", "vertices": [30, 31, 32, 33, 34, 35]}]})
}

struct Client {
    to_server: mpsc::Sender<Result<WsMsg, ()>>,
    from_server: mpsc::Receiver<WsMsg>,
    task: tokio::task::JoinHandle<()>,
}

fn connect(s: &SessionHandle, authed: bool, rate: u32) -> Client {
    connect_with(s, authed, rate, StreamOptions::default())
}

fn connect_with(s: &SessionHandle, authed: bool, rate: u32, stream: StreamOptions) -> Client {
    let (to_server, server_in) = mpsc::channel(64);
    let (server_out, from_server) = mpsc::channel(64);
    let cfg = ConnConfig {
        max_messages_per_sec: rate,
        auth_timeout: Duration::from_secs(5),
        groups: None,
        stream,
    };
    let task = tokio::spawn(run_connection(
        server_out,
        server_in,
        s.clone(),
        authed,
        cfg,
        None,
    ));
    Client {
        to_server,
        from_server,
        task,
    }
}

impl Client {
    async fn send(&mut self, v: serde_json::Value) {
        self.to_server
            .send(Ok(WsMsg::Text(v.to_string())))
            .await
            .expect("send");
    }
    async fn next(&mut self) -> WsMsg {
        tokio::time::timeout(Duration::from_secs(10), self.from_server.next())
            .await
            .expect("message within 10 s")
            .expect("stream open")
    }
    /// Next JSON event of type `ty`, skipping frames and other events.
    async fn event(&mut self, ty: &str) -> serde_json::Value {
        loop {
            if let WsMsg::Text(t) = self.next().await {
                let v: serde_json::Value = serde_json::from_str(&t).expect("json");
                if v["type"] == ty {
                    return v;
                }
            }
        }
    }
    /// Frames until one acknowledges `seq` and the session settled
    /// (converged, or `MAX_ITERS` iterations after the last delta).
    async fn settled_frame(&mut self, seq: u64) -> (crate::session::FrameHeader, Vec<[f32; 3]>) {
        loop {
            if let WsMsg::Binary(b) = self.next().await {
                let (h, v) = decode_frame(&b).expect("frame");
                if h.ack_seq >= seq && (h.converged || h.iteration as usize >= MAX_ITERS) {
                    return (h, v);
                }
            }
        }
    }
}

#[tokio::test]
async fn auth_by_first_message_and_refusals() {
    let s = session();
    let mut good = connect(&s, false, 100);
    good.send(serde_json::json!({"type": "auth", "token": TOKEN}))
        .await;
    assert_eq!(good.event("state").await["state"], "empty");

    let mut wrong = connect(&s, false, 100);
    wrong
        .send(serde_json::json!({"type": "auth", "token": "nope"}))
        .await;
    assert_eq!(wrong.event("error").await["code"], "forbidden");
    assert_eq!(
        wrong.next().await,
        WsMsg::Close(CLOSE_WRONG_TOKEN, "forbidden".into())
    );

    let mut missing = connect(&s, false, 100);
    missing.send(serde_json::json!({"type": "ping"})).await;
    assert_eq!(missing.event("error").await["code"], "missing_token");
    assert_eq!(
        missing.next().await,
        WsMsg::Close(CLOSE_MISSING_TOKEN, "missing_token".into())
    );
}

#[tokio::test]
async fn errors_pong_and_drags_acknowledged() {
    let s = session();
    let mut c = connect(&s, true, 1000);
    c.send(serde_json::json!({"type": "ping", "nonce": 7}))
        .await;
    assert_eq!(c.event("pong").await["nonce"], 7);
    c.send(serde_json::json!({"type": "drag", "handle": 0, "translate": [0, 0, 1], "seq": 1}))
        .await;
    let e = c.event("error").await;
    assert_eq!(
        (e["code"].as_str(), e["seq"].as_u64()),
        (Some("not_ready"), Some(1))
    );
    c.send(serde_json::json!({"type": "bogus"})).await;
    assert_eq!(c.event("error").await["code"], "invalid_json");
    c.send(serde_json::json!({"type": "set_constraints", "constraints": constraints()}))
        .await;
    let _ = c.event("ready").await;
    c.send(serde_json::json!({"type": "drag", "handle": "nope", "translate": [0, 0, 1], "seq": 3}))
        .await;
    assert_eq!(c.event("error").await["code"], "unknown_handle");
    c.to_server
        .send(Ok(WsMsg::Text(
            r#"{"type":"drag","handle":0,"translate":[0,0,NaN],"seq":4}"#.into(),
        )))
        .await
        .expect("send");
    assert_eq!(
        c.event("error").await["code"],
        "non_finite",
        "Python-style NaN literal"
    );
    c.send(serde_json::json!({"type": "drag", "handle": 0, "translate": [0, null, 0], "seq": 4}))
        .await;
    assert_eq!(
        c.event("error").await["code"],
        "non_finite",
        "JavaScript NaN arrives as null"
    );
    for seq in 5..=24 {
        c.send(serde_json::json!({"type": "drag", "handle": 0, "translate": [0.0, 0.0, 0.05], "seq": seq})).await;
    }
    let (h, v) = c.settled_frame(24).await;
    assert_eq!(h.vertex_count, 36);
    // all 20 deltas composed: the handle row moved up by 20 × 0.05
    assert!((v[33][2] - 1.0).abs() < 1e-3, "handle z {}", v[33][2]);
    drop(c.to_server);
    c.task
        .await
        .expect("connection ends when the client stream ends");
}

#[tokio::test]
async fn two_clients_both_get_frames_and_grabs_are_exclusive() {
    let s = session();
    assert_eq!(
        s.set_constraints(constraints(), None)
            .await
            .expect("constraints"),
        crate::session::SessionState::Building
    );
    let mut a = connect(&s, true, 1000);
    let mut b = connect(&s, true, 1000);
    let _ = a.event("state").await;
    let _ = b.event("state").await;
    a.send(serde_json::json!({"type": "grab", "handle": 0}))
        .await;
    let grabbed = b.event("handle_grabbed").await;
    assert_eq!(grabbed["handle"], 0);
    while s.info().state != crate::session::SessionState::Ready {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    b.send(serde_json::json!({"type": "drag", "handle": 0, "translate": [0, 0, 1], "seq": 1}))
        .await;
    assert_eq!(b.event("error").await["code"], "handle_grabbed");
    for seq in 1..=10 {
        a.send(serde_json::json!({"type": "drag", "handle": 0, "translate": [0.0, 0.1, 0.0], "seq": seq})).await;
    }
    let (ha, va) = a.settled_frame(10).await;
    let (hb, vb) = b.settled_frame(10).await;
    assert_eq!(ha.revision, hb.revision);
    assert_eq!(va, vb);
    assert!(
        (va[33][1] - 6.0).abs() < 1e-3,
        "ten deltas of 0.1 composed: {}",
        va[33][1]
    );
    a.send(serde_json::json!({"type": "release", "handle": 0}))
        .await;
    assert_eq!(
        b.event("handle_released").await["client"],
        grabbed["client"]
    );
    // a new constraint set ends every grab, and says so
    a.send(serde_json::json!({"type": "grab", "handle": 0}))
        .await;
    let _ = b.event("handle_grabbed").await;
    let _ = s
        .set_constraints(constraints(), None)
        .await
        .expect("constraints");
    let released = b.event("handle_released").await;
    assert_eq!(released["handle"], 0);
    assert_eq!(released["client"], grabbed["client"]);
}

#[tokio::test]
async fn rate_limit_answers_with_an_error_event() {
    let s = session();
    let mut c = connect(&s, true, 2);
    for _ in 0..5 {
        c.send(serde_json::json!({"type": "ping"})).await;
    }
    assert_eq!(c.event("error").await["code"], "rate_limited");
}

/// The factor build's stages reach the client as `build_progress` events,
/// in order, before `ready`; the session info carries the stage under way
/// and none once ready. The same set again is a cache hit: no stages.
#[tokio::test]
async fn factor_build_stages_are_reported_in_order() {
    let s = session();
    let mut c = connect(&s, true, 1000);
    assert_eq!(
        c.event("state").await["build_stage"],
        serde_json::Value::Null
    );
    for round in 0..2 {
        c.send(serde_json::json!({"type": "set_constraints", "constraints": constraints()}))
            .await;
        let mut stages = Vec::new();
        loop {
            let WsMsg::Text(t) = c.next().await else {
                continue;
            };
            let v: serde_json::Value = serde_json::from_str(&t).expect("json");
            match v["type"].as_str() {
                Some("build_progress") => {
                    stages.push(v["stage"].as_str().expect("stage").to_owned())
                }
                Some("ready") => break,
                Some("error") => panic!("error event {v}"),
                _ => {}
            }
        }
        if round == 0 {
            assert_eq!(
                stages,
                ["assembly", "symbolic", "numeric"],
                "a build reports its stages in order"
            );
        } else {
            assert!(stages.is_empty(), "a cache hit builds nothing: {stages:?}");
        }
        assert_eq!(s.info().build_stage, None, "no stage once ready");
    }
}

#[test]
fn peer_events_are_sent_as_their_own_json() {
    let cases = [
        (
            PeerEvent::HandleGrabbed {
                handle: 1,
                client: 7,
            },
            serde_json::json!({"type": "handle_grabbed", "handle": 1, "client": 7}),
        ),
        (
            PeerEvent::HandleReleased {
                handle: 0,
                client: 2,
            },
            serde_json::json!({"type": "handle_released", "handle": 0, "client": 2}),
        ),
        (
            PeerEvent::PeerJoined { client: 3 },
            serde_json::json!({"type": "peer_joined", "client": 3}),
        ),
        (
            PeerEvent::PeerLeft { client: 4 },
            serde_json::json!({"type": "peer_left", "client": 4}),
        ),
    ];
    for (event, want) in cases {
        let msg = ServerMsg::Peer(event);
        assert_eq!(serde_json::to_value(&msg).unwrap(), want);
        assert_eq!(serde_json::from_value::<ServerMsg>(want).unwrap(), msg);
    }
}

/// With a window of one frame, the connection sends nothing more until the
/// client acknowledges the frame it has; then it sends the latest frame,
/// skipping the ones the session produced meanwhile. The frames are
/// version 3 in the encoding asked for, a settled one in f32.
#[tokio::test]
async fn a_window_of_one_holds_frames_until_acked_then_sends_the_latest() {
    let s = session();
    let _ = s
        .set_constraints(constraints(), None)
        .await
        .expect("constraints");
    while s.info().state != crate::session::SessionState::Ready {
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let mut c = connect_with(&s, true, 1000, StreamOptions::flow(1, FrameEncoding::Q16));
    let _ = c.event("state").await;
    // a frame of the current pose may come first: take it
    while let Ok(Some(m)) =
        tokio::time::timeout(Duration::from_millis(100), c.from_server.next()).await
    {
        if let WsMsg::Binary(b) = m {
            let h = decode_frame(&b).expect("frame").0;
            c.send(serde_json::json!({"type": "ack", "revision": h.revision}))
                .await;
        }
    }
    c.send(
        serde_json::json!({"type": "drag", "handle": 0, "translate": [0.0, 0.0, 0.3], "seq": 1}),
    )
    .await;
    let first = loop {
        if let WsMsg::Binary(b) = c.next().await {
            break decode_frame_full(&b).expect("a version 3 frame");
        }
    };
    // q16 while the pose moves; a settled frame goes out in f32
    let want = if first.header.settled {
        FrameEncoding::F32
    } else {
        FrameEncoding::Q16
    };
    assert_eq!((first.version, first.encoding), (3, want));
    // a second drag while the window is full: the session solves it and
    // settles, and none of its frames is sent
    c.send(
        serde_json::json!({"type": "drag", "handle": 0, "translate": [0.0, 0.4, 0.2], "seq": 2}),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(400)).await;
    while let Ok(m) = c.from_server.try_recv() {
        assert!(!matches!(m, WsMsg::Binary(_)), "a frame beyond the window");
    }
    assert!(
        s.info().revision > first.header.revision,
        "the session went on meanwhile"
    );
    c.send(serde_json::json!({"type": "ack", "revision": first.header.revision}))
        .await;
    let latest = loop {
        if let WsMsg::Binary(b) = c.next().await {
            let f = decode_frame_full(&b).expect("frame");
            assert_eq!(f.encoding, FrameEncoding::F32, "a settled frame is f32");
            break f.header;
        }
    };
    assert!(
        latest.settled && latest.ack_seq == 2,
        "the frame after the ack is the latest, settled one: {latest:?}"
    );
    assert!(latest.revision > first.header.revision);
    // and the window is full again until this one is acknowledged
    c.send(
        serde_json::json!({"type": "drag", "handle": 0, "translate": [0.0, 0.0, -0.2], "seq": 3}),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    while let Ok(m) = c.from_server.try_recv() {
        assert!(!matches!(m, WsMsg::Binary(_)), "a frame beyond the window");
    }
}
