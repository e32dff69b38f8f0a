//! Mesh routes: upload (JSON or a mesh file), generate, info.

use std::sync::Arc;

use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use bytes::Bytes;
use serde::Deserialize;

use super::error::ApiError;
use super::AppState;
use dend::mesh::gen::{self, ShapeSpec};
use dend::mesh::io::{self, Format};
use dend::mesh::Mesh;

/// `?format=` of an upload.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FormatQuery {
    /// `json`, `obj`, `off`, `ply` or `stl`.
    pub format: Option<String>,
}

pub use dend_protocol::MeshInfo;

fn info_of(id: String, m: &Mesh) -> MeshInfo {
    let (lo, hi) = m.bounding_box();
    MeshInfo {
        id,
        vertices: m.num_vertices(),
        triangles: m.num_triangles(),
        bbox: [lo, hi],
    }
}

/// A new random 128-bit id, hex.
pub(crate) fn new_id() -> String {
    let b: [u8; 16] = rand::random();
    hex::encode(b)
}

fn format_of(q: &FormatQuery, headers: &HeaderMap) -> Result<String, ApiError> {
    if let Some(f) = &q.format {
        return Ok(f.to_ascii_lowercase());
    }
    let ct = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    let mime = ct
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    Ok(match mime.as_str() {
        "application/json" => "json",
        "model/obj" | "text/x-obj" => "obj",
        "model/off" | "text/x-off" => "off",
        "model/ply" | "application/ply" | "text/x-ply" => "ply",
        "model/stl" | "application/sla" | "model/x.stl-binary" => "stl",
        "" => {
            return Err(ApiError::UnsupportedFormat(
                "no Content-Type and no ?format=".into(),
            ))
        }
        other => {
            return Err(ApiError::UnsupportedFormat(format!(
                "Content-Type `{other}`"
            )))
        }
    }
    .to_owned())
}

fn check_vertices(st: &AppState, n: usize) -> Result<(), ApiError> {
    if n > st.config.max_vertices {
        return Err(ApiError::TooManyVertices {
            got: n,
            limit: st.config.max_vertices,
        });
    }
    Ok(())
}

fn parse_mesh(format: &str, body: &[u8], max_vertices: usize) -> Result<Mesh, ApiError> {
    let raw = match format {
        "json" => io::parse_json(body).map_err(|e| ApiError::InvalidJson(e.to_string()))?,
        other => {
            let f = parse_format(other)?;
            io::parse_bytes(body, f).map_err(|e| ApiError::InvalidMesh(format!("{f}: {e}")))?
        }
    };
    if raw.positions.len() > max_vertices {
        return Err(ApiError::TooManyVertices {
            got: raw.positions.len(),
            limit: max_vertices,
        });
    }
    raw.into_mesh()
        .map_err(|e| ApiError::InvalidMesh(e.to_string()))
}

/// A mesh file format by name (`obj`, `off`, `ply`, `stl`).
pub(crate) fn parse_format(name: &str) -> Result<Format, ApiError> {
    Format::ALL
        .into_iter()
        .find(|f| f.extension() == name)
        .ok_or_else(|| {
            ApiError::UnsupportedFormat(format!("`{name}` (use json, obj, off, ply or stl)"))
        })
}

async fn store_mesh(st: &AppState, mesh: Mesh) -> Result<(StatusCode, Json<MeshInfo>), ApiError> {
    check_vertices(st, mesh.num_vertices())?;
    if st.store_call(|s| s.mesh_count()).await? >= st.config.max_meshes {
        return Err(ApiError::TooManyMeshes(st.config.max_meshes));
    }
    let id = new_id();
    let info = info_of(id.clone(), &mesh);
    let key = id.clone();
    let count = st
        .store_call(move |s| {
            s.put_mesh(&key, Arc::new(mesh))?;
            s.mesh_count()
        })
        .await?;
    st.metrics.meshes.set(count as i64);
    Ok((StatusCode::CREATED, Json(info)))
}

/// `POST /v1/meshes`: body = mesh file or JSON `{positions, triangles}`.
pub async fn upload(
    State(st): State<AppState>,
    Query(q): Query<FormatQuery>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let format = format_of(&q, &headers)?;
    let body = body.map_err(|r| match ApiError::from(r) {
        ApiError::PayloadTooLarge(_) => ApiError::PayloadTooLarge(st.config.max_upload_bytes),
        e => e,
    })?;
    let max_v = st.config.max_vertices;
    let mesh = tokio::task::spawn_blocking(move || parse_mesh(&format, &body, max_v))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))??;
    store_mesh(&st, mesh).await
}

/// `POST /v1/meshes/generate`: a procedural test shape,
/// `{"shape": "bar", "params": {"nu": .., "nv": .., "size": .., ...}}`.
pub async fn generate(
    State(st): State<AppState>,
    body: Result<Json<ShapeSpec>, axum::extract::rejection::JsonRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let Json(spec) = body?;
    let mesh = tokio::task::spawn_blocking(move || gen::generate(&spec))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))?
        .map_err(|e| ApiError::InvalidParams(e.to_string()))?;
    store_mesh(&st, mesh).await
}

/// `GET /v1/meshes/{id}`.
pub async fn info(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<MeshInfo>, ApiError> {
    let key = id.clone();
    let m = st
        .store_call(move |s| s.get_mesh(&key))
        .await?
        .ok_or_else(|| ApiError::MeshNotFound(id.clone()))?;
    Ok(Json(info_of(id, &m)))
}
