//! The Rust client's routes against a real server: presets, readiness,
//! mesh info and deletion, curvature and named poses, with the typed
//! errors a caller matches on.

use std::time::Duration;

use dend_client::ws::{DeltaJson, PoseInfo};
use dend_client::{
    Client, ClientError, ConstraintsSpec, ErrorCode, HandleSpec, SessionClient, SessionParams,
    VertexSet,
};
use dend_server::Config;
use dend_testkit::server::{grid, grid_constraints, start};

/// The code of a refused call (panics on success or another failure).
fn code_of<T: std::fmt::Debug>(r: Result<T, ClientError>) -> ErrorCode {
    match r {
        Err(ClientError::Api { code, .. }) => code,
        other => panic!("expected an API error, got {other:?}"),
    }
}

#[tokio::test]
async fn presets_list_the_default_first_and_each_opens_a_session() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    c.ready().await?;
    let list = c.presets().await?;
    assert_eq!(list.presets[0].name, list.default);
    let names: std::collections::HashSet<_> = list.presets.iter().map(|p| &p.name).collect();
    assert_eq!(names.len(), list.presets.len(), "names are unique");
    assert!(list.presets.len() >= 2);
    // the presets differ, each written out in full
    assert_ne!(list.presets[0].params, list.presets[1].params);
    let (p, t) = grid(5);
    let mesh = c.upload_json(&p, &t).await?;
    for preset in &list.presets {
        assert!(preset.params.preset.is_none(), "written without a preset");
        assert!(preset.params.max_iters.is_some() && preset.params.formulation.is_some());
        // by name, and by its listed parameters: both open a session
        for params in [SessionParams::preset(&preset.name), preset.params.clone()] {
            let s = c.create_session(&mesh.id, params).await?;
            s.delete().await?;
        }
    }
    let unknown = c
        .create_session(&mesh.id, SessionParams::preset("no-such-preset"))
        .await;
    assert_eq!(code_of(unknown), ErrorCode::InvalidParams);
    Ok(())
}

#[tokio::test]
async fn a_mesh_is_read_back_and_deleted_once_no_session_uses_it() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let (p, t) = grid(4);
    let mesh = c.upload_json(&p, &t).await?;
    assert_eq!(c.mesh(&mesh.id).await?, mesh);
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    assert_eq!(code_of(c.delete_mesh(&mesh.id).await), ErrorCode::MeshInUse);
    s.delete().await?;
    c.delete_mesh(&mesh.id).await?;
    assert_eq!(code_of(c.mesh(&mesh.id).await), ErrorCode::MeshNotFound);
    // an id with characters a path must escape is one segment, not a route
    assert_eq!(code_of(c.mesh("a/b?c").await), ErrorCode::MeshNotFound);
    Ok(())
}

/// A ready session on an icosphere of radius `r` (south cap fixed, north
/// cap the handle `top`).
async fn sphere_session(c: &Client, r: f64) -> Result<SessionClient, ClientError> {
    let m = dend_testkit::icosphere(3, r);
    let mesh = c.upload_json(m.positions(), m.triangles()).await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    let cap = |z: f64| VertexSet::sphere([0.0, 0.0, z * r], 0.3 * r);
    let spec = ConstraintsSpec::new(cap(-1.0), vec![HandleSpec::named("top", cap(1.0))]);
    s.set_constraints(&spec).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    Ok(s)
}

#[tokio::test]
async fn curvature_scales_with_the_mesh_and_follows_the_pose() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let (small, large) = (
        sphere_session(&c, 1.0).await?,
        sphere_session(&c, 3.0).await?,
    );
    let (a, b) = (small.curvature().await?, large.curvature().await?);
    let n = dend_testkit::icosphere(3, 1.0).num_vertices();
    assert!(a.mean.len() == n && a.gaussian.len() == n && a.g.len() == n);
    // mesh units: the same sphere three times larger has H / 3 and K / 9
    for i in 0..n {
        assert!((a.mean[i] - 3.0 * b.mean[i]).abs() < 1e-9 * a.mean[i].abs().max(1.0));
        assert!((a.gaussian[i] - 9.0 * b.gaussian[i]).abs() < 1e-9 * a.gaussian[i].abs().max(1.0));
        // G = max(H² − K, 0) (the operators' clamp), and a sphere's H is
        // 1/r, its K 1/r²
        let g = (a.mean[i].powi(2) - a.gaussian[i]).max(0.0);
        assert!((a.g[i] - g).abs() < 1e-9, "G {} against {g} at {i}", a.g[i]);
        assert!((a.mean[i] - 1.0).abs() < 0.1, "H {} at {i}", a.mean[i]);
        assert!(
            (a.gaussian[i] - 1.0).abs() < 0.25,
            "K {} at {i}",
            a.gaussian[i]
        );
    }
    // a drag bends the sphere: the curvatures are the new pose's
    let pose = small
        .drag("top", DeltaJson::translate([0.0, 0.0, 0.5]), Some(50))
        .await?;
    let after = small.curvature().await?;
    assert_eq!(after.revision, pose.revision);
    assert!(after.revision > a.revision);
    assert!(
        after
            .mean
            .iter()
            .zip(&a.mean)
            .any(|(x, y)| (x - y).abs() > 1e-3),
        "the stretched sphere has other curvatures"
    );
    Ok(())
}

#[tokio::test]
async fn named_poses_are_saved_read_renamed_restored_and_deleted() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let (p, t) = grid(6);
    let mesh = c.upload_json(&p, &t).await?;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    s.set_constraints(&grid_constraints(6)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let lifted = s
        .drag("top", DeltaJson::translate([0.0, 0.0, 1.0]), Some(200))
        .await?;
    // a name with a space, a slash and a question mark: one path segment
    let name = "raised arm/left?";
    let saved = s.save_pose(name, false).await?;
    assert_eq!((saved.name.as_str(), saved.index), (name, 0));
    assert_eq!(s.poses().await?, vec![saved.clone()]);
    let read = s.named_pose(name).await?;
    assert_eq!(read.info, saved);
    assert_eq!(read.positions, s.pose().await?.positions);
    assert_eq!(read.positions, lifted.positions);
    // the name is taken: refused unless replacing
    assert_eq!(
        code_of(s.save_pose(name, false).await),
        ErrorCode::PoseExists
    );
    let replaced = s.save_pose(name, true).await?;
    assert_eq!(replaced.name, name);
    // renamed, then restored after another drag: the saved positions again
    let renamed: PoseInfo = s.rename_pose(name, "up").await?;
    assert_eq!(renamed.name, "up");
    assert_eq!(code_of(s.named_pose(name).await), ErrorCode::PoseNotFound);
    let moved = s
        .drag("top", DeltaJson::translate([1.0, 0.0, 0.0]), Some(200))
        .await?;
    assert_ne!(moved.positions, lifted.positions);
    let restored = s.restore_pose("up").await?;
    assert_eq!(restored.positions, lifted.positions);
    assert!(restored.revision > moved.revision);
    // an undo step: undo goes back to the moved pose
    assert_eq!(s.undo().await?.positions, moved.positions);
    s.delete_pose("up").await?;
    assert!(s.poses().await?.is_empty());
    assert_eq!(code_of(s.delete_pose("up").await), ErrorCode::PoseNotFound);
    assert_eq!(
        code_of(s.save_pose("", false).await),
        ErrorCode::InvalidPoseName
    );
    Ok(())
}
