//! Sessions outlive the process: choosing the store.
//!
//! At start-up [`open_store`] opens the configured store and lists its
//! sessions (logging how many, and failing on a corrupt one). Sessions are
//! re-opened lazily, by the first request naming one that is not live
//! (`registry/open.rs`).

use std::sync::Arc;

use crate::config::Config;
use crate::store::{MemoryStore, PgStore, SessionLog, SqliteStore, Store};

/// Opens the store `config` asks for (PostgreSQL with `store`, SQLite in
/// `data_dir`, or memory with `in_memory`) and reports the stored sessions
/// on stderr's log.
pub fn open_store(config: &Config) -> anyhow::Result<Arc<dyn Store>> {
    if let Some(url) = &config.store {
        return open_postgres(url, config.store_connections);
    }
    if config.in_memory {
        tracing::warn!("in-memory store: nothing survives a restart");
        return Ok(Arc::new(MemoryStore::new()));
    }
    let store = SqliteStore::open(&config.data_dir)?;
    let sessions = store.list_sessions()?;
    tracing::info!(path = %store.path().display(), sessions = sessions.len(), "opened the session store");
    Ok(Arc::new(store))
}

/// Opens the shared PostgreSQL store (migrating its schema) on a plain
/// thread: the blocking client must not run inside the async runtime.
fn open_postgres(url: &str, connections: u32) -> anyhow::Result<Arc<dyn Store>> {
    if !(url.starts_with("postgres://") || url.starts_with("postgresql://")) {
        anyhow::bail!("--store takes a postgres:// or postgresql:// URL");
    }
    let url = url.to_owned();
    let opened = std::thread::spawn(move || -> anyhow::Result<(PgStore, usize)> {
        let store = PgStore::open(&url, connections)?;
        let n = store.list_sessions()?.len();
        Ok((store, n))
    })
    .join()
    .map_err(|_| anyhow::anyhow!("opening the PostgreSQL store panicked"))?;
    let (store, sessions) = opened?;
    tracing::info!(sessions, "opened the shared PostgreSQL session store");
    Ok(Arc::new(store))
}
