//! The SQLite store's shared transaction helpers.

use rusqlite::{Connection, OptionalExtension, Transaction, TransactionBehavior};

use super::leases;
use crate::store::types::{Fence, StoreError};

pub(super) fn backend(e: impl std::fmt::Display) -> StoreError {
    StoreError::Backend(e.to_string())
}

pub(super) fn missing(id: &str) -> StoreError {
    StoreError::Missing(id.to_string())
}

/// An immediate (write-locked) transaction on session `id`'s rows, after
/// checking that the session exists and that `fence` still holds its lease.
pub(super) fn fenced<'c>(
    conn: &'c mut Connection,
    id: &str,
    fence: Fence,
) -> Result<Transaction<'c>, StoreError> {
    let tx = conn
        .transaction_with_behavior(TransactionBehavior::Immediate)
        .map_err(backend)?;
    if !session_exists(&tx, id)? {
        return Err(missing(id));
    }
    leases::check_fence(&tx, id, fence)?;
    Ok(tx)
}

pub(super) fn session_exists(conn: &Connection, id: &str) -> Result<bool, StoreError> {
    conn.query_row("SELECT 1 FROM sessions WHERE id = ?1", [id], |_| Ok(()))
        .optional()
        .map(|o| o.is_some())
        .map_err(backend)
}
