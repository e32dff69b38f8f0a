//! The reference web client (`web/`), served at `/`.
//!
//! The files are embedded in the binary (so `dend serve` works from any
//! directory and in the container image). Setting `DEND_WEB_DIR` serves
//! them from that directory instead, read on every request, for editing
//! the client without rebuilding. These routes are outside the `/v1` API
//! and so not in `ROUTES` / `api/openapi.yaml`.

use std::path::PathBuf;

use axum::extract::Path;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;

/// Every served file: (path under `web/`, embedded bytes). A test keeps this
/// equal to the files on disk.
pub const FILES: &[(&str, &[u8])] = &[
    ("index.html", include_bytes!("../../../web/index.html")),
    ("style.css", include_bytes!("../../../web/style.css")),
    ("js/api.js", include_bytes!("../../../web/js/api.js")),
    ("js/app.js", include_bytes!("../../../web/js/app.js")),
    ("js/camera.js", include_bytes!("../../../web/js/camera.js")),
    ("js/frame.js", include_bytes!("../../../web/js/frame.js")),
    ("js/gizmo.js", include_bytes!("../../../web/js/gizmo.js")),
    (
        "js/interact.js",
        include_bytes!("../../../web/js/interact.js"),
    ),
    ("js/keys.js", include_bytes!("../../../web/js/keys.js")),
    ("js/main.js", include_bytes!("../../../web/js/main.js")),
    ("js/mesh.js", include_bytes!("../../../web/js/mesh.js")),
    ("js/poses.js", include_bytes!("../../../web/js/poses.js")),
    (
        "js/regions.js",
        include_bytes!("../../../web/js/regions.js"),
    ),
    (
        "js/renderer.js",
        include_bytes!("../../../web/js/renderer.js"),
    ),
    ("js/select.js", include_bytes!("../../../web/js/select.js")),
    (
        "js/session.js",
        include_bytes!("../../../web/js/session.js"),
    ),
    (
        "js/settings.js",
        include_bytes!("../../../web/js/settings.js"),
    ),
    ("js/socket.js", include_bytes!("../../../web/js/socket.js")),
    (
        "js/zbuffer.js",
        include_bytes!("../../../web/js/zbuffer.js"),
    ),
];

fn content_type(path: &str) -> &'static str {
    match path.rsplit('.').next() {
        Some("html") => "text/html; charset=utf-8",
        Some("css") => "text/css; charset=utf-8",
        Some("js") => "text/javascript; charset=utf-8",
        _ => "application/octet-stream",
    }
}

fn file(path: &str) -> Response {
    let Some((name, embedded)) = FILES.iter().find(|(p, _)| *p == path) else {
        return (StatusCode::NOT_FOUND, format!("no file `{path}`")).into_response();
    };
    let body = match std::env::var_os("DEND_WEB_DIR") {
        Some(dir) => match std::fs::read(PathBuf::from(dir).join(name)) {
            Ok(b) => b,
            Err(e) => return (StatusCode::NOT_FOUND, format!("`{name}`: {e}")).into_response(),
        },
        None => embedded.to_vec(),
    };
    (
        [
            (header::CONTENT_TYPE, content_type(name)),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

/// `/`, `/style.css` and `/js/{file}`.
pub fn router<S: Clone + Send + Sync + 'static>() -> Router<S> {
    Router::new()
        .route("/", get(|| async { file("index.html") }))
        .route("/index.html", get(|| async { file("index.html") }))
        .route("/style.css", get(|| async { file("style.css") }))
        .route(
            "/js/{file}",
            get(|Path(f): Path<String>| async move { file(&format!("js/{f}")) }),
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_table_lists_every_client_file() {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../web");
        let mut on_disk = vec!["index.html".to_owned(), "style.css".to_owned()];
        for e in std::fs::read_dir(root.join("js")).unwrap() {
            on_disk.push(format!("js/{}", e.unwrap().file_name().to_string_lossy()));
        }
        on_disk.sort();
        let mut listed: Vec<String> = FILES.iter().map(|(p, _)| (*p).to_owned()).collect();
        listed.sort();
        assert_eq!(listed, on_disk);
        for (p, b) in FILES {
            assert_eq!(*b, std::fs::read(root.join(p)).unwrap().as_slice(), "{p}");
        }
    }

    #[test]
    fn unknown_file_is_404_and_types_are_right() {
        assert_eq!(file("js/nope.js").status(), StatusCode::NOT_FOUND);
        assert_eq!(file("../Cargo.toml").status(), StatusCode::NOT_FOUND);
        let r = file("index.html");
        assert_eq!(r.status(), StatusCode::OK);
        assert_eq!(
            r.headers()[header::CONTENT_TYPE],
            "text/html; charset=utf-8"
        );
        assert_eq!(content_type("js/app.js"), "text/javascript; charset=utf-8");
    }
}
