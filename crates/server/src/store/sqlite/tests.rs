use super::*;
use crate::store::codec::ENTRY_BYTES;
use crate::store::suite::{checkpoint, drag, grid, record};
use crate::store::types::NO_FENCE;

#[test]
fn newer_schema_is_refused() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().map_err(backend)?;
    drop(SqliteStore::open(dir.path())?);
    let conn = Connection::open(dir.path().join(DB_FILE)).map_err(backend)?;
    conn.pragma_update(None, "user_version", SCHEMA_VERSION + 1)
        .map_err(backend)?;
    drop(conn);
    assert!(matches!(
        SqliteStore::open(dir.path()),
        Err(StoreError::Corrupt { .. })
    ));
    Ok(())
}

#[test]
fn damaged_blobs_are_corrupt_errors() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().map_err(backend)?;
    let s = SqliteStore::open(dir.path())?;
    s.put_session(&record("a"))?;
    s.checkpoint("a", NO_FENCE, &checkpoint(1, 3))?;
    s.append("a", NO_FENCE, &[drag(1)])?;
    s.put_mesh("m", Arc::new(grid(2, 1.0)?))?;
    {
        let c = s.conn.lock();
        let _ = c
            .execute("UPDATE journal SET entry = x'0102'", [])
            .map_err(backend)?;
        let _ = c
            .execute("UPDATE checkpoints SET pose = x'00112233'", [])
            .map_err(backend)?;
        // a triangle index past the vertex count
        let _ = c
            .execute(
                "UPDATE meshes SET triangles = x'000000000100000063000000'",
                [],
            )
            .map_err(backend)?;
        let _ = c
            .execute("UPDATE sessions SET params = '{not json'", [])
            .map_err(backend)?;
    }
    assert!(matches!(s.journal("a"), Err(StoreError::Corrupt { .. })));
    assert!(matches!(
        s.get_checkpoint("a"),
        Err(StoreError::Corrupt { .. })
    ));
    assert!(matches!(s.get_mesh("m"), Err(StoreError::Corrupt { .. })));
    assert!(matches!(
        s.get_session("a"),
        Err(StoreError::Corrupt { .. })
    ));
    assert!(matches!(s.list_sessions(), Err(StoreError::Corrupt { .. })));
    Ok(())
}

#[test]
fn entry_decoder_rejects_every_bad_shape() {
    let good = encode_entry(&drag(3));
    assert_eq!(decode_entry(&good, "e").ok(), Some(drag(3)));
    for len in [0, 1, ENTRY_BYTES - 1, ENTRY_BYTES + 1] {
        let b: Vec<u8> = good
            .iter()
            .copied()
            .chain(std::iter::repeat(0))
            .take(len)
            .collect();
        assert!(
            matches!(decode_entry(&b, "e"), Err(StoreError::Corrupt { .. })),
            "len {len}"
        );
    }
    let mut tag = good.clone();
    tag[0] = 9;
    assert!(decode_entry(&tag, "e").is_err());
    let mut nan = good;
    nan[9..17].copy_from_slice(&f64::NAN.to_le_bytes());
    assert!(decode_entry(&nan, "e").is_err());
}

#[test]
fn a_version_1_database_is_migrated_to_leases() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().map_err(backend)?;
    {
        let conn = Connection::open(dir.path().join(DB_FILE)).map_err(backend)?;
        conn.execute_batch(SCHEMA).map_err(backend)?;
        conn.pragma_update(None, "user_version", 1)
            .map_err(backend)?;
    }
    let s = SqliteStore::open(dir.path())?;
    s.put_session(&record("a"))?;
    assert!(matches!(
        s.acquire_lease("a", "i1", std::time::Duration::from_secs(5))?,
        LeaseGrant::Granted { revision: 1, .. }
    ));
    let v: i64 = s
        .conn
        .lock()
        .query_row("PRAGMA user_version", [], |r| r.get(0))
        .map_err(backend)?;
    assert_eq!(v, SCHEMA_VERSION);
    Ok(())
}
