//! The OpenAPI document lists exactly the router's routes, and every route
//! of the table is really served (no fallback 404, no 405).

use std::collections::BTreeSet;

use axum::body::Body;
use axum::http::{Method, Request};
use dend_server::{app, AppState, Config, ROUTES};
use tower::ServiceExt;

/// (method, path) pairs under `paths:` of api/openapi.yaml, read by the
/// YAML parser.
fn openapi_routes() -> BTreeSet<(String, String)> {
    let doc = openapi_doc();
    let paths = doc["paths"].as_hash().expect("paths: a mapping");
    let mut out = BTreeSet::new();
    for (path, item) in paths {
        let path = path.as_str().expect("a path string");
        for method in item.as_hash().expect("a path item").keys() {
            let method = method.as_str().expect("a method");
            if ["get", "post", "put", "delete", "patch"].contains(&method) {
                out.insert((method.to_owned(), path.to_owned()));
            }
        }
    }
    out
}

fn router_routes() -> BTreeSet<(String, String)> {
    ROUTES
        .iter()
        .flat_map(|(p, ms)| ms.iter().map(move |m| (m.to_string(), p.to_string())))
        .collect()
}

#[test]
fn openapi_and_router_list_the_same_routes() {
    let doc = openapi_routes();
    let router = router_routes();
    assert!(!doc.is_empty());
    let only_doc: Vec<_> = doc.difference(&router).collect();
    let only_router: Vec<_> = router.difference(&doc).collect();
    assert!(
        only_doc.is_empty() && only_router.is_empty(),
        "only in openapi: {only_doc:?}; only in router: {only_router:?}"
    );
}

#[tokio::test]
async fn every_route_in_the_table_is_served() {
    let state = AppState::new(Config::default()).expect("state");
    let router = app(state);
    for (method, path) in router_routes() {
        let uri = path.replace("{id}", "x").replace("{name}", "x");
        let req = Request::builder()
            .method(Method::from_bytes(method.to_uppercase().as_bytes()).expect("method"))
            .uri(&uri)
            .body(Body::empty())
            .expect("request");
        let resp = router.clone().oneshot(req).await.expect("response");
        assert_ne!(resp.status().as_u16(), 405, "{method} {path}");
        let body = axum::body::to_bytes(resp.into_body(), 1 << 20)
            .await
            .expect("body");
        let text = String::from_utf8_lossy(&body);
        assert!(
            !text.contains("route_not_found"),
            "{method} {path} fell through: {text}"
        );
    }
    // and the fallback does answer unknown routes
    let req = Request::builder()
        .uri("/v2/nope")
        .body(Body::empty())
        .expect("request");
    let resp = router.oneshot(req).await.expect("response");
    assert_eq!(resp.status().as_u16(), 404);
}

/// api/openapi.yaml, parsed by a real YAML parser.
fn openapi_doc() -> yaml_rust2::Yaml {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/api/openapi.yaml");
    let text = std::fs::read_to_string(path).expect("api/openapi.yaml");
    let mut docs = yaml_rust2::YamlLoader::load_from_str(&text).expect("valid YAML");
    assert_eq!(docs.len(), 1, "one YAML document");
    docs.remove(0)
}

/// The keys of a YAML mapping.
fn keys(y: &yaml_rust2::Yaml) -> BTreeSet<String> {
    y.as_hash()
        .expect("a mapping")
        .keys()
        .filter_map(|k| k.as_str().map(str::to_owned))
        .collect()
}

/// The documented `Params` schema has exactly the fields `Params`
/// serialises, and each enum field lists exactly the names its Rust enum
/// accepts (it would have caught `square_lu` and `elastic` missing).
#[test]
fn params_schema_matches_the_params_type() {
    use dend::deform::{Corrections, DetailTerm, Formulation, Mode, ParamsSpec, Preset};
    let doc = openapi_doc();
    let props = &doc["components"]["schemas"]["Params"]["properties"];
    let documented = keys(props);
    // what a client may send: every parameter and the preset
    let spec = ParamsSpec {
        preset: Some(Preset::default()),
        ..ParamsSpec::default()
    };
    let serialised = serde_json::to_value(spec).expect("params JSON");
    let fields: BTreeSet<String> = serialised
        .as_object()
        .expect("an object")
        .keys()
        .cloned()
        .collect();
    assert_eq!(documented, fields, "Params fields");
    let names = |v: Vec<serde_json::Value>| -> BTreeSet<String> {
        v.into_iter()
            .map(|x| x.as_str().expect("a unit variant").to_owned())
            .collect()
    };
    let enum_of = |field: &str| -> BTreeSet<String> {
        props[field]["enum"]
            .as_vec()
            .unwrap_or_else(|| panic!("{field} has an enum"))
            .iter()
            .map(|e| e.as_str().expect("a string").to_owned())
            .collect()
    };
    // every variant, serialised: a new variant without a line here fails
    // to compile through the exhaustive matches below
    let formulations = [
        Formulation::Elastic,
        Formulation::LeastSquares,
        Formulation::Square,
        Formulation::SquareLu,
    ];
    for f in formulations {
        match f {
            Formulation::Elastic
            | Formulation::LeastSquares
            | Formulation::Square
            | Formulation::SquareLu => {}
        }
    }
    assert_eq!(
        enum_of("formulation"),
        names(
            formulations
                .iter()
                .map(|f| serde_json::to_value(f).expect("json"))
                .collect()
        )
    );
    for d in [DetailTerm::Linear, DetailTerm::Nonlinear] {
        match d {
            DetailTerm::Linear | DetailTerm::Nonlinear => {}
        }
    }
    assert_eq!(
        enum_of("detail"),
        names(
            [DetailTerm::Linear, DetailTerm::Nonlinear]
                .iter()
                .map(|d| serde_json::to_value(d).expect("json"))
                .collect()
        )
    );
    for m in [Mode::Default, Mode::Paper] {
        match m {
            Mode::Default | Mode::Paper => {}
        }
    }
    assert_eq!(
        enum_of("mode"),
        names(
            [Mode::Default, Mode::Paper]
                .iter()
                .map(|m| serde_json::to_value(m).expect("json"))
                .collect()
        )
    );
    let corrections = [Corrections::WhileFaster, Corrections::WhileGaining];
    for c in corrections {
        match c {
            Corrections::WhileFaster | Corrections::WhileGaining => {}
        }
    }
    assert_eq!(
        enum_of("corrections"),
        names(
            corrections
                .iter()
                .map(|c| serde_json::to_value(c).expect("json"))
                .collect()
        )
    );
}

/// The Pose schema documents exactly the pose JSON's fields.
#[test]
fn pose_schema_matches_the_pose_json() {
    let doc = openapi_doc();
    let documented = keys(&doc["components"]["schemas"]["Pose"]["properties"]);
    let pose = dend_protocol::PoseJson {
        revision: 0,
        ack_seq: 0,
        iteration: 0,
        converged: false,
        settled: false,
        objective: None,
        positions: vec![],
    };
    let fields: BTreeSet<String> = serde_json::to_value(pose)
        .expect("json")
        .as_object()
        .expect("an object")
        .keys()
        .cloned()
        .collect();
    assert_eq!(documented, fields);
}

/// The JSON keys of a serialised value (an object).
fn json_keys(v: serde_json::Value) -> BTreeSet<String> {
    v.as_object().expect("an object").keys().cloned().collect()
}

/// A schema's `required` list.
fn required(y: &yaml_rust2::Yaml) -> BTreeSet<String> {
    y["required"]
        .as_vec()
        .map(|v| {
            v.iter()
                .map(|s| s.as_str().expect("a name").to_owned())
                .collect()
        })
        .unwrap_or_default()
}

/// A schema's `enum` list.
fn enum_names(y: &yaml_rust2::Yaml) -> BTreeSet<String> {
    y["enum"]
        .as_vec()
        .expect("an enum")
        .iter()
        .map(|s| s.as_str().expect("a name").to_owned())
        .collect()
}

/// The MeshInfo schema documents exactly the fields of the wire type
/// (`dend_protocol::MeshInfo`, its asset summary and groups, each with
/// every optional field present), the groups' required fields are the ones
/// never omitted, and the group kinds are the core's `GroupKind`s.
#[test]
fn mesh_info_schema_matches_the_wire_type() {
    use dend::mesh::asset::groups::GroupKind;
    use dend_protocol::{AssetGroup, AssetSummary, MeshInfo};
    let doc = openapi_doc();
    let schema = &doc["components"]["schemas"]["MeshInfo"];
    let group = AssetGroup {
        kind: "node".into(),
        name: Some("Arm".into()),
        index: Some(1),
        primitive: Some(0),
        triangles: 2,
        vertices: 3,
    };
    let joint = dend_protocol::AssetJoint {
        name: "hip".into(),
        index: 0,
        node: 1,
        parent: Some("root".into()),
        head: [0.0; 3],
        vertices: 3,
        region: vec![0, 1, 2],
    };
    let info = MeshInfo {
        id: "m".into(),
        vertices: 3,
        triangles: 1,
        bbox: [[0.0; 3]; 2],
        asset: Some(AssetSummary {
            format: "glb".into(),
            name: Some("tube".into()),
            asset_vertices: 4,
            attributes: vec!["TEXCOORD_0".into()],
            groups: vec![group.clone()],
            skeleton: Some(dend_protocol::AssetSkeleton {
                skin: 0,
                joints: vec![joint.clone()],
                renormalised_vertices: 0,
            }),
            skin_error: Some("e".into()),
        }),
        warnings: vec![dend_protocol::MeshWarning {
            code: "huge_extent".into(),
            message: "m".into(),
        }],
    };
    let json = serde_json::to_value(&info).expect("json");
    assert_eq!(
        keys(&schema["properties"]),
        json_keys(json.clone()),
        "MeshInfo"
    );
    let asset = &schema["properties"]["asset"];
    assert_eq!(
        keys(&asset["properties"]),
        json_keys(json["asset"].clone()),
        "MeshInfo.asset"
    );
    let items = &asset["properties"]["groups"]["items"];
    assert_eq!(
        keys(&items["properties"]),
        json_keys(serde_json::to_value(&group).expect("json")),
        "MeshInfo.asset.groups"
    );
    let skeleton = &asset["properties"]["skeleton"];
    assert_eq!(
        keys(&skeleton["properties"]),
        json_keys(json["asset"]["skeleton"].clone()),
        "MeshInfo.asset.skeleton"
    );
    assert_eq!(
        keys(&skeleton["properties"]["joints"]["items"]["properties"]),
        json_keys(serde_json::to_value(&joint).expect("json")),
        "MeshInfo.asset.skeleton.joints"
    );
    let bare = AssetGroup {
        name: None,
        index: None,
        primitive: None,
        ..group
    };
    assert_eq!(
        required(items),
        json_keys(serde_json::to_value(&bare).expect("json")),
        "the groups' required fields"
    );
    let kinds = [
        GroupKind::G,
        GroupKind::O,
        GroupKind::Node,
        GroupKind::Mesh,
        GroupKind::Primitive,
    ];
    for k in kinds {
        match k {
            GroupKind::G
            | GroupKind::O
            | GroupKind::Node
            | GroupKind::Mesh
            | GroupKind::Primitive => {}
        }
    }
    assert_eq!(
        enum_names(&items["properties"]["kind"]),
        kinds.iter().map(|k| k.name().to_owned()).collect()
    );
}

/// The Session schema documents exactly the fields of `GET
/// /v1/sessions/{id}` (`SessionInfo`), and its states are `SessionState`'s.
#[test]
fn session_schema_matches_the_session_info() {
    use dend_server::session::{SessionInfo, SessionState};
    let doc = openapi_doc();
    let schema = &doc["components"]["schemas"]["Session"];
    let states = [
        SessionState::Empty,
        SessionState::Building,
        SessionState::Ready,
        SessionState::Failed,
    ];
    for s in states {
        match s {
            SessionState::Empty
            | SessionState::Building
            | SessionState::Ready
            | SessionState::Failed => {}
        }
    }
    let info = SessionInfo {
        id: "s".into(),
        mesh_id: "m".into(),
        state: SessionState::Ready,
        revision: 1,
        handles: vec!["h".into()],
        peers: 0,
        can_undo: false,
        can_redo: false,
        vertices: 3,
        constraints: None,
        constraints_revision: 0,
        warnings: vec![],
        build_stage: Some(dend_protocol::BuildStage::Numeric),
        poses: vec![],
    };
    let json = serde_json::to_value(&info).expect("json");
    assert_eq!(keys(&schema["properties"]), json_keys(json), "Session");
    assert_eq!(
        enum_names(&schema["properties"]["state"]),
        states
            .iter()
            .map(|s| serde_json::to_value(s)
                .expect("json")
                .as_str()
                .expect("a name")
                .to_owned())
            .collect()
    );
}

/// The Error schema documents the error body's fields, and its description
/// names every code the API answers with.
#[test]
fn error_schema_matches_the_error_body() {
    let doc = openapi_doc();
    let schema = &doc["components"]["schemas"]["Error"];
    let body = dend_server::ApiError::Internal(String::new()).body();
    let json = serde_json::to_value(&body).expect("json");
    assert_eq!(keys(&schema["properties"]), json_keys(json), "Error");
    assert_eq!(required(schema), keys(&schema["properties"]), "Error");
    let described = schema["description"].as_str().expect("a description");
    use dend_server::ApiError::*;
    let s = String::new;
    let all = [
        InvalidJson(s()),
        InvalidMesh(s()),
        UnsupportedFormat(s()),
        InvalidParams(s()),
        InvalidConstraints(s()),
        UnsupportedMediaType(s()),
        InvalidQuery(s()),
        InvalidPath(s()),
        InvalidUpgrade(s()),
        MethodNotAllowed(s()),
        VertexOutOfRange(s()),
        UnknownGroup(s()),
        UnknownJoint(s()),
        NotSkinned(s()),
        BadSkin(s()),
        NonFinite(s()),
        MeshNotFound(s()),
        SessionNotFound(s()),
        UnknownHandle(s()),
        RouteNotFound(s()),
        MissingToken,
        WrongToken,
        NotReady(s()),
        MeshInUse {
            mesh: s(),
            sessions: 1,
        },
        HandleGrabbed(s()),
        NothingToUndo(s()),
        NothingToRedo(s()),
        StaleConstraints(s()),
        SolveFailed(s()),
        PayloadTooLarge(1),
        TooManyVertices { got: 2, limit: 1 },
        RateLimited(1),
        TooManySessions(1),
        Overloaded {
            waiting: 2,
            limit: 1,
        },
        Draining,
        TooManyMeshes(1),
        Timeout,
        SessionClosed,
        StoreUnavailable(s()),
        SessionOwnedElsewhere {
            session: s(),
            owner: s(),
            retry_after_ms: 1,
        },
        PoseNotFound(s()),
        PoseExists(s()),
        InvalidPoseName(s()),
        TooManyPoses(s()),
        UnsupportedExport(s()),
        Internal(s()),
    ];
    let mut emitted = std::collections::HashSet::new();
    for e in &all {
        // a new variant fails to compile here until it is listed above
        match e {
            InvalidJson(_)
            | InvalidMesh(_)
            | UnsupportedFormat(_)
            | InvalidParams(_)
            | InvalidConstraints(_)
            | UnsupportedMediaType(_)
            | InvalidQuery(_)
            | InvalidPath(_)
            | InvalidUpgrade(_)
            | MethodNotAllowed(_)
            | VertexOutOfRange(_)
            | UnknownGroup(_)
            | UnknownJoint(_)
            | NotSkinned(_)
            | BadSkin(_)
            | NonFinite(_)
            | MeshNotFound(_)
            | SessionNotFound(_)
            | UnknownHandle(_)
            | RouteNotFound(_)
            | MissingToken
            | WrongToken
            | NotReady(_)
            | MeshInUse { .. }
            | HandleGrabbed(_)
            | NothingToUndo(_)
            | NothingToRedo(_)
            | StaleConstraints(_)
            | SolveFailed(_)
            | PayloadTooLarge(_)
            | TooManyVertices { .. }
            | RateLimited(_)
            | TooManySessions(_)
            | Overloaded { .. }
            | Draining
            | TooManyMeshes(_)
            | Timeout
            | SessionClosed
            | StoreUnavailable(_)
            | SessionOwnedElsewhere { .. }
            | PoseNotFound(_)
            | PoseExists(_)
            | InvalidPoseName(_)
            | TooManyPoses(_)
            | UnsupportedExport(_)
            | Internal(_) => {}
        }
        let (code, status) = e.code_status();
        let status = status.as_u16().to_string();
        assert!(
            described.contains(code.as_str()),
            "the Error schema does not list {code}"
        );
        assert!(described.contains(&status), "no status {status} listed");
        emitted.insert(code);
    }
    // the protocol's codes are exactly the ones the server answers with
    let known: std::collections::HashSet<_> = dend_client::ErrorCode::ALL.iter().cloned().collect();
    assert_eq!(emitted, known);
}
