//! Named poses through the server: save the settled pose under a name,
//! list, read, rename, delete and restore (an undo step, back to the
//! pose's constraint set), over HTTP and WebSocket, with typed errors; and
//! a SIGKILL of a `dend serve --data-dir` process keeps them (SQLite).

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use dend_client::ws::{ClientMsg, DeltaJson};
use dend_client::{
    Client, ClientError, ConstraintsSpec, HandleSpec, RenamePose, SavePose, SessionClient,
    SessionParams, VertexSet,
};
use dend_server::Config;
use dend_testkit::server::{grid, grid_constraints, start};
use serde_json::{json, Value};

/// The body of a save as `name`.
fn save(name: &str, replace: bool) -> Option<Value> {
    let name = name.to_owned();
    Some(json_of(SavePose { name, replace }))
}

/// The body of a rename to `name`.
fn rename(name: &str) -> Option<Value> {
    let name = name.to_owned();
    Some(json_of(RenamePose { name }))
}

const N: usize = 8;

/// A small raw HTTP helper for the pose routes: (status, JSON body).
async fn call(
    s: &SessionClient,
    base: &str,
    method: &str,
    tail: &str,
    body: Option<Value>,
) -> (u16, Value) {
    let url = format!("{base}/v1/sessions/{}{tail}", s.id);
    let mut rq = reqwest::Client::new()
        .request(method.parse().unwrap(), url)
        .bearer_auth(&s.token);
    if let Some(b) = body {
        rq = rq.json(&b);
    }
    let r = rq.send().await.unwrap();
    let status = r.status().as_u16();
    let text = r.text().await.unwrap();
    (status, serde_json::from_str(&text).unwrap_or(Value::Null))
}

async fn ready_grid(base: &str) -> Result<SessionClient, ClientError> {
    let c = Client::new(base);
    let (p, t) = grid(N);
    let m = c.upload_json(&p, &t).await?;
    let s = c.create_session(&m.id, SessionParams::default()).await?;
    s.set_constraints(&grid_constraints(N)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    Ok(s)
}

fn positions(v: &Value) -> Vec<[f64; 3]> {
    serde_json::from_value(v["positions"].clone()).unwrap()
}

/// The pose names of a session's info, a `state` message (the session's
/// fields flattened into it) or a list.
fn names(v: &impl serde::Serialize) -> Vec<String> {
    let v = serde_json::to_value(v).unwrap();
    v["poses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap().to_owned())
        .collect()
}

/// A typed answer as its JSON.
fn json_of(v: impl serde::Serialize) -> Value {
    serde_json::to_value(v).unwrap()
}

#[tokio::test]
async fn save_list_rename_delete_and_restore_over_http() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let s = ready_grid(&base).await?;
    let (st, v) = call(&s, &base, "GET", "/poses", None).await;
    assert_eq!((st, names(&v)), (200, Vec::<String>::new()));
    s.drag("top", DeltaJson::translate([0.0, 0.0, 2.0]), Some(100))
        .await?;
    let (st, lift) = call(&s, &base, "POST", "/poses", save("lift", false)).await;
    assert_eq!(st, 201, "{lift}");
    assert_eq!(
        (lift["name"].as_str(), lift["index"].as_u64()),
        (Some("lift"), Some(0))
    );
    let settled = s.pose().await?;
    assert!(settled.settled, "a save waits for the pose to settle");
    s.drag(
        "top",
        DeltaJson::axis_angle([1.0, 0.0, 0.0], 40.0),
        Some(100),
    )
    .await?;
    let (st, _) = call(&s, &base, "POST", "/poses", save("curl", false)).await;
    assert_eq!(st, 201);
    let curl = s.pose().await?;
    // listed in save order, in the session's state too
    let (_, v) = call(&s, &base, "GET", "/poses", None).await;
    assert_eq!(names(&v), ["lift", "curl"]);
    assert_eq!(names(&s.info().await?), ["lift", "curl"]);
    let (st, got) = call(&s, &base, "GET", "/poses/lift", None).await;
    assert_eq!(st, 200);
    assert_eq!(positions(&got), settled.positions, "saved bit for bit");
    // restore: exactly the saved pose, an undo step, and drags go on from it
    let (st, back) = call(&s, &base, "POST", "/poses/lift/restore", None).await;
    assert_eq!(st, 200, "{back}");
    assert_eq!(positions(&back), settled.positions);
    assert_eq!(s.pose().await?.positions, settled.positions);
    assert_eq!(
        s.undo().await?.positions,
        curl.positions,
        "undo goes back to before the restore"
    );
    assert_eq!(s.redo().await?.positions, settled.positions);
    let moved = s
        .drag("top", DeltaJson::translate([0.0, 0.0, -0.5]), Some(100))
        .await?;
    let dz = moved.positions[N * N - 1][2] - settled.positions[N * N - 1][2];
    assert!(
        (dz + 0.5).abs() < 0.05,
        "the handle target was restored with the pose: {dz}"
    );
    // rename, replace in place, delete; typed errors
    let (st, r) = call(&s, &base, "PATCH", "/poses/lift", rename("raised arm")).await;
    assert_eq!((st, r["name"].as_str()), (200, Some("raised arm")));
    let (st, e) = call(&s, &base, "PATCH", "/poses/curl", rename("raised arm")).await;
    assert_eq!((st, e["code"].as_str()), (409, Some("pose_exists")));
    // saving over a name is refused unless asked for: the first pose stays
    let (_, before) = call(&s, &base, "GET", "/poses/raised%20arm", None).await;
    let (st, e) = call(&s, &base, "POST", "/poses", save("raised arm", false)).await;
    assert_eq!((st, e["code"].as_str()), (409, Some("pose_exists")), "{e}");
    let (_, kept) = call(&s, &base, "GET", "/poses/raised%20arm", None).await;
    assert_eq!(
        positions(&kept),
        positions(&before),
        "a refused save keeps the pose"
    );
    let (st, _) = call(&s, &base, "POST", "/poses", save("raised arm", true)).await;
    assert_eq!(st, 201, "saving with `replace` replaces it");
    let (_, v) = call(&s, &base, "GET", "/poses", None).await;
    assert_eq!(names(&v), ["raised arm", "curl"], "in its place");
    let (_, replaced) = call(&s, &base, "GET", "/poses/raised%20arm", None).await;
    assert_eq!(positions(&replaced), s.pose().await?.positions);
    assert_ne!(
        positions(&replaced),
        positions(&before),
        "the pose moved since"
    );
    let (st, _) = call(&s, &base, "GET", "/poses/raised%20arm", None).await;
    assert_eq!(st, 200, "names are percent-encoded in paths");
    for (method, tail, body) in [
        ("GET", "/poses/nope", None),
        ("DELETE", "/poses/nope", None),
        ("POST", "/poses/nope/restore", None),
        ("PATCH", "/poses/nope", rename("x")),
    ] {
        let (st, e) = call(&s, &base, method, tail, body).await;
        assert_eq!(
            (st, e["code"].as_str()),
            (404, Some("pose_not_found")),
            "{method} {tail}"
        );
    }
    for bad in ["", " \t", "a\nb", &"x".repeat(129)] {
        let (st, e) = call(&s, &base, "POST", "/poses", save(bad, false)).await;
        assert_eq!(
            (st, e["code"].as_str()),
            (422, Some("invalid_pose_name")),
            "{bad:?}"
        );
    }
    // deliberately malformed (a misspelt field), which the typed body
    // cannot write: sent as raw JSON
    let (st, e) = call(&s, &base, "POST", "/poses", Some(json!({"nom": "x"}))).await;
    assert_eq!((st, e["code"].as_str()), (400, Some("invalid_json")));
    let (st, _) = call(&s, &base, "DELETE", "/poses/curl", None).await;
    assert_eq!(st, 204);
    let (_, v) = call(&s, &base, "GET", "/poses", None).await;
    assert_eq!(names(&v), ["raised arm"]);
    // a wrong token opens nothing
    let other = Client::new(&base).session(&s.id, "nope");
    let (st, _) = call(&other, &base, "GET", "/poses/raised%20arm", None).await;
    assert_eq!(st, 403);
    Ok(())
}

#[tokio::test]
async fn a_restore_brings_back_the_pose_constraint_set() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let s = ready_grid(&base).await?;
    s.drag("top", DeltaJson::translate([0.0, 1.0, 1.0]), Some(100))
        .await?;
    let (st, _) = call(&s, &base, "POST", "/poses", save("a", false)).await;
    assert_eq!(st, 201);
    let saved = s.pose().await?;
    let first = json_of(s.info().await?)["constraints"].clone();
    // another set: the left column fixed, the right one the handle
    let left: Vec<usize> = (0..N).map(|j| j * N).collect();
    let right: Vec<usize> = (0..N).map(|j| j * N + N - 1).collect();
    let side = ConstraintsSpec::new(
        VertexSet::indices(left),
        vec![HandleSpec::named("side", VertexSet::indices(right))],
    );
    s.set_constraints(&side).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    s.drag("side", DeltaJson::translate([0.0, 0.0, 1.0]), Some(50))
        .await?;
    let (st, back) = call(&s, &base, "POST", "/poses/a/restore", None).await;
    assert_eq!(st, 200, "{back}");
    assert_eq!(positions(&back), saved.positions);
    s.wait_ready(Duration::from_secs(60)).await?;
    let typed = s.info().await?;
    assert_eq!(typed.handles, ["top"]);
    let info = json_of(typed);
    assert_eq!(
        info["constraints"]["handles"][0]["name"],
        first["handles"][0]["name"]
    );
    assert_eq!(
        s.pose().await?.positions,
        saved.positions,
        "the pose stays as restored"
    );
    Ok(())
}

#[tokio::test]
async fn poses_over_the_websocket() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let s = ready_grid(&base).await?;
    let mut ws = s.connect().await?;
    ws.send(&ClientMsg::SavePose {
        name: "rest".into(),
        replace: false,
    })
    .await?;
    let mut state = ws.event("state").await?;
    while names(&state).is_empty() {
        state = ws.event("state").await?;
    }
    assert_eq!(names(&state), ["rest"]);
    // the same name again: refused, unless `replace`
    ws.send(&ClientMsg::SavePose {
        name: "rest".into(),
        replace: false,
    })
    .await?;
    let e = json_of(ws.event("error").await?);
    assert_eq!(e["code"], "pose_exists", "{e}");
    ws.send(&ClientMsg::SavePose {
        name: "rest".into(),
        replace: true,
    })
    .await?;
    // (had it been refused, its error would come before the one below)
    ws.send(&ClientMsg::RenamePose {
        name: "rest".into(),
        to: "start".into(),
    })
    .await?;
    let mut state = ws.event("state").await?;
    while names(&state) != ["start"] {
        state = ws.event("state").await?;
    }
    ws.send(&ClientMsg::RestorePose {
        name: "gone".into(),
    })
    .await?;
    let e = json_of(ws.event("error").await?);
    assert_eq!(e["code"], "pose_not_found");
    ws.send(&ClientMsg::DeletePose {
        name: "start".into(),
    })
    .await?;
    let mut state = ws.event("state").await?;
    while !names(&state).is_empty() {
        state = ws.event("state").await?;
    }
    ws.close().await?;
    Ok(())
}

struct Server {
    child: Child,
    base: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn serve(dir: &std::path::Path) -> Server {
    let mut child = Command::new(env!("CARGO_BIN_EXE_dend"))
        .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
        .arg(dir)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let base = loop {
        let line = lines.next().expect("the server printed its URL").unwrap();
        if let Some(url) = line.strip_prefix("listening on ") {
            break url.trim().to_owned();
        }
    };
    drop(std::thread::spawn(move || for _ in lines.by_ref() {}));
    Server { child, base }
}

#[tokio::test]
async fn named_poses_survive_a_sigkill_with_sqlite() -> Result<(), ClientError> {
    let dir = tempfile::tempdir().unwrap();
    let mut server = serve(dir.path());
    let s = ready_grid(&server.base).await?;
    let mut saved = vec![];
    for (name, dz) in [("low", 0.5), ("high", 2.0)] {
        s.drag("top", DeltaJson::translate([0.0, 0.0, dz]), Some(100))
            .await?;
        let (st, _) = call(&s, &server.base, "POST", "/poses", save(name, false)).await;
        assert_eq!(st, 201);
        saved.push(s.pose().await?.positions);
    }
    let (st, _) = call(&s, &server.base, "PATCH", "/poses/low", rename("lower")).await;
    assert_eq!(st, 200);
    // acknowledged, then killed without warning
    server.child.kill().unwrap();
    let _ = server.child.wait();
    let server = serve(dir.path());
    let s = Client::new(&server.base).session(&s.id, &s.token);
    let (st, v) = call(&s, &server.base, "GET", "/poses", None).await;
    assert_eq!(st, 200, "{v}");
    assert_eq!(names(&v), ["lower", "high"]);
    for (name, want) in ["lower", "high"].iter().zip(&saved) {
        let (_, got) = call(&s, &server.base, "GET", &format!("/poses/{name}"), None).await;
        assert_eq!(&positions(&got), want, "{name} bit for bit");
    }
    s.wait_ready(Duration::from_secs(60)).await?;
    let (st, back) = call(&s, &server.base, "POST", "/poses/lower/restore", None).await;
    assert_eq!(st, 200, "{back}");
    assert_eq!(positions(&back), saved[0]);
    Ok(())
}
