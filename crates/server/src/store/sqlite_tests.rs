use super::*;

/// An `n`×`n` vertex grid of the unit square scaled by `h`, two triangles per cell.
fn grid(n: u32, h: f64) -> Result<Mesh, StoreError> {
    let positions = (0..n * n)
        .map(|k| [(k % n) as f64 * h / 3.0, (k / n) as f64 * h, 0.25])
        .collect();
    let mut triangles = vec![];
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i;
            triangles.push([a, a + 1, a + n + 1]);
            triangles.push([a, a + n + 1, a + n]);
        }
    }
    Mesh::new(positions, triangles).map_err(backend)
}

fn record(id: &str) -> SessionRecord {
    SessionRecord {
        id: id.into(),
        mesh_id: "m".into(),
        token_sha256: hex::encode([7u8; 32]),
        params: serde_json::json!({"alpha": 0.5}),
        constraints: None,
        created_unix: 1_700_000_000,
    }
}

fn drag(seq: u64) -> JournalEntry {
    JournalEntry::Drag {
        handle: seq as usize % 3,
        rotation: [0.1, -0.2, 0.3, (1.0f64 - 0.14).sqrt()],
        translation: [seq as f64 * 0.5, -1.0 / 3.0, 1e-300],
        seq,
    }
}

fn checkpoint(rev: u64, n: usize) -> Checkpoint {
    Checkpoint {
        revision: rev,
        ack_seq: rev * 10 + u64::MAX / 2,
        pose: (0..n)
            .map(|i| [i as f64 / 7.0, -(i as f64), std::f64::consts::PI])
            .collect(),
        targets: vec![StoredTransform {
            rotation: [0.0, 0.0, 0.6, 0.8],
            translation: [1.0, 2.0, 3.0],
            pivot: [0.1, 0.2, 0.3],
        }],
    }
}

#[test]
fn mesh_and_session_round_trip_bit_exact() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().map_err(backend)?;
    let s = SqliteStore::open(dir.path())?;
    let mesh = Arc::new(grid(5, 1.3)?);
    s.put_mesh("m", mesh.clone())?;
    let back = s.get_mesh("m")?.ok_or_else(|| backend("mesh missing"))?;
    assert_eq!(back.positions(), mesh.positions());
    assert_eq!(back.triangles(), mesh.triangles());
    assert_eq!(s.mesh_count()?, 1);
    assert!(s.get_mesh("nope")?.is_none());

    let mut r = record("a");
    s.put_session(&r)?;
    assert_eq!(s.get_session("a")?, Some(r.clone()));
    r.constraints = Some(serde_json::json!({"fixed": [0, 1]}));
    s.put_session(&r)?;
    assert_eq!(s.list_sessions()?, vec![r]);
    // a bad token hash is refused, never stored
    let mut bad = record("b");
    bad.token_sha256 = "secret-token".into();
    assert!(s.put_session(&bad).is_err());
    assert!(s.get_session("b")?.is_none());
    Ok(())
}

#[test]
fn journal_append_and_truncate_on_checkpoint() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().map_err(backend)?;
    let s = SqliteStore::open(dir.path())?;
    s.put_session(&record("a"))?;
    s.put_session(&record("b"))?;
    s.append("a", &[drag(1), drag(2)])?;
    s.append("b", &[drag(9)])?;
    s.append("a", &[drag(3)])?;
    assert_eq!(s.journal("a")?, vec![drag(1), drag(2), drag(3)]);
    assert_eq!(s.journal("b")?, vec![drag(9)]);
    let cp = checkpoint(4, 10);
    s.checkpoint("a", &cp)?;
    assert!(s.journal("a")?.is_empty());
    assert_eq!(
        s.journal("b")?,
        vec![drag(9)],
        "other sessions' journals are untouched"
    );
    assert_eq!(s.get_checkpoint("a")?, Some(cp));
    s.append("a", &[drag(5)])?;
    assert_eq!(s.journal("a")?, vec![drag(5)]);
    // re-putting the record (an upsert) keeps journal and checkpoint
    s.put_session(&record("a"))?;
    assert_eq!(s.journal("a")?, vec![drag(5)]);
    assert!(s.get_checkpoint("a")?.is_some());
    s.set_constraints("a", &serde_json::json!({"fixed": [2]}))?;
    assert!(s.journal("a")?.is_empty());
    assert!(s.get_checkpoint("a")?.is_none());
    assert_eq!(
        s.get_session("a")?.map(|r| r.constraints),
        Some(Some(serde_json::json!({"fixed": [2]})))
    );
    s.append("a", &[drag(6)])?;
    s.delete_session("a")?;
    assert!(s.get_session("a")?.is_none());
    assert!(s.journal("a")?.is_empty(), "delete cascades to the journal");
    assert!(s.append("a", &[drag(7)]).is_err());
    assert!(s.checkpoint("a", &checkpoint(1, 1)).is_err());
    assert!(s.set_constraints("a", &serde_json::json!({})).is_err());
    Ok(())
}

#[test]
fn everything_survives_reopen() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().map_err(backend)?;
    let mesh = Arc::new(grid(3, 1.0)?);
    {
        let s = SqliteStore::open(dir.path())?;
        s.put_mesh("m", mesh.clone())?;
        s.put_session(&record("a"))?;
        s.checkpoint("a", &checkpoint(2, 9))?;
        s.append("a", &[drag(1), drag(2)])?;
    }
    let s = SqliteStore::open(dir.path())?;
    assert_eq!(
        s.get_mesh("m")?.map(|m| m.positions().to_vec()),
        Some(mesh.positions().to_vec())
    );
    assert_eq!(s.list_sessions()?, vec![record("a")]);
    assert_eq!(s.get_checkpoint("a")?, Some(checkpoint(2, 9)));
    assert_eq!(s.journal("a")?, vec![drag(1), drag(2)]);
    s.integrity_check()?;
    Ok(())
}

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
    s.checkpoint("a", &checkpoint(1, 3))?;
    s.append("a", &[drag(1)])?;
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
fn concurrent_appends_from_threads_are_all_kept_in_order() -> Result<(), StoreError> {
    let dir = tempfile::tempdir().map_err(backend)?;
    let s = Arc::new(SqliteStore::open(dir.path())?);
    for t in 0..4 {
        s.put_session(&record(&format!("s{t}")))?;
    }
    let threads: Vec<_> = (0..8u64)
        .map(|t| {
            let s = s.clone();
            std::thread::spawn(move || -> Result<(), StoreError> {
                let id = format!("s{}", t % 4);
                for k in 0..25u64 {
                    s.append(&id, &[drag(t * 1000 + k)])?;
                    if k % 10 == 0 {
                        let _ = s.list_sessions()?;
                    }
                }
                Ok(())
            })
        })
        .collect();
    for t in threads {
        t.join().map_err(|_| backend("thread panicked"))??;
    }
    for i in 0..4u64 {
        let seqs: Vec<u64> = s
            .journal(&format!("s{i}"))?
            .into_iter()
            .map(|e| match e {
                JournalEntry::Drag { seq, .. } => seq,
            })
            .collect();
        assert_eq!(seqs.len(), 50);
        // each writer thread's entries appear in its own order
        for t in [i, i + 4] {
            let mine: Vec<u64> = seqs.iter().copied().filter(|q| q / 1000 == t).collect();
            assert_eq!(mine, (0..25).map(|k| t * 1000 + k).collect::<Vec<_>>());
        }
    }
    Ok(())
}
