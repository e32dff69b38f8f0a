use super::*;
use crate::store::suite::{drag, fresh_pg_database, record};
use crate::store::types::NO_FENCE;

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

/// An owner frozen inside a fenced write (SIGSTOP after its `FOR SHARE` on
/// the lease row, before its commit) must not hold the lease forever: the
/// server ends its connection after IDLE_IN_TRANSACTION_TIMEOUT, another
/// instance's takeover goes through, and the frozen write fails when it
/// wakes instead of landing. Before the timeout was set, the takeover
/// waited on the row lock for as long as the owner stayed frozen (the
/// failover test's frozen-owner step hung on it).
#[test]
fn a_frozen_fenced_write_does_not_block_a_takeover() -> Result<(), StoreError> {
    let Some(cfg) = fresh_pg_database() else {
        return Ok(());
    };
    let a = PgStore::open_config(cfg.clone(), 2)?;
    let b = PgStore::open_config(cfg, 2)?;
    a.put_session(&record("s"))?;
    let ttl = Duration::from_millis(200);
    let LeaseGrant::Granted { revision, .. } = a.acquire_lease("s", "a", ttl)? else {
        panic!("a free lease is granted");
    };
    // instance a's write, frozen between its fence check and its commit
    let mut frozen = a.conn()?;
    let mut tx = frozen.transaction().map_err(pg_err)?;
    leases::check_fence(&mut tx, "s", revision)?;
    std::thread::sleep(ttl * 2); // the lease expires meanwhile
    let (done_tx, done) = std::sync::mpsc::channel();
    let taker = std::thread::spawn(move || {
        let _ = done_tx.send(b.acquire_lease("s", "b", Duration::from_secs(10)));
    });
    let waited = IDLE_IN_TRANSACTION_TIMEOUT + LOCK_TIMEOUT + Duration::from_secs(10);
    let grant = done
        .recv_timeout(waited)
        .expect("the takeover waited on the frozen write's row lock");
    let _ = taker.join();
    match grant? {
        LeaseGrant::Granted {
            revision: r,
            taken_over,
        } => assert!(taken_over && r > revision, "taken over: {r} > {revision}"),
        other => panic!("an expired lease is taken over, got {other:?}"),
    }
    // the frozen write wakes: its connection is gone, nothing lands
    let woke = tx.execute("SELECT 1", &[]).map_err(pg_err);
    assert!(
        matches!(woke, Err(StoreError::Unavailable(_))),
        "the frozen write's connection was ended: {woke:?}"
    );
    drop(tx);
    assert!(a.append("s", revision, &[drag(1)]).is_err(), "fenced");
    assert!(a.journal("s")?.is_empty());
    Ok(())
}
