//! The OpenAPI document lists exactly the router's routes, and every route
//! of the table is really served (no fallback 404, no 405).

use std::collections::BTreeSet;

use axum::body::Body;
use axum::http::{Method, Request};
use dend_server::{app, AppState, Config, ROUTES};
use tower::ServiceExt;

/// (method, path) pairs under `paths:` of api/openapi.yaml.
fn openapi_routes() -> BTreeSet<(String, String)> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/api/openapi.yaml");
    let text = std::fs::read_to_string(path).expect("api/openapi.yaml");
    let mut in_paths = false;
    let mut current = None;
    let mut out = BTreeSet::new();
    for line in text.lines() {
        if !line.starts_with(' ') && !line.is_empty() {
            in_paths = line.trim_end() == "paths:";
            continue;
        }
        if !in_paths {
            continue;
        }
        if let Some(p) = line.strip_prefix("  /") {
            current = Some(format!("/{}", p.trim_end().trim_end_matches(':')));
        } else if let Some(m) = line.strip_prefix("    ").filter(|l| !l.starts_with(' ')) {
            let m = m.trim_end().trim_end_matches(':');
            if ["get", "post", "put", "delete", "patch"].contains(&m) {
                out.insert((m.to_owned(), current.clone().expect("method under a path")));
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
        let uri = path.replace("{id}", "x");
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
    use dend::deform::{DetailTerm, Formulation, Mode, Params};
    let doc = openapi_doc();
    let props = &doc["components"]["schemas"]["Params"]["properties"];
    let documented = keys(props);
    let serialised = serde_json::to_value(Params::default()).expect("params JSON");
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
