use super::*;
use crate::store::suite::{drag, fresh_pg_database, record};
use crate::store::NO_FENCE;

#[test]
fn an_unreachable_server_is_unavailable_not_a_panic() {
    // a loopback port nothing listens on (bound, then released)
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap_or(1);
    let t0 = std::time::Instant::now();
    let r = PgStore::open(&format!("postgres://dend@127.0.0.1:{port}/dend"), 2);
    assert!(
        matches!(r, Err(StoreError::Unavailable(_))),
        "{:?}",
        r.err()
    );
    assert!(t0.elapsed() < Duration::from_secs(20), "fails fast");
    assert!(matches!(
        PgStore::open("mysql://nope", 2),
        Err(StoreError::Backend(_))
    ));
}

#[test]
fn migrations_apply_once_and_a_newer_schema_is_refused() -> Result<(), StoreError> {
    let Some(cfg) = fresh_pg_database() else {
        return Ok(());
    };
    let s = PgStore::open_config(cfg.clone(), 2)?;
    assert_eq!(s.schema_version()?, PG_SCHEMA_VERSION);
    s.put_session(&record("a"))?;
    s.append("a", NO_FENCE, &[drag(1)])?;
    drop(s);
    // re-opening applies nothing twice and keeps the data
    let s = PgStore::open_config(cfg.clone(), 2)?;
    assert_eq!(s.schema_version()?, PG_SCHEMA_VERSION);
    assert_eq!(s.journal("a")?, vec![drag(1)]);
    s.execute_batch(&format!(
        "INSERT INTO dend_schema_migrations (version) VALUES ({})",
        PG_SCHEMA_VERSION + 1
    ))?;
    drop(s);
    assert!(matches!(
        PgStore::open_config(cfg, 2),
        Err(StoreError::Corrupt { .. })
    ));
    Ok(())
}

#[test]
fn damaged_rows_are_corrupt_errors() -> Result<(), StoreError> {
    let Some(cfg) = fresh_pg_database() else {
        return Ok(());
    };
    let s = PgStore::open_config(cfg, 2)?;
    s.put_session(&record("a"))?;
    s.append("a", NO_FENCE, &[drag(1)])?;
    s.execute_batch(
        "UPDATE journal SET entry = '\\x0102'::bytea; UPDATE sessions SET params = '{not json'",
    )?;
    assert!(matches!(s.journal("a"), Err(StoreError::Corrupt { .. })));
    assert!(matches!(
        s.get_session("a"),
        Err(StoreError::Corrupt { .. })
    ));
    Ok(())
}
