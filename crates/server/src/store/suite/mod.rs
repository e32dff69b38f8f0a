//! The one store test suite, run against every backend: [`MemoryStore`],
//! [`SqliteStore`] and [`PgStore`]. Each case takes a [`Backend`] (a fresh,
//! empty store and, for the durable ones, a way to re-open it).
//!
//! PostgreSQL: `DEND_TEST_POSTGRES` names a server (`postgres://user@host:port/db`
//! of a role that may create databases; `scripts/test.sh` starts a
//! throw-away one); each test gets a database of its own. Without it the
//! PostgreSQL cases are skipped with a line in `$DEND_SKIP_LOG`, and fail
//! under `CI=true`.

mod poses;

use std::sync::Arc;
use std::time::Duration;

use super::*;
use dend::mesh::Mesh;

use poses::named_poses_round_trip;

/// Re-opens a durable backend's storage.
type Reopen = Box<dyn Fn() -> Result<Arc<dyn Store>, StoreError>>;

/// A store under test.
pub(super) struct Backend {
    pub store: Arc<dyn Store>,
    /// Re-opens the same storage (durable backends).
    pub reopen: Option<Reopen>,
    _dir: Option<tempfile::TempDir>,
}

fn backend_err(e: impl std::fmt::Display) -> StoreError {
    StoreError::Backend(e.to_string())
}

pub(super) fn memory() -> Option<Backend> {
    Some(Backend {
        store: Arc::new(MemoryStore::new()),
        reopen: None,
        _dir: None,
    })
}

pub(super) fn sqlite() -> Option<Backend> {
    let dir = tempfile::tempdir().ok()?;
    let path = dir.path().to_owned();
    let store = SqliteStore::open(&path).ok()?;
    Some(Backend {
        store: Arc::new(store),
        reopen: Some(Box::new(move || Ok(Arc::new(SqliteStore::open(&path)?)))),
        _dir: Some(dir),
    })
}

/// A client configuration for a new, empty database on the test server.
pub(super) fn fresh_pg_database() -> Option<::postgres::Config> {
    let Ok(url) = std::env::var("DEND_TEST_POSTGRES") else {
        let why = "DEND_TEST_POSTGRES is not set (scripts/test.sh starts a PostgreSQL for it)";
        assert!(
            !dend_testkit::under_ci(),
            "{why}; CI must run the PostgreSQL store tests"
        );
        dend_testkit::record_skip(why);
        return None;
    };
    let admin: ::postgres::Config = url.parse().expect("DEND_TEST_POSTGRES is a PostgreSQL URL");
    let name = format!("dend_test_{}", hex::encode(rand::random::<[u8; 6]>()));
    let mut client = admin
        .connect(::postgres::NoTls)
        .expect("DEND_TEST_POSTGRES accepts connections");
    client
        .batch_execute(&format!("CREATE DATABASE {name}"))
        .expect("the test role may create databases");
    let mut cfg = admin;
    let _ = cfg.dbname(&name);
    Some(cfg)
}

pub(super) fn postgres() -> Option<Backend> {
    let cfg = fresh_pg_database()?;
    let store = PgStore::open_config(cfg.clone(), 4).expect("open the test database");
    Some(Backend {
        store: Arc::new(store),
        reopen: Some(Box::new(move || {
            Ok(Arc::new(PgStore::open_config(cfg.clone(), 4)?))
        })),
        _dir: None,
    })
}

/// An `n`×`n` vertex grid of the unit square scaled by `h`, two triangles per cell.
pub(super) fn grid(n: u32, h: f64) -> Result<Mesh, StoreError> {
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
    Mesh::new(positions, triangles).map_err(backend_err)
}

pub(super) fn record(id: &str) -> SessionRecord {
    SessionRecord {
        id: id.into(),
        mesh_id: "m".into(),
        token_sha256: hex::encode([7u8; 32]),
        params: serde_json::json!({"alpha": 0.5}),
        constraints: None,
        created_unix: 1_700_000_000,
    }
}

pub(super) fn drag(seq: u64) -> JournalEntry {
    JournalEntry::Drag {
        handle: seq as usize % 3,
        rotation: [0.1, -0.2, 0.3, (1.0f64 - 0.14).sqrt()],
        translation: [seq as f64 * 0.5, -1.0 / 3.0, 1e-300],
        seq,
    }
}

pub(super) fn checkpoint(rev: u64, n: usize) -> Checkpoint {
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

pub(super) fn mesh_and_session_round_trip(b: Backend) -> Result<(), StoreError> {
    let s = &*b.store;
    let mesh = Arc::new(grid(5, 1.3)?);
    s.put_mesh("m", mesh.clone())?;
    let back = s
        .get_mesh("m")?
        .ok_or_else(|| backend_err("mesh missing"))?;
    assert_eq!(back.positions(), mesh.positions(), "bit-exact positions");
    assert_eq!(back.triangles(), mesh.triangles());
    assert_eq!(s.mesh_count()?, 1);
    assert!(s.get_mesh("nope")?.is_none());
    let asset = StoredAsset {
        format: "obj".into(),
        bytes: vec![0, 1, 2, 255],
    };
    s.put_asset("m", &asset)?;
    assert_eq!(s.get_asset("m")?, Some(asset));
    assert!(s.delete_mesh("m")?);
    assert!(!s.delete_mesh("m")?);
    assert!(s.get_asset("m")?.is_none());
    assert_eq!(s.mesh_count()?, 0);

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

pub(super) fn journal_append_and_truncate_on_checkpoint(b: Backend) -> Result<(), StoreError> {
    let s = &*b.store;
    s.put_session(&record("a"))?;
    s.put_session(&record("b"))?;
    s.append("a", NO_FENCE, &[drag(1), drag(2)])?;
    s.append("b", NO_FENCE, &[drag(9)])?;
    s.append("a", NO_FENCE, &[drag(3)])?;
    assert_eq!(s.journal("a")?, vec![drag(1), drag(2), drag(3)]);
    assert_eq!(s.journal("b")?, vec![drag(9)]);
    let cp = checkpoint(4, 10);
    s.checkpoint("a", NO_FENCE, &cp)?;
    assert!(s.journal("a")?.is_empty());
    assert_eq!(s.journal("b")?, vec![drag(9)], "other journals untouched");
    assert_eq!(s.get_checkpoint("a")?, Some(cp));
    s.append("a", NO_FENCE, &[drag(5)])?;
    assert_eq!(s.journal("a")?, vec![drag(5)]);
    // re-putting the record (an upsert) keeps journal and checkpoint
    s.put_session(&record("a"))?;
    assert_eq!(s.journal("a")?, vec![drag(5)]);
    assert!(s.get_checkpoint("a")?.is_some());
    s.set_constraints("a", NO_FENCE, &serde_json::json!({"fixed": [2]}))?;
    assert!(s.journal("a")?.is_empty());
    assert!(s.get_checkpoint("a")?.is_none());
    assert_eq!(
        s.get_session("a")?.map(|r| r.constraints),
        Some(Some(serde_json::json!({"fixed": [2]})))
    );
    s.append("a", NO_FENCE, &[drag(6)])?;
    s.delete_session("a")?;
    assert!(s.get_session("a")?.is_none());
    assert!(s.journal("a")?.is_empty(), "delete takes the journal");
    assert!(s.append("a", NO_FENCE, &[drag(7)]).is_err());
    assert!(s.checkpoint("a", NO_FENCE, &checkpoint(1, 1)).is_err());
    assert!(s
        .set_constraints("a", NO_FENCE, &serde_json::json!({}))
        .is_err());
    Ok(())
}

pub(super) fn concurrent_appends_are_all_kept_in_order(b: Backend) -> Result<(), StoreError> {
    let s = b.store.clone();
    for t in 0..4 {
        s.put_session(&record(&format!("s{t}")))?;
    }
    let threads: Vec<_> = (0..8u64)
        .map(|t| {
            let s = s.clone();
            std::thread::spawn(move || -> Result<(), StoreError> {
                let id = format!("s{}", t % 4);
                for k in 0..25u64 {
                    s.append(&id, NO_FENCE, &[drag(t * 1000 + k)])?;
                    if k % 10 == 0 {
                        let _ = s.list_sessions()?;
                    }
                }
                Ok(())
            })
        })
        .collect();
    for t in threads {
        t.join().map_err(|_| backend_err("thread panicked"))??;
    }
    for i in 0..4u64 {
        let seqs: Vec<u64> = s
            .journal(&format!("s{i}"))?
            .into_iter()
            .map(|JournalEntry::Drag { seq, .. }| seq)
            .collect();
        assert_eq!(seqs.len(), 50);
        for t in [i, i + 4] {
            let mine: Vec<u64> = seqs.iter().copied().filter(|q| q / 1000 == t).collect();
            assert_eq!(mine, (0..25).map(|k| t * 1000 + k).collect::<Vec<_>>());
        }
    }
    Ok(())
}

fn fenced(r: Result<(), StoreError>, want_current: Option<Fence>) -> bool {
    matches!(r, Err(StoreError::Fenced { current, .. }) if current == want_current)
}

pub(super) fn leases_hold_expire_and_fence(b: Backend) -> Result<(), StoreError> {
    let s = &*b.store;
    let ttl = Duration::from_millis(400);
    s.put_session(&record("a"))?;
    let g = s.acquire_lease("a", "i1", ttl)?;
    assert_eq!(
        g,
        LeaseGrant::Granted {
            revision: 1,
            taken_over: false
        }
    );
    match s.acquire_lease("a", "i2", ttl)? {
        LeaseGrant::HeldBy {
            owner,
            expires_in_ms,
        } => {
            assert_eq!(owner, "i1");
            assert!(expires_in_ms <= 400, "{expires_in_ms}");
        }
        other => panic!("i2 got {other:?} while i1 holds the lease"),
    }
    s.append("a", 1, &[drag(1)])?;
    assert!(fenced(s.append("a", 2, &[drag(2)]), Some(1)));
    assert_eq!(
        s.renew_leases("i1", &[("a".into(), 1)], ttl)?,
        Vec::<String>::new()
    );
    assert_eq!(s.renew_leases("i2", &[("a".into(), 1)], ttl)?, vec!["a"]);
    std::thread::sleep(Duration::from_millis(550));
    // expired: i2 takes it over, and i1's writes are refused from now on
    assert_eq!(
        s.acquire_lease("a", "i2", ttl)?,
        LeaseGrant::Granted {
            revision: 2,
            taken_over: true
        }
    );
    assert!(fenced(s.append("a", 1, &[drag(3)]), Some(2)));
    assert!(fenced(s.checkpoint("a", 1, &checkpoint(1, 2)), Some(2)));
    assert!(fenced(
        s.set_constraints("a", 1, &serde_json::json!({})),
        Some(2)
    ));
    assert_eq!(s.journal("a")?, vec![drag(1)], "no fenced write landed");
    assert!(s.get_checkpoint("a")?.is_none());
    assert_eq!(s.renew_leases("i1", &[("a".into(), 1)], ttl)?, vec!["a"]);
    s.checkpoint("a", 2, &checkpoint(2, 2))?;
    // released: the next owner takes it at once (not a takeover); the
    // released revision stays refused
    s.release_lease("a", "i2", 2)?;
    assert_eq!(
        s.acquire_lease("a", "i1", ttl)?,
        LeaseGrant::Granted {
            revision: 3,
            taken_over: false
        }
    );
    assert!(fenced(s.append("a", 2, &[drag(4)]), Some(3)));
    // a deleted session's lease goes with it
    s.delete_session("a")?;
    s.put_session(&record("a"))?;
    assert!(fenced(s.append("a", 3, &[drag(5)]), None));
    Ok(())
}

pub(super) fn handoff_requests_reach_the_owner(b: Backend) -> Result<(), StoreError> {
    let s = &*b.store;
    let ttl = Duration::from_secs(30);
    s.put_session(&record("a"))?;
    s.put_session(&record("b"))?;
    let _ = s.acquire_lease("a", "i1", ttl)?;
    let _ = s.acquire_lease("b", "i1", ttl)?;
    assert!(s.handoffs_wanted("i1")?.is_empty());
    assert!(matches!(
        s.acquire_lease("a", "i2", ttl)?,
        LeaseGrant::HeldBy { .. }
    ));
    assert_eq!(s.handoffs_wanted("i1")?, vec!["a"]);
    assert!(s.handoffs_wanted("i2")?.is_empty());
    // renewing keeps the request; the owner releases, the asker takes it
    assert!(s.renew_leases("i1", &[("a".into(), 1)], ttl)?.is_empty());
    assert_eq!(s.handoffs_wanted("i1")?, vec!["a"]);
    s.release_lease("a", "i1", 1)?;
    assert!(
        s.handoffs_wanted("i1")?.is_empty(),
        "released: nothing to hand over"
    );
    assert_eq!(
        s.acquire_lease("a", "i2", ttl)?,
        LeaseGrant::Granted {
            revision: 2,
            taken_over: false
        }
    );
    assert!(s.handoffs_wanted("i2")?.is_empty(), "the grant cleared it");
    Ok(())
}

pub(super) fn one_winner_when_instances_race_for_a_lease(b: Backend) -> Result<(), StoreError> {
    let s = b.store.clone();
    s.put_session(&record("r"))?;
    let threads: Vec<_> = (0..6)
        .map(|i| {
            let s = s.clone();
            std::thread::spawn(move || {
                s.acquire_lease("r", &format!("i{i}"), Duration::from_secs(30))
            })
        })
        .collect();
    let mut granted = 0;
    for t in threads {
        let g = t.join().map_err(|_| backend_err("thread panicked"))??;
        granted += usize::from(matches!(g, LeaseGrant::Granted { .. }));
    }
    assert_eq!(granted, 1);
    Ok(())
}

pub(super) fn everything_survives_reopen(b: Backend) -> Result<(), StoreError> {
    let Some(reopen) = b.reopen else {
        return Ok(()); // the memory store keeps nothing, by design
    };
    let mesh = Arc::new(grid(3, 1.0)?);
    {
        let s = b.store;
        s.put_mesh("m", mesh.clone())?;
        s.put_session(&record("a"))?;
        s.checkpoint("a", NO_FENCE, &checkpoint(2, 9))?;
        s.append("a", NO_FENCE, &[drag(1), drag(2)])?;
        let _ = s.acquire_lease("a", "i1", Duration::from_secs(60))?;
    }
    let s = reopen()?;
    assert_eq!(
        s.get_mesh("m")?.map(|m| m.positions().to_vec()),
        Some(mesh.positions().to_vec())
    );
    assert_eq!(s.list_sessions()?, vec![record("a")]);
    assert_eq!(s.get_checkpoint("a")?, Some(checkpoint(2, 9)));
    assert_eq!(s.journal("a")?, vec![drag(1), drag(2)]);
    assert!(matches!(
        s.acquire_lease("a", "i2", Duration::from_secs(1))?,
        LeaseGrant::HeldBy { .. }
    ));
    s.ping()?;
    Ok(())
}

/// Writes to a session the store does not hold (deleted while an actor's
/// checkpoint or journal write was on its way) are the typed `Missing`,
/// which the actor treats as nothing to keep and the API as 404.
pub(super) fn writes_to_a_deleted_session_are_missing(b: Backend) -> Result<(), StoreError> {
    let s = &*b.store;
    s.put_session(&record("gone"))?;
    s.append("gone", NO_FENCE, &[drag(1)])?;
    s.delete_session("gone")?;
    let missing = |r: Result<(), StoreError>, want: &str| matches!(r, Err(StoreError::Missing(ref id)) if id == want);
    assert!(missing(
        s.checkpoint("gone", NO_FENCE, &checkpoint(1, 4)),
        "gone"
    ));
    assert!(missing(s.append("gone", NO_FENCE, &[drag(2)]), "gone"));
    assert!(missing(
        s.checkpoint("never", NO_FENCE, &checkpoint(1, 4)),
        "never"
    ));
    Ok(())
}

/// One `#[test]` per case for a backend constructor.
macro_rules! store_suite {
    ($backend:ident: $($case:ident),* $(,)?) => {
        mod $backend {
            $(
                #[test]
                fn $case() -> Result<(), super::StoreError> {
                    match super::$backend() {
                        Some(b) => super::$case(b),
                        None => Ok(()),
                    }
                }
            )*
        }
    };
}

macro_rules! every_case {
    ($($backend:ident),*) => {
        $(
            store_suite!($backend:
                mesh_and_session_round_trip,
                journal_append_and_truncate_on_checkpoint,
                concurrent_appends_are_all_kept_in_order,
                leases_hold_expire_and_fence,
                handoff_requests_reach_the_owner,
                one_winner_when_instances_race_for_a_lease,
                everything_survives_reopen,
                writes_to_a_deleted_session_are_missing,
                named_poses_round_trip,
            );
        )*
    };
}

every_case!(memory, sqlite, postgres);
