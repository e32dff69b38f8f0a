//! Each bad input gets its specific error code, over real sockets; oversize
//! uploads are refused from `Content-Length` or while streaming.

use std::time::Duration;

use dend_client::ws::{CreateSession, DeltaJson, DragRequest};
use dend_client::{
    Client, ClientError, ConstraintsSpec, ErrorCode, HandleSpec, MeshJson, SessionParams, VertexSet,
};
use dend_server::Config;
use dend_testkit::server::{grid, grid_constraints, start};
use serde_json::{json, Value};

async fn expect(r: reqwest::Response, status: u16, code: &str) {
    assert_eq!(r.status().as_u16(), status, "status for {code}");
    let body: Value = r.json().await.expect("JSON error body");
    assert_eq!(body["code"], code, "{body}");
    assert!(body["message"].as_str().is_some_and(|m| !m.is_empty()));
}

#[tokio::test]
async fn each_bad_input_gets_its_code() -> Result<(), ClientError> {
    let (base, _state) = start(Config {
        max_vertices: 100,
        ..Config::default()
    })
    .await;
    let http = reqwest::Client::new();
    let c = Client::new(&base);
    let post = |path: &str, body: &str, ct: &str| {
        http.post(format!("{base}{path}"))
            .header("content-type", ct)
            .body(body.to_owned())
            .send()
    };
    let json_ct = "application/json";
    expect(
        post("/v1/meshes", "{not json", json_ct).await?,
        400,
        "invalid_json",
    )
    .await;
    expect(
        post(
            "/v1/meshes",
            r#"{"positions": [[0,0,0]], "triangles": [[0,1,2]]}"#,
            json_ct,
        )
        .await?,
        422,
        "invalid_mesh",
    )
    .await;
    expect(
        post("/v1/meshes", "v 0 0 0", "image/png").await?,
        415,
        "unsupported_format",
    )
    .await;
    let (p, t) = grid(11);
    let big = serde_json::to_string(&MeshJson {
        positions: p,
        triangles: t,
    })
    .expect("json");
    expect(
        post("/v1/meshes", &big, json_ct).await?,
        413,
        "too_many_vertices",
    )
    .await;
    expect(
        post("/v1/sessions", r#"{"mesh_id": "nope"}"#, json_ct).await?,
        404,
        "mesh_not_found",
    )
    .await;
    expect(
        http.get(format!("{base}/v1/nothing")).send().await?,
        404,
        "route_not_found",
    )
    .await;

    let (p, t) = grid(6);
    let mesh = c.upload_json(&p, &t).await?;
    let create = |params: SessionParams| {
        serde_json::to_string(&CreateSession {
            mesh_id: mesh.id.clone(),
            params,
        })
        .expect("json")
    };
    let body = create(SessionParams {
        tol: Some(-1.0),
        ..SessionParams::default()
    });
    expect(
        post("/v1/sessions", &body, json_ct).await?,
        422,
        "invalid_params",
    )
    .await;
    // deliberately malformed (an unknown parameter, which the typed body
    // cannot write): raw JSON
    let body = json!({"mesh_id": mesh.id, "params": {"bogus": 1}}).to_string();
    expect(
        post("/v1/sessions", &body, json_ct).await?,
        422,
        "invalid_params",
    )
    .await;
    let s = c.create_session(&mesh.id, SessionParams::default()).await?;
    let auth = format!("Bearer {}", s.token);
    let sess = |m: reqwest::Method, tail: &str| {
        http.request(m, format!("{base}/v1/sessions/{}{tail}", s.id))
            .header("authorization", auth.clone())
    };
    expect(
        http.get(format!("{base}/v1/sessions/nope"))
            .bearer_auth(&s.token)
            .send()
            .await?,
        404,
        "session_not_found",
    )
    .await;
    // drag before constraints are ready
    let drag = DragRequest {
        handle: 0.into(),
        delta: DeltaJson::translate([0.0, 0.0, 1.0]),
        max_iters: None,
    };
    expect(
        sess(reqwest::Method::POST, "/drag")
            .json(&drag)
            .send()
            .await?,
        409,
        "not_ready",
    )
    .await;
    expect(
        sess(reqwest::Method::POST, "/undo").send().await?,
        409,
        "not_ready",
    )
    .await;
    // constraints: out-of-range vertex, malformed, invalid JSON
    let bad = ConstraintsSpec::new(
        VertexSet::indices([0, 1, 999]),
        vec![HandleSpec::named("h", VertexSet::indices([30]))],
    );
    expect(
        sess(reqwest::Method::PUT, "/constraints")
            .json(&bad)
            .send()
            .await?,
        422,
        "vertex_out_of_range",
    )
    .await;
    // deliberately malformed (an unknown member): raw JSON
    let bad = json!({"fixed": [0], "handles": [{"name": "h", "vertices": [30]}], "extra": true});
    expect(
        sess(reqwest::Method::PUT, "/constraints")
            .json(&bad)
            .send()
            .await?,
        422,
        "invalid_constraints",
    )
    .await;
    let r = sess(reqwest::Method::PUT, "/constraints")
        .header("content-type", json_ct)
        .body("[")
        .send()
        .await?;
    expect(r, 400, "invalid_json").await;
    s.set_constraints(&grid_constraints(6)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    // deltas: NaN (JS sends null, Python sends NaN), unknown handle, bad rotation
    let r = sess(reqwest::Method::POST, "/drag")
        .json(&DragRequest {
            handle: 0.into(),
            // JavaScript's NaN, as `JSON.stringify` writes it: null
            delta: DeltaJson {
                translate: Some([Some(0.0), None, Some(1.0)]),
                ..DeltaJson::default()
            },
            max_iters: None,
        })
        .send()
        .await?;
    expect(r, 422, "non_finite").await;
    let r = sess(reqwest::Method::POST, "/drag")
        .header("content-type", json_ct)
        .body(r#"{"handle": 0, "translate": [0, NaN, 1]}"#)
        .send()
        .await?;
    expect(r, 422, "non_finite").await;
    let r = sess(reqwest::Method::POST, "/drag")
        .json(&DragRequest {
            handle: 0.into(),
            delta: DeltaJson {
                quaternion: Some([Some(0.0); 4]),
                ..DeltaJson::default()
            },
            max_iters: None,
        })
        .send()
        .await?;
    expect(r, 422, "non_finite").await;
    let r = sess(reqwest::Method::POST, "/drag")
        .json(&DragRequest {
            handle: "nope".into(),
            ..drag.clone()
        })
        .send()
        .await?;
    expect(r, 422, "unknown_handle").await;
    let r = sess(reqwest::Method::POST, "/drag")
        // deliberately malformed (a misspelt member): raw JSON
        .json(&json!({"handle": 0, "translation": [0, 0, 1]}))
        .send()
        .await?;
    expect(r, 400, "invalid_json").await;
    expect(
        sess(reqwest::Method::POST, "/redo").send().await?,
        409,
        "nothing_to_redo",
    )
    .await;
    expect(
        sess(reqwest::Method::GET, "/export?format=fbx")
            .send()
            .await?,
        415,
        "unsupported_format",
    )
    .await;
    Ok(())
}

#[tokio::test]
async fn session_limit_is_503() -> Result<(), ClientError> {
    let (base, _state) = start(Config {
        max_sessions: 1,
        ..Config::default()
    })
    .await;
    let c = Client::new(&base);
    let (p, t) = grid(4);
    let mesh = c.upload_json(&p, &t).await?;
    let _s = c.create_session(&mesh.id, SessionParams::default()).await?;
    match c.create_session(&mesh.id, SessionParams::default()).await {
        Err(ClientError::Api {
            status: 503, code, ..
        }) => assert_eq!(code, ErrorCode::TooManySessions),
        other => panic!("expected 503, got {other:?}"),
    }
    Ok(())
}

/// A server instance on the SQLite store in `dir` (the second one sees the
/// first one's sessions as stored, not live).
async fn start_on_store(dir: &std::path::Path) -> String {
    let config = Config {
        in_memory: false,
        data_dir: dir.to_path_buf(),
        ..Config::default()
    };
    let store = dend_server::recover::open_store(&config).expect("store");
    dend_testkit::server::start_with_store(config, store)
        .await
        .0
}

/// A wrong or missing token on a stored session that is not live is
/// refused before the session is re-opened: no rest operators, no actor,
/// no factor build (the server's metrics show none); the right token
/// re-opens it.
#[tokio::test]
async fn a_wrong_token_on_a_stored_session_starts_no_work() -> Result<(), ClientError> {
    let dir = tempfile::tempdir().expect("tempdir");
    let first = Client::new(&start_on_store(dir.path()).await);
    let (p, t) = grid(8);
    let mesh = first.upload_json(&p, &t).await?;
    let s = first
        .create_session(&mesh.id, SessionParams::default())
        .await?;
    s.set_constraints(&grid_constraints(8)).await?;
    s.wait_ready(Duration::from_secs(60)).await?;

    let base = start_on_store(dir.path()).await;
    let second = Client::new(&base);
    let http = reqwest::Client::new();
    let url = format!("{base}/v1/sessions/{}", s.id);
    let wrong = http.get(&url).bearer_auth("not-the-token").send().await?;
    expect(wrong, 403, "forbidden").await;
    let missing = http.get(&url).send().await?;
    expect(missing, 401, "missing_token").await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    assert_eq!(second.metric("dend_sessions").await?, Some(0.0));
    assert_eq!(second.metric("dend_factor_cache_builds").await?, Some(0.0));

    let right = http.get(&url).bearer_auth(&s.token).send().await?;
    assert_eq!(right.status().as_u16(), 200);
    assert_eq!(second.metric("dend_sessions").await?, Some(1.0));
    Ok(())
}

/// An invalid upload says why once: the validation's or the reader's reason
/// appears a single time in the message, and the message does not repeat
/// what the code `invalid_mesh` says ("invalid mesh: invalid mesh: …").
#[tokio::test]
async fn an_invalid_upload_says_why_once() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let http = reqwest::Client::new();
    for (path, body, ct, cause) in [
        (
            "/v1/meshes",
            r#"{"positions": [[0,0,0],[1,0,0],[0,1,0]], "triangles": [[0,1,7]]}"#,
            "application/json",
            "refers to vertex 7",
        ),
        (
            "/v1/meshes?format=off",
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
            "application/octet-stream",
            "refers to vertex 7",
        ),
        (
            "/v1/meshes?format=obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
            "application/octet-stream",
            "refers to vertex 8",
        ),
        (
            "/v1/meshes?format=off",
            "OFF\n3 1 0\n0 0 0\n",
            "application/octet-stream",
            "unexpected end of file",
        ),
    ] {
        let r = http
            .post(format!("{base}{path}"))
            .header("content-type", ct)
            .body(body)
            .send()
            .await?;
        assert_eq!(r.status().as_u16(), 422, "{path} {body}");
        let e: Value = r.json().await.expect("JSON error body");
        assert_eq!(e["code"], "invalid_mesh", "{e}");
        let message = e["message"].as_str().unwrap_or_default();
        assert_eq!(message.matches(cause).count(), 1, "{e}");
        assert!(!message.contains("invalid mesh"), "{e}");
    }
    Ok(())
}
