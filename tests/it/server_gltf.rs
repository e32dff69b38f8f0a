//! glTF/GLB through the server: uploads by Content-Type or `?format=`, the
//! asset kept by the store (memory and SQLite, across a restart), exports
//! in the asset's layout that pass the Khronos validator, typed 4xx errors.

use std::sync::Arc;
use std::time::Duration;

use dend::mesh::asset::sample::{self, TubeOptions};
use dend::mesh::io::gltf::{Container, GltfAsset, Sidecars};
use dend_client::ws::{ClientMsg, DeltaJson, ServerMsg};
use dend_client::{
    Client, ClientError, ConstraintsSpec, ErrorBody, ErrorCode, GenerateMesh, HandleSpec,
    SessionParams, VertexSet,
};
use dend_server::store::SqliteStore;
use dend_server::Config;
use dend_testkit::assets::{banded_tube_obj, AROUND, RINGS};
use dend_testkit::server::{start, start_with_store};
use serde_json::json;

fn twist() -> ConstraintsSpec {
    ConstraintsSpec::new(
        VertexSet::bbox([-9.0, -9.0, -0.01], [9.0, 9.0, 0.3]),
        vec![HandleSpec::named(
            "top",
            VertexSet::bbox([-9.0, -9.0, 2.7], [9.0, 9.0, 3.1]),
        )],
    )
}

/// Fixes the asset's group `fixed` and drags its group `handle` as `name`.
fn by_groups(fixed: &str, name: &str, handle: &str) -> ConstraintsSpec {
    ConstraintsSpec::new(
        VertexSet::group(fixed),
        vec![HandleSpec::named(name, VertexSet::group(handle))],
    )
}

async fn upload(base: &str, bytes: Vec<u8>, content_type: &str) -> reqwest::Response {
    reqwest::Client::new()
        .post(format!("{base}/v1/meshes"))
        .header("content-type", content_type)
        .body(bytes)
        .send()
        .await
        .unwrap()
}

#[tokio::test]
async fn a_glb_upload_exports_posed_in_its_own_layout() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let input = sample::tube(TubeOptions::default()).unwrap();
    let r = upload(&base, input.clone(), "model/gltf-binary").await;
    assert_eq!(r.status(), 201);
    let info: serde_json::Value = r.json().await.unwrap();
    assert_eq!(info["vertices"], 16 * 13 + 2, "the welded surface");
    assert_eq!(info["asset"]["asset_vertices"], 17 * 15);
    assert_eq!(info["asset"]["format"], "glb");
    assert_eq!(info["asset"]["name"], "skinned tube");
    let c = Client::new(&base);
    let id = info["id"].as_str().unwrap();
    let got: serde_json::Value = reqwest::get(format!("{base}/v1/meshes/{id}"))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(got, info, "GET /v1/meshes/{{id}} reports the same asset");

    let s = c.create_session(id, SessionParams::default()).await?;
    // at rest the export is the uploaded file, byte for byte
    assert_eq!(s.export("glb").await?, input);
    s.set_constraints(&twist()).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let p = s
        .drag(
            "top",
            DeltaJson::axis_angle([0.0, 0.0, 1.0], 60.0),
            Some(30),
        )
        .await?;
    assert!(p.positions.len() == 16 * 13 + 2);
    let rest = GltfAsset::parse(&input, Sidecars::Refuse).unwrap();
    for format in ["glb", "gltf"] {
        let out = s.export(format).await?;
        let a = GltfAsset::parse(&out, Sidecars::Refuse).unwrap();
        assert_eq!(a.positions().len(), rest.positions().len(), "{format}");
        assert_eq!(a.triangles(), rest.triangles());
        assert_eq!(a.summary(), rest.summary());
        assert!(dend_testkit::max_dist(a.positions(), rest.positions()) > 0.2);
        if let Some(r) = dend_testkit::gltf_validator::validate(&out, &format!("posed.{format}")) {
            assert_eq!((r.errors, r.warnings), (0, 0), "{format}: {}", r.messages);
        }
    }
    // other formats get the welded surface
    let obj = s.export("obj").await?;
    let m = dend::mesh::io::read_bytes(&obj, dend::mesh::io::Format::Obj).unwrap();
    assert_eq!(m.num_vertices(), 16 * 13 + 2);
    Ok(())
}

#[tokio::test]
async fn gltf_json_by_query_and_typed_errors() {
    let (base, _state) = start(Config::default()).await;
    let o = TubeOptions {
        container: Container::Json,
        skinned: false,
        ..TubeOptions::default()
    };
    let c = Client::new(&base);
    let info = c
        .upload_file(sample::tube(o).unwrap(), "gltf")
        .await
        .unwrap();
    assert_eq!(info.vertices, 16 * 13 + 2);
    assert_eq!(info.asset.unwrap().asset_vertices, 17 * 15);
    let r = upload(&base, sample::tube(o).unwrap(), "model/gltf+json").await;
    assert_eq!(r.status(), 201);
    // malformed: truncated GLB, a side-car buffer, bad JSON
    let mut glb = sample::tube(TubeOptions::default()).unwrap();
    glb.truncate(100);
    let (mut j, _) = (
        serde_json::from_slice::<serde_json::Value>(&sample::tube(o).unwrap()).unwrap(),
        (),
    );
    j["buffers"][0]["uri"] = json!("tube.bin");
    for (body, ct) in [
        (glb, "model/gltf-binary"),
        (serde_json::to_vec(&j).unwrap(), "model/gltf+json"),
        (b"{\"asset\":".to_vec(), "model/gltf+json"),
    ] {
        let r = upload(&base, body, ct).await;
        assert_eq!(r.status(), 422, "{ct}");
        let e: serde_json::Value = r.json().await.unwrap();
        assert_eq!(e["code"], "invalid_mesh", "{e}");
    }
}

#[tokio::test]
async fn the_sqlite_store_keeps_the_asset_across_a_restart() -> Result<(), ClientError> {
    let dir = tempfile::tempdir().unwrap();
    let input = sample::tube(TubeOptions::default()).unwrap();
    let id = {
        let store = Arc::new(SqliteStore::open(dir.path()).unwrap());
        let (base, _state) = start_with_store(Config::default(), store).await;
        Client::new(&base)
            .upload_file(input.clone(), "glb")
            .await?
            .id
    };
    let store = Arc::new(SqliteStore::open(dir.path()).unwrap());
    let (base, _state) = start_with_store(Config::default(), store).await;
    let c = Client::new(&base);
    let s = c.create_session(&id, SessionParams::default()).await?;
    assert_eq!(s.export("glb").await?, input);
    Ok(())
}

#[tokio::test]
async fn delete_mesh_is_refused_while_a_session_uses_it() -> Result<(), ClientError> {
    let (base, state) = start(Config {
        max_meshes: 1,
        ..Config::default()
    })
    .await;
    let c = Client::new(&base);
    let input = sample::tube(TubeOptions::default()).unwrap();
    let id = c.upload_file(input.clone(), "glb").await?.id;
    // the one slot is taken
    let r = upload(&base, input.clone(), "model/gltf-binary").await;
    assert_eq!(r.status(), 503);
    let s = c.create_session(&id, SessionParams::default()).await?;
    s.set_constraints(&twist()).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    assert!(state.cache.bytes() > 0, "a factor is cached");
    let http = reqwest::Client::new();
    let del = || http.delete(format!("{base}/v1/meshes/{id}")).send();
    let r = del().await.unwrap();
    assert_eq!(r.status(), 409);
    let e: serde_json::Value = r.json().await.unwrap();
    assert_eq!(e["code"], "mesh_in_use");
    s.delete().await?;
    assert_eq!(del().await.unwrap().status(), 204);
    assert_eq!(state.cache.bytes(), 0, "its factors are evicted");
    assert_eq!(del().await.unwrap().status(), 404);
    let r = reqwest::get(format!("{base}/v1/meshes/{id}"))
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
    // the slot is free again
    assert_eq!(
        upload(&base, input, "model/gltf-binary").await.status(),
        201
    );
    Ok(())
}

#[tokio::test]
async fn constraints_by_group_resolve_on_the_uploaded_asset() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let c = Client::new(&base);
    let obj = banded_tube_obj();
    let info = c.upload_file(obj.clone().into_bytes(), "obj").await?;
    // GET /v1/meshes/{id} lists the groups with the vertices they select
    let got: serde_json::Value = reqwest::get(format!("{base}/v1/meshes/{}", info.id))
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let groups: Vec<(String, String, u64)> = got["asset"]["groups"]
        .as_array()
        .unwrap()
        .iter()
        .map(|g| {
            let s = |k: &str| g[k].as_str().unwrap().to_owned();
            (s("kind"), s("name"), g["vertices"].as_u64().unwrap())
        })
        .collect();
    let n = AROUND as u64;
    let want = [
        ("o", "tube", n * RINGS as u64),
        ("g", "base", 2 * n),
        ("g", "mid", (RINGS as u64 - 2) * n),
        ("g", "tip", 2 * n),
        ("g", "end", 2 * n),
    ];
    assert_eq!(
        groups,
        want.map(|(k, g, v)| (k.to_owned(), g.to_owned(), v))
            .to_vec()
    );

    // a session deforms by group: base held, tip moved
    let rest = dend::mesh::asset::Asset::read_bytes(
        obj.as_bytes(),
        dend::mesh::io::Format::Obj,
        Sidecars::Refuse,
    )
    .unwrap();
    let rest = rest.mesh().positions();
    let s = c.create_session(&info.id, SessionParams::default()).await?;
    // deliberately malformed (`{"o": …}` is no group selector, which the
    // typed client cannot write): sent as raw JSON
    let malformed = json!({
        "fixed": {"group": "base"},
        "handles": [{"name": "tip", "vertices": {"group": {"o": "x"}}}]
    });
    let r = reqwest::Client::new()
        .put(format!("{base}/v1/sessions/{}/constraints", s.id))
        .bearer_auth(&s.token)
        .json(&malformed)
        .send()
        .await?;
    assert_eq!(r.status(), 422, "not a group selector");
    let e: ErrorBody = r.json().await?;
    assert_eq!(e.code, ErrorCode::InvalidConstraints);
    s.set_constraints(&by_groups("base", "tip", "tip")).await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let p = s
        .drag("tip", DeltaJson::translate([1.5, 0.0, 0.0]), Some(60))
        .await?;
    let top = (RINGS - 1) as f64;
    let (mut held, mut moved) = (0, 0);
    for (v, (q, r)) in p.positions.iter().zip(rest).enumerate() {
        if r[2] <= 1.0 {
            assert!(
                dend_testkit::max_dist(&[*q], &[*r]) < 1e-9,
                "base vertex {v}"
            );
            held += 1;
        } else if r[2] >= top - 1.0 {
            let want = [r[0] + 1.5, r[1], r[2]];
            assert!(
                dend_testkit::max_dist(&[*q], &[want]) < 1e-6,
                "tip vertex {v}"
            );
            moved += 1;
        }
    }
    assert_eq!((held, moved), (2 * AROUND, 2 * AROUND));

    // an unknown group: 422 unknown_group naming it and listing the groups,
    // over HTTP and over the WebSocket; the session keeps its constraints
    let bad = by_groups("base", "arm", "LeftArm");
    match s.set_constraints(&bad).await {
        Err(ClientError::Api {
            status,
            code,
            message,
        }) => {
            assert_eq!((status, code), (422, ErrorCode::UnknownGroup));
            assert!(
                message.contains("LeftArm") && message.contains("g \"tip\""),
                "{message}"
            );
        }
        other => panic!("{other:?}"),
    }
    let mut ws = s.connect().await?;
    ws.send(&ClientMsg::SetConstraints {
        constraints: bad.clone(),
        if_revision: None,
    })
    .await?;
    let e = ws.event("error").await?;
    assert!(
        matches!(
            &e,
            ServerMsg::Error {
                code: ErrorCode::UnknownGroup,
                ..
            }
        ),
        "{e:?}"
    );
    // over the WebSocket a known group resolves like over HTTP
    let good = by_groups("tip", "b", "base");
    ws.send(&ClientMsg::SetConstraints {
        constraints: good,
        if_revision: None,
    })
    .await?;
    s.wait_ready(Duration::from_secs(60)).await?;
    let stored = s.info().await?;
    let constraints = stored.constraints.expect("constraints");
    let VertexSet::Indices(fixed) = &constraints.fixed else {
        panic!("stored as the index list: {constraints:?}")
    };
    assert_eq!(fixed.len(), 2 * AROUND);
    ws.close().await?;

    // a mesh without an asset has no groups
    let plain = c.generate(&GenerateMesh::new("bar")).await?;
    let s = c
        .create_session(&plain.id, SessionParams::default())
        .await?;
    match s.set_constraints(&bad).await {
        Err(ClientError::Api { status, code, .. }) => {
            assert_eq!((status, code), (422, ErrorCode::UnknownGroup));
        }
        other => panic!("{other:?}"),
    }
    Ok(())
}

#[tokio::test]
async fn an_export_that_drops_the_assets_attributes_says_so() -> Result<(), ClientError> {
    let (base, _state) = start(Config::default()).await;
    let r = upload(
        &base,
        sample::tube(TubeOptions::default()).unwrap(),
        "model/gltf-binary",
    )
    .await;
    let info: serde_json::Value = r.json().await.unwrap();
    let s = Client::new(&base)
        .create_session(info["id"].as_str().unwrap(), SessionParams::default())
        .await?;
    let get = |format: &str| {
        reqwest::Client::new()
            .get(format!(
                "{base}/v1/sessions/{}/export?format={format}",
                s.id
            ))
            .bearer_auth(&s.token)
            .send()
    };
    for format in ["obj", "off", "ply", "stl"] {
        let r = get(format).await.unwrap();
        assert_eq!(r.status(), 200);
        let h = r.headers()["dend-warnings"].to_str().unwrap().to_owned();
        let w: serde_json::Value = serde_json::from_str(&h).unwrap();
        assert_eq!(w[0]["code"], "attributes_dropped", "{format}: {h}");
        let message = w[0]["message"].as_str().unwrap();
        // every attribute the upload reported but positions is named as left out
        for a in info["asset"]["attributes"].as_array().unwrap() {
            let a = a.as_str().unwrap();
            assert!(
                a == "POSITION" || message.contains(a),
                "{format}: {a} in {message}"
            );
        }
        assert!(
            message.contains("TEXCOORD_0") && message.contains("skins"),
            "{message}"
        );
        assert!(
            !message.contains("POSITION"),
            "positions are written: {message}"
        );
    }
    for format in ["glb", "gltf"] {
        let r = get(format).await.unwrap();
        assert_eq!(r.status(), 200);
        assert!(
            r.headers().get("dend-warnings").is_none(),
            "{format} keeps the attributes"
        );
    }
    Ok(())
}

#[tokio::test]
async fn an_absurd_extent_is_accepted_with_a_warning() {
    let (base, _state) = start(Config::default()).await;
    let obj = |far: f64| {
        format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nv {far} 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    };
    let post = |text: String| {
        reqwest::Client::new()
            .post(format!("{base}/v1/meshes?format=obj"))
            .body(text)
            .send()
    };
    let r = post(obj(0.0)).await.unwrap();
    assert_eq!(r.status(), 201);
    let plain: serde_json::Value = r.json().await.unwrap();
    assert!(plain.get("warnings").is_none(), "{plain}");
    let r = post(obj(1e30)).await.unwrap();
    assert_eq!(r.status(), 201, "a valid mesh is still accepted");
    let info: serde_json::Value = r.json().await.unwrap();
    assert_eq!(info["warnings"][0]["code"], "huge_extent", "{info}");
    // and its info says so again
    let again: serde_json::Value =
        reqwest::get(format!("{base}/v1/meshes/{}", info["id"].as_str().unwrap()))
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
    assert_eq!(again["warnings"], info["warnings"]);
}
