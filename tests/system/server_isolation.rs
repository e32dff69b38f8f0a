//! Isolation between sessions and hostile input, over real sockets: a
//! token opens its own session only (HTTP and WebSocket); ids and tokens
//! are 128+ random bits; deeply nested JSON, huge index lists, NaN/inf in
//! every numeric field, message floods, clients that never read and many
//! connections each get a bounded, typed answer.

use std::collections::HashSet;
use std::time::Duration;

use dend_client::ws::{ClientMsg, DeltaJson, DragRequest, ServerMsg, SessionState};
use dend_client::{Client, ClientError, WsEvent};
use dend_client::{ConstraintsSpec, ErrorBody, ErrorCode, HandleSpec, SessionParams, VertexSet};
use dend_server::Config;
use dend_testkit::server::{grid, grid_constraints, start};
use futures_util::{SinkExt, StreamExt};
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

type Res = Result<(), ClientError>;

/// The tests of this file run one at a time: the flood test measures the
/// process's resident memory, which another test's large request bodies
/// (hostile_json_gets_typed_4xx) would otherwise inflate.
static SERIAL: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// The status and code of an answer (an unreadable body's code is
/// `Other("")`, which no check below accepts).
async fn code_of(r: reqwest::Response) -> (u16, ErrorCode) {
    let status = r.status().as_u16();
    let body: Option<ErrorBody> = r.json().await.ok();
    (
        status,
        body.map_or(ErrorCode::Other(String::new()), |b| b.code),
    )
}

#[tokio::test]
async fn a_token_opens_its_own_session_only() -> Res {
    let _serial = SERIAL.lock().await;
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let (p, t) = grid(5);
    let mesh = c.upload_json(&p, &t).await?;
    let a = c.create_session(&mesh.id, SessionParams::default()).await?;
    let b = c.create_session(&mesh.id, SessionParams::default()).await?;
    b.set_constraints(&grid_constraints(5)).await?;
    b.wait_ready(Duration::from_secs(60)).await?;
    let http = reqwest::Client::new();
    let url = |tail: &str| format!("{base}/v1/sessions/{}{tail}", b.id);
    let drag = DragRequest {
        handle: 0.into(),
        delta: DeltaJson::translate([0.0, 0.0, 1.0]),
        max_iters: None,
    };
    let attempts = [
        http.get(url("")),
        http.get(url("/pose")),
        http.get(url("/export?format=obj")),
        http.post(url("/drag")).json(&drag),
        http.put(url("/constraints")).json(&grid_constraints(5)),
        http.post(url("/undo")),
        http.post(url("/reset")),
        http.delete(url("")),
    ];
    for rq in attempts {
        let (status, code) = code_of(rq.bearer_auth(&a.token).send().await?).await;
        assert_eq!((status, code), (403, ErrorCode::Forbidden));
    }
    // B is untouched: still ready, still at revision of its own making
    assert_eq!(b.info().await?.state, SessionState::Ready);
    // WebSocket with A's token: 403 before the upgrade (query), close 4003 (auth message)
    let ws_url = url("/ws").replacen("http", "ws", 1);
    match tokio_tungstenite::connect_async(format!("{ws_url}?token={}", a.token)).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(resp)) => assert_eq!(resp.status(), 403),
        other => panic!("expected 403, got {:?}", other.map(|_| ())),
    }
    let (mut ws, _) = tokio_tungstenite::connect_async(&ws_url)
        .await
        .map_err(Box::new)?;
    ws.send(Message::Text(
        serde_json::to_string(&ClientMsg::Auth {
            token: a.token.clone(),
        })
        .expect("json")
        .into(),
    ))
    .await
    .map_err(Box::new)?;
    let mut close = None;
    while let Some(Ok(m)) = ws.next().await {
        match m {
            Message::Close(f) => {
                close = f.map(|f| u16::from(f.code));
                break;
            }
            Message::Binary(_) => panic!("a pose frame of B reached A's token"),
            _ => {}
        }
    }
    assert_eq!(close, Some(4003));
    // A's own token works on A
    assert_eq!(a.info().await?.id, a.id);
    Ok(())
}

#[tokio::test]
async fn ids_and_tokens_are_random_128_bit_or_more() -> Res {
    let _serial = SERIAL.lock().await;
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let (p, t) = grid(3);
    let mesh = c.upload_json(&p, &t).await?;
    let (mut ids, mut tokens, mut prefixes) = (HashSet::new(), HashSet::new(), HashSet::new());
    for _ in 0..40 {
        let s = c.create_session(&mesh.id, SessionParams::default()).await?;
        assert!(
            s.id.len() >= 32 && s.id.chars().all(|ch| ch.is_ascii_hexdigit()),
            "id {}",
            s.id
        );
        assert!(s.token.len() >= 32 && s.token.chars().all(|ch| ch.is_ascii_hexdigit()));
        assert!(
            prefixes.insert(s.id[..8].to_owned()),
            "ids share a 32-bit prefix: not random"
        );
        assert!(ids.insert(s.id.clone()) && tokens.insert(s.token.clone()));
        assert!(!s.token.contains(&s.id) && !s.id.contains(&s.token[..8]));
        s.delete().await?;
    }
    Ok(())
}

#[tokio::test]
async fn hostile_json_gets_typed_4xx() -> Res {
    let _serial = SERIAL.lock().await;
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let n = 6;
    let (p, t) = grid(n);
    let mesh = c.upload_json(&p, &t).await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    s.set_constraints(&grid_constraints(n)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let http = reqwest::Client::new();
    let send = |m: reqwest::Method, tail: &str, body: String| {
        http.request(m, format!("{base}/v1/sessions/{}{tail}", s.id))
            .bearer_auth(&s.token)
            .header("content-type", "application/json")
            .body(body)
            .send()
    };
    // deeply nested JSON, as a whole body and inside a field
    let deep = format!("{}{}", "[".repeat(100_000), "]".repeat(100_000));
    for (m, tail) in [
        (reqwest::Method::PUT, "/constraints"),
        (reqwest::Method::POST, "/drag"),
    ] {
        let (status, code) = code_of(send(m.clone(), tail, deep.clone()).await?).await;
        assert_eq!((status, code), (400, ErrorCode::InvalidJson), "{tail}");
    }
    let nested_field = format!(r#"{{"handle": 0, "translate": {deep}}}"#);
    assert_eq!(
        code_of(send(reqwest::Method::POST, "/drag", nested_field).await?)
            .await
            .0,
        400
    );
    let r = http
        .post(format!("{base}/v1/meshes"))
        .header("content-type", "application/json")
        .body(format!(r#"{{"positions": {deep}, "triangles": []}}"#))
        .send()
        .await?;
    assert_eq!(code_of(r).await.0, 400);

    // huge index lists: a million out-of-range indices, u64::MAX, and a million duplicates
    let huge: Vec<u64> = (0..1_000_000).collect();
    let one = |fixed: Vec<u64>, handle: u64| {
        let spec = ConstraintsSpec::new(
            VertexSet::Indices(fixed),
            vec![HandleSpec::named("h", VertexSet::Indices(vec![handle]))],
        );
        serde_json::to_string(&spec).expect("json")
    };
    let body = one(huge, (n * n - 1) as u64);
    let (status, code) = code_of(send(reqwest::Method::PUT, "/constraints", body).await?).await;
    assert_eq!(status, 422, "{code}");
    let body = one(vec![u64::MAX], 0);
    assert_eq!(
        code_of(send(reqwest::Method::PUT, "/constraints", body).await?)
            .await
            .0,
        422
    );
    let dup = vec![0u64; 1_000_000];
    let body = one(dup, (n * n - 1) as u64);
    let status = send(reqwest::Method::PUT, "/constraints", body)
        .await?
        .status()
        .as_u16();
    assert!(status == 202 || status == 422, "duplicates: {status}");

    // NaN / ±inf / null / out-of-range literals in every numeric field
    let bads = ["NaN", "Infinity", "-Infinity", "null", "1e999"];
    let drag_templates = [
        r#"{"handle": 0, "translate": [X, 0, 0]}"#,
        r#"{"handle": 0, "translate": [0, X, 0]}"#,
        r#"{"handle": 0, "translate": [0, 0, X]}"#,
        r#"{"handle": 0, "rotate": {"axis": [X, 0, 1], "degrees": 5}}"#,
        r#"{"handle": 0, "rotate": {"axis": [0, X, 1], "degrees": 5}}"#,
        r#"{"handle": 0, "rotate": {"axis": [1, 0, X], "degrees": 5}}"#,
        r#"{"handle": 0, "rotate": {"axis": [0, 0, 1], "degrees": X}}"#,
        r#"{"handle": 0, "quaternion": [X, 0, 0, 1]}"#,
        r#"{"handle": 0, "quaternion": [0, X, 0, 1]}"#,
        r#"{"handle": 0, "quaternion": [0, 0, X, 1]}"#,
        r#"{"handle": 0, "quaternion": [0, 0, 0, X]}"#,
        r#"{"handle": X, "translate": [0, 0, 1]}"#,
        r#"{"handle": 0, "translate": [0, 0, 1], "max_iters": X}"#,
    ];
    for tpl in drag_templates {
        for x in bads {
            if x == "null" && tpl.contains("max_iters") {
                continue; // null = the default budget: a valid drag
            }
            let (status, code) =
                code_of(send(reqwest::Method::POST, "/drag", tpl.replace('X', x)).await?).await;
            assert!(
                (400..500).contains(&status) && !matches!(code, ErrorCode::Other(_)),
                "{tpl} with {x}: {status} {code}"
            );
        }
    }
    let constraint_templates = [
        r#"{"fixed": {"box": {"min": [X, -1, -1], "max": [9, 0.5, 1]}}, "handles": [{"name": "h", "vertices": [30]}]}"#,
        r#"{"fixed": {"box": {"min": [-1, -1, -1], "max": [9, X, 1]}}, "handles": [{"name": "h", "vertices": [30]}]}"#,
        r#"{"fixed": {"sphere": {"center": [0, X, 0], "radius": 1}}, "handles": [{"name": "h", "vertices": [30]}]}"#,
        r#"{"fixed": {"sphere": {"center": [0, 0, 0], "radius": X}}, "handles": [{"name": "h", "vertices": [30]}]}"#,
        r#"{"fixed": [0, 1], "handles": [{"name": "h", "vertices": [30], "translate": [0, X, 0]}]}"#,
        r#"{"fixed": [0, 1], "handles": [{"name": "h", "vertices": [30], "pivot": [X, 0, 0]}]}"#,
        r#"{"fixed": [0, 1], "handles": [{"name": "h", "vertices": [30], "positions": [[0, 0, X]]}]}"#,
        r#"{"fixed": [0, X], "handles": [{"name": "h", "vertices": [30]}]}"#,
    ];
    for tpl in constraint_templates {
        for x in bads {
            let (status, code) =
                code_of(send(reqwest::Method::PUT, "/constraints", tpl.replace('X', x)).await?)
                    .await;
            assert!(
                (400..500).contains(&status) && !matches!(code, ErrorCode::Other(_)),
                "{tpl} with {x}: {status} {code}"
            );
        }
    }
    for field in ["tol", "lambda1", "lambda2", "max_iters", "anderson"] {
        for x in bads {
            let body = format!(
                r#"{{"mesh_id": "{}", "params": {{"{field}": {x}}}}}"#,
                mesh.id
            );
            let r = http
                .post(format!("{base}/v1/sessions"))
                .header("content-type", "application/json")
                .body(body)
                .send()
                .await?;
            let (status, code) = code_of(r).await;
            assert!(
                (400..500).contains(&status) && !matches!(code, ErrorCode::Other(_)),
                "params.{field} = {x}: {status} {code}"
            );
        }
    }
    // the session survived all of it
    s.wait_ready(Duration::from_secs(60)).await?;
    let pose = s.pose().await?;
    assert!(pose.positions.iter().flatten().all(|x| x.is_finite()));
    Ok(())
}

/// Resident set size of this process in bytes (Linux), if known.
fn rss() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: u64 = s.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096)
}

#[tokio::test]
async fn floods_slow_readers_and_many_connections_stay_bounded() -> Res {
    let _serial = SERIAL.lock().await;
    let config = Config {
        ws_max_messages_per_sec: 50,
        ..Config::default()
    };
    let (base, _state) = start(config).await;
    let c = Client::new(&base);
    let n = 20;
    let (p, t) = grid(n);
    let mesh = c.upload_json(&p, &t).await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    s.set_constraints(&grid_constraints(n)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;

    // a flood of 1000 messages: the excess gets `rate_limited` error events
    let mut ws = s.connect().await?;
    for i in 0..1000 {
        ws.send(&ClientMsg::Ping {
            nonce: Some(json!(i)),
        })
        .await?;
    }
    let (mut pongs, mut limited) = (0, 0);
    while pongs + limited < 1000 {
        match tokio::time::timeout(Duration::from_secs(20), ws.next())
            .await
            .map_err(|_| ClientError::Protocol("flood answers stalled".into()))??
        {
            WsEvent::Event(ServerMsg::Pong { .. }) => pongs += 1,
            WsEvent::Event(ServerMsg::Error { code, .. }) => {
                assert_eq!(code, ErrorCode::RateLimited);
                limited += 1;
            }
            WsEvent::Closed(code) => panic!("closed {code:?}"),
            _ => {}
        }
    }
    assert!(
        limited > 0 && pongs >= 50,
        "pongs {pongs}, rate limited {limited}"
    );
    drop(ws);

    // slow clients: 20 connections that drag but never read a frame
    let before = rss();
    let mut slow = vec![];
    for _ in 0..20 {
        slow.push(s.connect().await?);
    }
    for (k, w) in slow.iter_mut().enumerate() {
        for seq in 1..=40u64 {
            let _ = tokio::time::timeout(
                Duration::from_secs(2),
                w.drag(0, [0.0, 0.0, 1e-3 * k as f64], None, seq),
            )
            .await;
        }
    }
    // many idle connections
    let mut idle = vec![];
    for _ in 0..200 {
        idle.push(s.connect().await?);
    }
    tokio::time::sleep(Duration::from_millis(500)).await;
    // the server still answers promptly, and memory did not balloon
    tokio::time::timeout(Duration::from_secs(10), c.healthz())
        .await
        .map_err(|_| ClientError::Protocol("healthz stalled".into()))??;
    let pose = s.pose().await?;
    assert!(pose.positions.iter().flatten().all(|x| x.is_finite()));
    if let (Some(b), Some(a)) = (before, rss()) {
        // 220 connections × (64 KiB message limit + socket buffers) stays far below this
        assert!(
            a < b + (200 << 20),
            "RSS grew by {} bytes",
            a.saturating_sub(b)
        );
    }
    let peers = s.info().await?.peers;
    assert!(peers >= 220, "{peers} peers");
    Ok(())
}
