//! Posing workflow over the HTTP API: a constraint edit on a posed session
//! keeps the pose (the new set is anchored where the pose has it), undo and
//! redo span constraint edits, and a revived session gets the anchored set
//! back from the store.

use std::sync::Arc;
use std::time::Duration;

use dend_client::ws::{ClientMsg, DeltaJson, ServerMsg, SessionInfo};
use dend_client::{
    Client, ClientError, ConstraintsSpec, ErrorCode, HandleSpec, SessionClient, SessionParams,
    VertexSet, WarningKind,
};
use dend_server::store::MemoryStore;
use dend_server::Config;
use dend_testkit::server::{grid, grid_constraints, start_with_store};

const N: usize = 8;

fn max_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
        .fold(0.0, f64::max)
}

/// Row `r` of the grid.
fn row(r: usize) -> Vec<usize> {
    (r * N..(r + 1) * N).collect()
}

/// A drag of `top` by `t`, solved to convergence; the pose.
async fn drag(s: &SessionClient, t: [f64; 3]) -> Result<Vec<[f64; 3]>, ClientError> {
    let p = s.drag("top", DeltaJson::translate(t), Some(2000)).await?;
    assert!(p.converged, "drag by {t:?} did not converge");
    Ok(p.positions)
}

async fn posed_session(
    store: Arc<MemoryStore>,
) -> Result<(Client, SessionClient, Vec<[f64; 3]>), ClientError> {
    let (base, _state) = start_with_store(Config::default(), store).await;
    let c = Client::new(&base);
    let (p, t) = grid(N);
    let mesh = c.upload_json(&p, &t).await?;
    let s = c
        .create_session(
            &mesh.id,
            SessionParams {
                tol: Some(1e-9),
                max_iters: Some(2000),
                ..SessionParams::default()
            },
        )
        .await?;
    s.set_constraints(&grid_constraints(N)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let posed = drag(&s, [0.0, 0.0, 3.0]).await?;
    Ok((c, s, posed))
}

/// Bottom and row 3 fixed, the top row the handle `top`.
fn pinned_middle() -> ConstraintsSpec {
    let mut fixed = row(0);
    fixed.extend(row(3));
    ConstraintsSpec::new(
        VertexSet::indices(fixed),
        vec![HandleSpec::named("top", VertexSet::indices(row(N - 1)))],
    )
}

#[tokio::test]
async fn a_constraint_edit_keeps_the_pose_and_undo_spans_it() -> Result<(), ClientError> {
    let (_c, s, posed) = posed_session(Arc::new(MemoryStore::new())).await?;
    let lifted = posed[3 * N + 2][2];
    assert!(lifted > 0.5, "the drag should lift row 3: z = {lifted}");
    // pin row 3 where the pose has it
    s.set_constraints(&pinned_middle()).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let kept = drag(&s, [0.0; 3]).await?;
    for v in row(3).into_iter().chain(row(N - 1)).chain(row(0)) {
        assert!(
            max_diff(&kept[v..v + 1], &posed[v..v + 1]) < 1e-12,
            "constrained vertex {v} moved: {:?} -> {:?}",
            posed[v],
            kept[v]
        );
    }
    let jump = max_diff(&kept, &posed);
    assert!(jump < 0.05, "pose jump {jump} on an 8-unit grid");
    // a drag with the new set moves the top, not row 3
    let moved = drag(&s, [1.0, 0.0, 0.0]).await?;
    assert!(
        max_diff(
            &moved[row(3)[0]..row(3)[N - 1] + 1],
            &kept[row(3)[0]..row(3)[N - 1] + 1]
        ) < 1e-12
    );
    assert!((moved[N * N - 1][0] - kept[N * N - 1][0] - 1.0).abs() < 1e-9);
    // undo: the pose after the edit, then the pose before it (old set)
    assert!(max_diff(&s.undo().await?.positions, &kept) < 1e-12);
    let before = s.undo().await?;
    assert!(max_diff(&before.positions, &posed) < 1e-12);
    s.wait_ready(Duration::from_secs(60)).await?;
    // the old set again: row 3 is free, so dragging the top moves it
    let old = drag(&s, [0.0, 0.0, 1.0]).await?;
    let r3 = row(3)[2];
    assert!(
        (old[r3][2] - posed[r3][2]).abs() > 0.05,
        "row 3 should be free after undoing the edit: {:?} vs {:?}",
        old[r3],
        posed[r3]
    );
    Ok(())
}

#[tokio::test]
async fn redo_and_reset_cross_constraint_sets() -> Result<(), ClientError> {
    let (_c, s, _posed) = posed_session(Arc::new(MemoryStore::new())).await?;
    s.set_constraints(&pinned_middle()).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let kept = drag(&s, [0.0; 3]).await?;
    let _ = s.undo().await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let again = s.redo().await?;
    assert!(max_diff(&again.positions, &kept) < 1e-12);
    s.wait_ready(Duration::from_secs(60)).await?;
    // reset: the rest pose, and the set anchored at rest (row 3 held at
    // rest, so a zero drag keeps the rest pose)
    let z = s.reset().await?;
    let (rest, _) = grid(N);
    assert!(max_diff(&z.positions, &rest) < 1e-12);
    s.wait_ready(Duration::from_secs(60)).await?;
    let still = drag(&s, [0.0; 3]).await?;
    assert!(
        max_diff(&still, &rest) < 1e-9,
        "{}",
        max_diff(&still, &rest)
    );
    Ok(())
}

#[tokio::test]
async fn a_revived_session_has_the_anchored_set_and_the_kept_pose() -> Result<(), ClientError> {
    let store = Arc::new(MemoryStore::new());
    let (_c, s, _posed) = posed_session(store.clone()).await?;
    s.set_constraints(&pinned_middle()).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let kept = drag(&s, [0.0; 3]).await?;
    let moved = drag(&s, [0.5, 0.0, 0.0]).await?;
    assert!(max_diff(&moved, &kept) > 0.1);
    // a second instance on the same store revives the session
    let (base2, _state2) = start_with_store(Config::default(), store).await;
    let s2 = Client::new(&base2).session(&s.id, &s.token);
    s2.wait_ready(Duration::from_secs(60)).await?;
    let revived = drag(&s2, [0.0; 3]).await?;
    let d = max_diff(&revived, &moved);
    assert!(d < 1e-6, "the revived pose differs by {d}");
    Ok(())
}

#[tokio::test]
async fn the_session_shows_its_constraints_and_refuses_stale_edits() -> Result<(), ClientError> {
    let (_c, s, _posed) = posed_session(Arc::new(MemoryStore::new())).await?;
    let info = s.info().await?;
    assert_eq!(info.constraints, Some(grid_constraints(N)));
    let r1 = info.constraints_revision;
    // a joined client sees the set and its revision in its first state
    let mut ws = s.connect().await?;
    let st = state_of(ws.event("state").await?);
    assert_eq!(st.constraints, Some(grid_constraints(N)));
    // an edit based on the current revision applies...
    let r2 = s.set_constraints_if(&pinned_middle(), r1).await?;
    assert_ne!(r2, r1);
    // ...and reaches the joined client
    loop {
        let st = state_of(ws.event("state").await?);
        if st.constraints_revision == r2 {
            assert_eq!(st.constraints, Some(pinned_middle()));
            break;
        }
    }
    // a second edit based on the old revision is refused, the set unchanged
    match s.set_constraints_if(&grid_constraints(N), r1).await {
        Err(ClientError::Api { status, code, .. }) => {
            assert_eq!((status, code), (409, ErrorCode::StaleConstraints));
        }
        other => panic!("expected stale_constraints, got {other:?}"),
    }
    let info = s.info().await?;
    assert_eq!(info.constraints, Some(pinned_middle()));
    assert_eq!(info.constraints_revision, r2);
    // undo to the first set (the edit's own solve and this drag are one
    // entry) changes the revision back to the first set's
    s.wait_ready(Duration::from_secs(60)).await?;
    let _ = drag(&s, [0.0; 3]).await?;
    let _ = s.undo().await?;
    let info = s.info().await?;
    assert_eq!(info.constraints, Some(grid_constraints(N)));
    assert_eq!(info.constraints_revision, r1);
    Ok(())
}

#[tokio::test]
async fn one_gesture_is_one_undo_step_however_often_it_settles() -> Result<(), ClientError> {
    let (_c, s, posed) = posed_session(Arc::new(MemoryStore::new())).await?;
    let mut ws = s.connect().await?;
    ws.send(&ClientMsg::Grab {
        handle: "top".into(),
    })
    .await?;
    // three moves, each settling before the next
    for seq in 1..=3 {
        ws.drag(0, [0.3, 0.0, 0.0], None, seq).await?;
        let (h, _) = ws.frame_acking(seq, true).await?;
        assert!(h.settled);
    }
    let mid = s.pose().await?.positions;
    assert!(max_diff(&mid, &posed) > 0.5);
    ws.send(&ClientMsg::Release {
        handle: "top".into(),
    })
    .await?;
    // one undo goes back to before the grab...
    let back = s.undo().await?;
    let d = max_diff(&back.positions, &posed);
    assert!(
        d < 1e-12,
        "one undo should undo the whole gesture (off by {d})"
    );
    // ...and the release made the gesture's end one entry: redo reaches it
    let again = s.redo().await?;
    let d = max_diff(&again.positions, &mid);
    assert!(d < 1e-12, "redo should give the gesture's end (off by {d})");
    Ok(())
}

#[tokio::test]
async fn the_session_reports_the_warnings_of_its_constraint_set() -> Result<(), ClientError> {
    let (_c, s, _posed) = posed_session(Arc::new(MemoryStore::new())).await?;
    assert!(s.info().await?.warnings.is_empty());
    // one handle, nothing fixed, and a stray handle vertex in row 3
    let mut top = row(N - 1);
    top.push(3 * N + 3);
    let no_fixed = ConstraintsSpec::new(
        VertexSet::indices([]),
        vec![HandleSpec::named("top", VertexSet::indices(top))],
    );
    s.set_constraints(&no_fixed).await?;
    let w = s.info().await?.warnings;
    assert_eq!(w.len(), 2, "{w:?}");
    assert_eq!(w[0].kind, WarningKind::NothingFixed);
    let stray = (3 * N + 3) as u32;
    assert_eq!(
        w[1].kind,
        WarningKind::StrayVertices {
            count: 1,
            vertices: vec![stray]
        }
    );
    assert!(w[0].message.contains("rigidly"), "{}", w[0].message);
    Ok(())
}

/// The session of a `state` event.
fn state_of(m: ServerMsg) -> SessionInfo {
    match m {
        ServerMsg::State { session, .. } => session,
        other => panic!("not a state: {other:?}"),
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[tokio::test]
async fn curvature_of_the_pose_matches_a_sphere() -> Result<(), ClientError> {
    let (base, _state) = start_with_store(Config::default(), Arc::new(MemoryStore::new())).await;
    let c = Client::new(&base);
    let sphere = dend_testkit::uv_sphere(23, 48, 2.0);
    let (p, t) = (sphere.positions().to_vec(), sphere.triangles().to_vec());
    let mesh = c.upload_json(&p, &t).await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    let http = reqwest::Client::new();
    let url = format!("{base}/v1/sessions/{}/curvature", s.id);
    assert_eq!(http.get(&url).send().await?.status(), 401);
    let j: serde_json::Value = http
        .get(&url)
        .bearer_auth(&s.token)
        .send()
        .await?
        .json()
        .await?;
    let col = |k: &str| -> Vec<f64> {
        j[k].as_array()
            .expect(k)
            .iter()
            .map(|v| v.as_f64().expect("number"))
            .collect()
    };
    let (h, k, g) = (col("mean"), col("gaussian"), col("g"));
    assert_eq!(h.len(), p.len());
    // radius 2: H = 1/2, K = 1/4, G = 0 (medians: the poles are irregular)
    assert!((median(h) - 0.5).abs() < 0.01, "H {}", median(col("mean")));
    assert!(
        (median(k) - 0.25).abs() < 0.01,
        "K {}",
        median(col("gaussian"))
    );
    assert!(median(g).abs() < 0.01, "G {}", median(col("g")));
    Ok(())
}
