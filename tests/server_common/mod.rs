//! Shared helpers of the server tests: an in-process server on port 0 and
//! a generated grid mesh.
#![allow(dead_code)]

use dend_server::{app, AppState, Config};

/// Starts a server on 127.0.0.1:0 with the in-memory store; returns its
/// base URL and state.
pub async fn start(config: Config) -> (String, AppState) {
    start_with_store(
        config,
        std::sync::Arc::new(dend_server::store::MemoryStore::new()),
    )
    .await
}

/// [`start`] on the given store.
pub async fn start_with_store(
    config: Config,
    store: std::sync::Arc<dyn dend_server::store::Store>,
) -> (String, AppState) {
    let config = Config {
        addr: ([127, 0, 0, 1], 0).into(),
        ..config
    };
    let listener = tokio::net::TcpListener::bind(config.addr)
        .await
        .expect("bind");
    let addr = listener.local_addr().expect("addr");
    let state = AppState::with_store(config, store).expect("state");
    let router = app(state.clone());
    drop(tokio::spawn(
        async move { axum::serve(listener, router).await },
    ));
    (format!("http://{addr}"), state)
}

/// An n×n grid of unit spacing in the z = 0 plane.
pub fn grid(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut p = vec![];
    for j in 0..n {
        for i in 0..n {
            p.push([i as f64, j as f64, 0.0]);
        }
    }
    let mut t = vec![];
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
            t.push([a, b, d]);
            t.push([a, d, c]);
        }
    }
    (p, t)
}

/// Constraints on an n×n grid: bottom row fixed, top row the handle `top`.
pub fn grid_constraints(n: usize) -> serde_json::Value {
    let bottom: Vec<usize> = (0..n).collect();
    let top: Vec<usize> = (n * (n - 1)..n * n).collect();
    serde_json::json!({"fixed": bottom, "handles": [{"name": "top", "vertices": top}]})
}
