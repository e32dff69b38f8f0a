//! The store suite's cases for named poses (run on every backend by
//! `suite/mod.rs`'s `every_case!`).

use super::{checkpoint, drag, record, Backend};
use crate::store::*;

/// A named pose `name` saved `ordinal`-th, over `n` vertices.
fn named(name: &str, ordinal: u64, n: usize) -> NamedPose {
    let cp = checkpoint(ordinal + 3, n);
    NamedPose {
        name: name.into(),
        ordinal,
        revision: cp.revision,
        created_unix: 1_700_000_000 + ordinal,
        constraints: (ordinal % 2 == 0).then(|| serde_json::json!({"handles": [[ordinal]]})),
        pose: cp
            .pose
            .iter()
            .map(|p| [p[0] * ordinal as f64, p[1], p[2]])
            .collect(),
        targets: cp.targets,
    }
}

/// Save, replace, rename, delete and list round-trip bit-exactly, in save
/// order; constraint edits and checkpoints keep the poses, a deleted
/// session's go with it, a reopened store has them, and writes are fenced.
pub(super) fn named_poses_round_trip(b: Backend) -> Result<(), StoreError> {
    let s = &*b.store;
    s.put_session(&record("a"))?;
    s.put_session(&record("b"))?;
    assert_eq!(s.named_poses("a")?, vec![]);
    let (p2, p1, p3) = (
        named("wave", 2, 5),
        named("crouch", 1, 5),
        named("jump", 3, 5),
    );
    for p in [&p2, &p1, &p3] {
        s.put_named_pose("a", NO_FENCE, p)?;
    }
    s.put_named_pose("b", NO_FENCE, &named("other", 1, 2))?;
    assert_eq!(
        s.named_poses("a")?,
        vec![p1.clone(), p2.clone(), p3.clone()]
    );
    // replacing keeps one pose of the name
    let p2b = NamedPose {
        pose: vec![[1e-300, -0.0, f64::MAX]; 5],
        ..p2.clone()
    };
    s.put_named_pose("a", NO_FENCE, &p2b)?;
    s.rename_named_pose("a", NO_FENCE, "crouch", "crouch 2")?;
    s.delete_named_pose("a", NO_FENCE, "jump")?;
    s.delete_named_pose("a", NO_FENCE, "never saved")?;
    let renamed = NamedPose {
        name: "crouch 2".into(),
        ..p1.clone()
    };
    let want = vec![renamed, p2b];
    assert_eq!(s.named_poses("a")?, want);
    // a new constraint set and a checkpoint keep them
    s.set_constraints("a", NO_FENCE, &serde_json::json!({"handles": []}))?;
    s.append("a", NO_FENCE, &[drag(1)])?;
    s.checkpoint("a", NO_FENCE, &checkpoint(9, 5))?;
    assert_eq!(s.named_poses("a")?, want);
    if let Some(reopen) = &b.reopen {
        assert_eq!(reopen()?.named_poses("a")?, want, "survives reopening");
    }
    // writes to a missing session are `Missing`; its poses go with it
    s.delete_session("b")?;
    assert_eq!(s.named_poses("b")?, vec![]);
    assert!(matches!(
        s.put_named_pose("b", NO_FENCE, &p1),
        Err(StoreError::Missing(_))
    ));
    // fenced like the journal
    let ttl = std::time::Duration::from_secs(30);
    assert!(matches!(
        s.acquire_lease("a", "i1", ttl)?,
        LeaseGrant::Granted { revision: 1, .. }
    ));
    s.put_named_pose("a", 1, &p3)?;
    for r in [
        s.put_named_pose("a", 7, &p1),
        s.rename_named_pose("a", 7, "jump", "x"),
        s.delete_named_pose("a", 7, "jump"),
    ] {
        assert!(matches!(r, Err(StoreError::Fenced { .. })), "{r:?}");
    }
    assert_eq!(s.named_poses("a")?.len(), 3);
    Ok(())
}
