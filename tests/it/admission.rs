//! Admission control (docs/deployment.md "Fair scheduling and
//! admission control"): while the configured number of sessions wait for a
//! solver worker, a new session is refused with 503 `overloaded` and a
//! `Retry-After`, counted in `dend_sessions_refused_total`; once the queue
//! drains, sessions are created again. The load is made exact by holding
//! the only solver worker busy from the test (no clock involved).

use std::sync::mpsc;
use std::time::Duration;

use dend_client::ws::CreateSession;
use dend_client::{Client, SessionParams};
use dend_server::{app, AppState, Config};
use dend_testkit::server::grid;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn new_sessions_get_503_overloaded_with_retry_after_while_solvers_are_saturated() {
    let config = Config {
        addr: ([127, 0, 0, 1], 0).into(),
        solver_threads: 1,
        admission_waiting_sessions: 2,
        ..Config::default()
    };
    let listener = tokio::net::TcpListener::bind(config.addr)
        .await
        .expect("bind");
    let url = format!("http://{}", listener.local_addr().expect("addr"));
    let state = AppState::new(config).expect("state");
    let scheduler = state.scheduler.clone();
    let router = app(state);
    drop(tokio::spawn(async move {
        axum::serve(dend_server::no_delay(listener), router).await
    }));
    let c = Client::new(&url);
    let (p, t) = grid(4);
    let mesh = c.upload_json(&p, &t).await.expect("upload");
    // the one worker busy, two other sessions' solves waiting
    let (release, gate) = mpsc::channel::<()>();
    let (started_tx, started) = mpsc::channel::<()>();
    scheduler.submit("busy", move || {
        let _ = started_tx.send(());
        let _ = gate.recv_timeout(Duration::from_secs(60));
    });
    started
        .recv_timeout(Duration::from_secs(30))
        .expect("the worker runs the busy job");
    scheduler.submit("waiting-1", || {});
    scheduler.submit("waiting-2", || {});
    assert_eq!(scheduler.waiting(), 2);
    let r = reqwest::Client::new()
        .post(format!("{url}/v1/sessions"))
        .json(&CreateSession {
            mesh_id: mesh.id.clone(),
            params: SessionParams::default(),
        })
        .send()
        .await
        .expect("post");
    assert_eq!(r.status().as_u16(), 503);
    assert_eq!(
        r.headers().get("retry-after").and_then(|v| v.to_str().ok()),
        Some("2")
    );
    let body: serde_json::Value = r.json().await.expect("json");
    assert_eq!(body["code"], "overloaded", "{body}");
    assert_eq!(
        c.metric("dend_sessions_refused_total")
            .await
            .expect("metric"),
        Some(1.0)
    );
    // the queue drains: admitted again
    release.send(()).expect("release");
    let t0 = std::time::Instant::now();
    while scheduler.waiting() > 0 {
        assert!(t0.elapsed() < Duration::from_secs(30), "the queue drains");
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let s = c
        .create_session(&mesh.id, SessionParams::default())
        .await
        .expect("admitted once the solvers have room");
    assert!(!s.id.is_empty());
    assert!(
        c.metric("dend_solve_schedule_delay_seconds_count")
            .await
            .expect("metric")
            .is_some_and(|n| n >= 3.0),
        "the scheduler reports each solve's wait"
    );
}
