//! Every error of every route in `api/openapi.yaml` is JSON `{code,
//! message}`, axum's own extractor rejections included: each route is
//! called with a malformed path parameter, a malformed query string, a
//! malformed JSON body, a body of the wrong content type, no upgrade (the
//! WebSocket route) and a method it does not serve.

use axum::body::Body;
use axum::http::{header, Method, Request, Response};
use axum::Router;
use dend_server::{app, AppState, Config};
use serde_json::Value;
use tower::ServiceExt;

/// One route of the OpenAPI document: method, path, whether it documents
/// query parameters and a request body.
struct Route {
    method: String,
    path: String,
    has_query: bool,
    has_body: bool,
}

fn openapi_routes() -> Vec<Route> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/api/openapi.yaml");
    let text = std::fs::read_to_string(path).expect("api/openapi.yaml");
    let docs = yaml_rust2::YamlLoader::load_from_str(&text).expect("valid YAML");
    let paths = docs[0]["paths"].as_hash().expect("paths: a mapping");
    let mut out = Vec::new();
    for (path, item) in paths {
        let path = path.as_str().expect("a path string");
        for (method, op) in item.as_hash().expect("a path item") {
            let method = method.as_str().expect("a method");
            if !["get", "post", "put", "delete", "patch"].contains(&method) {
                continue;
            }
            let has_query = op["parameters"]
                .as_vec()
                .is_some_and(|ps| ps.iter().any(|p| p["in"].as_str() == Some("query")));
            out.push(Route {
                method: method.to_uppercase(),
                path: path.to_owned(),
                has_query,
                has_body: !op["requestBody"].is_badvalue(),
            });
        }
    }
    assert!(
        out.len() >= 10,
        "routes read from the document: {}",
        out.len()
    );
    out
}

/// Sends one request; returns the status and, for a status ≥ 400, checks
/// the body is JSON with exactly a non-empty string `code` and `message`
/// and returns the code.
async fn call(
    router: &Router,
    method: &str,
    uri: &str,
    token: Option<&str>,
    body: Option<(&str, &str)>,
) -> (u16, Option<String>) {
    let mut req = Request::builder()
        .method(Method::from_bytes(method.as_bytes()).expect("method"))
        .uri(uri);
    if let Some(t) = token {
        req = req.header(header::AUTHORIZATION, format!("Bearer {t}"));
    }
    let req = match body {
        Some((ct, b)) => req
            .header(header::CONTENT_TYPE, ct)
            .body(Body::from(b.to_owned())),
        None => req.body(Body::empty()),
    }
    .expect("request");
    let resp: Response<Body> = router.clone().oneshot(req).await.expect("response");
    let status = resp.status().as_u16();
    if status < 400 {
        return (status, None);
    }
    let what = format!("{method} {uri} → {status}");
    let ct = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_owned();
    let bytes = axum::body::to_bytes(resp.into_body(), 1 << 20)
        .await
        .expect("body");
    let text = String::from_utf8_lossy(&bytes);
    assert!(
        ct.starts_with("application/json"),
        "{what}: content type `{ct}`, body {text}"
    );
    let v: Value =
        serde_json::from_slice(&bytes).unwrap_or_else(|e| panic!("{what}: not JSON ({e}): {text}"));
    let obj = v
        .as_object()
        .unwrap_or_else(|| panic!("{what}: not an object: {v}"));
    let mut keys: Vec<_> = obj.keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(keys, ["code", "message"], "{what}: {v}");
    for k in keys {
        assert!(
            obj[k].as_str().is_some_and(|s| !s.is_empty()),
            "{what}: `{k}` is not a non-empty string: {v}"
        );
    }
    (status, Some(obj["code"].as_str().expect("code").to_owned()))
}

/// A small mesh and a session on it (ids and the session's token), made
/// through the router itself.
async fn mesh_and_session(router: &Router) -> (String, String, String) {
    let json = |resp: Response<Body>| async move {
        let b = axum::body::to_bytes(resp.into_body(), 1 << 20)
            .await
            .expect("body");
        serde_json::from_slice::<Value>(&b).expect("JSON")
    };
    let post = |uri: &str, body: String| {
        Request::post(uri)
            .header(header::CONTENT_TYPE, "application/json")
            .body(Body::from(body))
            .expect("request")
    };
    let r = router
        .clone()
        .oneshot(post(
            "/v1/meshes/generate",
            r#"{"shape": "flag", "params": {"nu": 4, "nv": 4}}"#.into(),
        ))
        .await
        .expect("response");
    assert_eq!(r.status().as_u16(), 201);
    let mesh = json(r).await["id"].as_str().expect("mesh id").to_owned();
    let r = router
        .clone()
        .oneshot(post("/v1/sessions", format!(r#"{{"mesh_id": "{mesh}"}}"#)))
        .await
        .expect("response");
    assert_eq!(r.status().as_u16(), 201);
    let s = json(r).await;
    (
        mesh,
        s["id"].as_str().expect("session id").to_owned(),
        s["token"].as_str().expect("token").to_owned(),
    )
}

#[tokio::test]
async fn every_route_answers_malformed_requests_with_json_errors() {
    let router = app(AppState::new(Config::default()).expect("state"));
    let mut codes = std::collections::BTreeSet::new();
    for r in openapi_routes() {
        let templated = r.path.contains("{id}");
        // a fresh mesh and session per route: a DELETE may remove them
        let (mesh, session, token) = mesh_and_session(&router).await;
        let id = if r.path.starts_with("/v1/sessions/") {
            &session
        } else {
            &mesh
        };
        let good = r.path.replace("{id}", id);
        let tok = Some(token.as_str());
        let what = format!("{} {}", r.method, r.path);

        // a path parameter that is not UTF-8
        if templated {
            let bad = r.path.replace("{id}", "%FF%FE");
            let (status, code) = call(&router, &r.method, &bad, tok, None).await;
            assert!(status >= 400, "{what} with a non-UTF-8 id: {status}");
            codes.insert(code.expect("a code"));
        }
        // an unknown query parameter and an invalid percent escape
        let (status, code) = call(
            &router,
            &r.method,
            &format!("{good}?bogus=%FF&format=%"),
            tok,
            None,
        )
        .await;
        if r.has_query {
            assert!(status >= 400, "{what} with a malformed query: {status}");
        }
        codes.extend(code);
        // a body that is not JSON, sent as JSON
        let (status, code) = call(
            &router,
            &r.method,
            &good,
            tok,
            Some(("application/json", r#"{"mesh_id": [1, "#)),
        )
        .await;
        if r.has_body {
            assert!(status >= 400, "{what} with a malformed body: {status}");
        }
        codes.extend(code);
        // a JSON body of the wrong content type
        let (status, code) = call(
            &router,
            &r.method,
            &good,
            tok,
            Some(("text/x-nothing", r#"{"nothing": true}"#)),
        )
        .await;
        if r.has_body {
            assert!(status >= 400, "{what} with a wrong content type: {status}");
        }
        codes.extend(code);
        // a method the route does not serve (TRACE: no route serves it)
        let (status, code) = call(&router, "TRACE", &good, tok, None).await;
        assert_eq!(status, 405, "{what}: TRACE");
        codes.extend(code);
    }
    // the rejections that used to be axum's plain text are among the codes
    for c in [
        "invalid_path",
        "invalid_query",
        "invalid_json",
        "unsupported_media_type",
        "invalid_upgrade",
        "method_not_allowed",
    ] {
        assert!(codes.contains(c), "no route answered `{c}`: {codes:?}");
    }
}
