//! An in-process server on port 0 and the grid the server tests edit.

use std::sync::Arc;

use dend_protocol::{ConstraintsSpec, HandleSpec};
use dend_server::store::{MemoryStore, Store};
use dend_server::{app, AppState, Config};

/// Starts a server on 127.0.0.1:0 with the in-memory store; returns its
/// base URL and state.
pub async fn start(config: Config) -> (String, AppState) {
    start_with_store(config, Arc::new(MemoryStore::new())).await
}

/// [`start`] on the given store.
pub async fn start_with_store(config: Config, store: Arc<dyn Store>) -> (String, AppState) {
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
    drop(tokio::spawn(async move {
        axum::serve(dend_server::no_delay(listener), router).await
    }));
    (format!("http://{addr}"), state)
}

/// The positions and triangles of [`crate::unit_grid`] (`n`×`n`, unit
/// spacing, z = 0), as uploaded.
pub fn grid(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let n = u32::try_from(n).expect("grid size fits u32");
    let m = crate::unit_grid(n);
    (m.positions().to_vec(), m.triangles().to_vec())
}

/// Constraints on an n×n grid: bottom row fixed, top row the handle `top`.
pub fn grid_constraints(n: usize) -> ConstraintsSpec {
    let n = n as u64;
    let bottom: Vec<u64> = (0..n).collect();
    let top: Vec<u64> = (n * (n - 1)..n * n).collect();
    ConstraintsSpec::new(bottom.into(), vec![HandleSpec::named("top", top.into())])
}
