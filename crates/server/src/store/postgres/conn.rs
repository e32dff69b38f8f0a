//! The PostgreSQL store's connections and how their errors are classified.

use postgres::NoTls;
use r2d2_postgres::PostgresConnectionManager;

use crate::store::types::StoreError;

/// A pooled connection.
pub(super) type Conn = r2d2::PooledConnection<PostgresConnectionManager<NoTls>>;

/// Classifies a client error: connection-level failures are
/// [`StoreError::Unavailable`] (retry later), the rest `Backend`.
pub(super) fn pg_err(e: postgres::Error) -> StoreError {
    let unavailable = e.is_closed()
        || std::error::Error::source(&e).is_some_and(|s| s.is::<std::io::Error>())
        || e.code().is_some_and(|c| {
            let c = c.code();
            // 08: connection exception; 57P0x: shutdown / cannot connect now;
            // 53: insufficient resources; 55P03: lock wait over
            // LOCK_TIMEOUT; 25P03: this connection idled in a transaction
            // past IDLE_IN_TRANSACTION_TIMEOUT and was ended
            c.starts_with("08")
                || c.starts_with("57P0")
                || c.starts_with("53")
                || c == "55P03"
                || c == "25P03"
        });
    if unavailable {
        StoreError::Unavailable(e.to_string())
    } else {
        StoreError::Backend(e.to_string())
    }
}
