//! Store calls off the async workers.

use std::sync::Arc;

use crate::error::ApiError;
use crate::store::{Store, StoreError};

/// Runs `f` on `store` from tokio's blocking pool: the SQLite and
/// PostgreSQL stores' calls block (a mutex and an fsync per write, a round
/// trip) and must not hold an async worker thread that other sessions'
/// requests and frames need.
pub(crate) async fn store_call<T, F>(store: &Arc<dyn Store>, f: F) -> Result<T, ApiError>
where
    F: FnOnce(&dyn Store) -> Result<T, StoreError> + Send + 'static,
    T: Send + 'static,
{
    let store = store.clone();
    tokio::task::spawn_blocking(move || f(&*store))
        .await
        .map_err(|e| ApiError::Internal(format!("store task: {e}")))?
        .map_err(ApiError::from)
}
