//! The reference web client (`web/`), served at `/`; the JavaScript client
//! package's modules (`clients/js/src`) at `/js/dend-client/`, which the
//! editor imports; and the package's three.js example at `/examples/three/`.
//!
//! The files are embedded in the binary (so `dend serve` works from any
//! directory and in the container image). Setting `DEND_WEB_DIR` serves
//! them from that directory instead, read on every request, for editing
//! the client without rebuilding (`web/js/dend-client` is a link to the
//! package's `src/`, `web/examples` to its `examples/`). These routes are
//! outside the `/v1` API and so not in `ROUTES` / `api/openapi.yaml`.
//!
//! three.js is not embedded (it is the example's npm dependency, not
//! dend's): `/vendor/three/{file}` serves the ES module build of the
//! three.js installed by `npm ci` in `clients/js` (or in `$DEND_THREE_DIR`),
//! and answers 404 with what to install when there is none.

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
    ("js/drop.js", include_bytes!("../../../web/js/drop.js")),
    ("js/frame.js", include_bytes!("../../../web/js/frame.js")),
    ("js/gizmo.js", include_bytes!("../../../web/js/gizmo.js")),
    ("js/guide.js", include_bytes!("../../../web/js/guide.js")),
    (
        "js/interact.js",
        include_bytes!("../../../web/js/interact.js"),
    ),
    ("js/keys.js", include_bytes!("../../../web/js/keys.js")),
    ("js/main.js", include_bytes!("../../../web/js/main.js")),
    ("js/mesh.js", include_bytes!("../../../web/js/mesh.js")),
    (
        "js/outliner.js",
        include_bytes!("../../../web/js/outliner.js"),
    ),
    ("js/poses.js", include_bytes!("../../../web/js/poses.js")),
    (
        "js/regions.js",
        include_bytes!("../../../web/js/regions.js"),
    ),
    (
        "js/renderer.js",
        include_bytes!("../../../web/js/renderer.js"),
    ),
    ("js/rig.js", include_bytes!("../../../web/js/rig.js")),
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
    (
        "js/dend-client/index.js",
        include_bytes!("../../../clients/js/src/index.js"),
    ),
    (
        "js/dend-client/api.js",
        include_bytes!("../../../clients/js/src/api.js"),
    ),
    (
        "js/dend-client/errors.js",
        include_bytes!("../../../clients/js/src/errors.js"),
    ),
    (
        "js/dend-client/frame.js",
        include_bytes!("../../../clients/js/src/frame.js"),
    ),
    (
        "js/dend-client/session.js",
        include_bytes!("../../../clients/js/src/session.js"),
    ),
    (
        "js/dend-client/three/index.js",
        include_bytes!("../../../clients/js/src/three/index.js"),
    ),
    (
        "examples/three/index.html",
        include_bytes!("../../../clients/js/examples/three/index.html"),
    ),
];

/// Where the three.js build is looked for: `$DEND_THREE_DIR`, else the
/// `npm ci` of `clients/js` in the source tree this binary was built from.
fn three_dir() -> PathBuf {
    match std::env::var_os("DEND_THREE_DIR") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../clients/js/node_modules/three/build"),
    }
}

/// A file of the three.js ES module build (`three.module.js` and the
/// modules it imports), or 404 saying how to get one.
fn three(name: &str) -> Response {
    let valid = name.ends_with(".js")
        && name.starts_with("three.")
        && name.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'.');
    if !valid {
        return (StatusCode::NOT_FOUND, format!("no file `{name}`")).into_response();
    }
    let path = three_dir().join(name);
    match std::fs::read(&path) {
        Ok(body) => (
            [
                (header::CONTENT_TYPE, content_type(name)),
                (header::CACHE_CONTROL, "max-age=3600"),
            ],
            body,
        )
            .into_response(),
        Err(e) => (
            StatusCode::NOT_FOUND,
            format!(
                "three.js is not installed here ({}: {e}): run `npm ci` in clients/js, \
                 or point DEND_THREE_DIR at a three.js `build` folder",
                path.display()
            ),
        )
            .into_response(),
    }
}

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

/// `/`, `/style.css`, `/js/{file}`, `/js/dend-client/{path}`,
/// `/examples/three/` and `/vendor/three/{file}`.
pub fn router<S: Clone + Send + Sync + 'static>() -> Router<S> {
    Router::new()
        .route(
            "/js/dend-client/{*path}",
            get(|Path(p): Path<String>| async move { file(&format!("js/dend-client/{p}")) }),
        )
        .route(
            "/examples/three/",
            get(|| async { file("examples/three/index.html") }),
        )
        .route(
            "/examples/three/index.html",
            get(|| async { file("examples/three/index.html") }),
        )
        .route(
            "/vendor/three/{file}",
            get(|Path(f): Path<String>| async move { three(&f) }),
        )
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

    /// The files under `dir` (links followed), as `prefix/name` paths.
    fn walk(dir: &std::path::Path, prefix: &str, out: &mut Vec<String>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let e = e.unwrap();
            let name = format!("{prefix}/{}", e.file_name().to_string_lossy());
            if e.path().is_dir() {
                walk(&e.path(), &name, out);
            } else if !name.ends_with(".d.ts") {
                out.push(name);
            }
        }
    }

    #[test]
    fn embedded_table_lists_every_client_file() {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../web");
        let mut on_disk = vec!["index.html".to_owned(), "style.css".to_owned()];
        // js/dend-client and examples are links into clients/js
        walk(&root.join("js"), "js", &mut on_disk);
        walk(&root.join("examples"), "examples", &mut on_disk);
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
        assert_eq!(three("../../package.json").status(), StatusCode::NOT_FOUND);
        assert_eq!(three("three.module.js/x").status(), StatusCode::NOT_FOUND);
        assert_eq!(
            content_type("js/dend-client/three/index.js"),
            "text/javascript; charset=utf-8"
        );
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
