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
