//! Mesh routes: upload (JSON or a mesh file), generate, info.
//!
//! glTF/GLB, OBJ and PLY uploads are read as assets (`dend::mesh::asset`): the
//! stored mesh is the welded surface, and the uploaded bytes are kept
//! ([`StoredAsset`]) so that export writes the pose in the file's layout.

use std::sync::Arc;

use axum::extract::rejection::BytesRejection;
use axum::extract::State;
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::IntoResponse;
use axum::Json;
use bytes::Bytes;
use serde::Deserialize;

use crate::error::{ApiError, Path, Query};
use crate::state::AppState;
use crate::store::StoredAsset;
use dend::deform::ConstraintsSpec;
use dend::mesh::asset::Asset;
use dend::mesh::gen::{self, ShapeSpec};
use dend::mesh::io::gltf::{Container, Sidecars};
use dend::mesh::io::{self, Format, IoError};
use dend::mesh::Mesh;

/// `?format=` of an upload.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FormatQuery {
    /// `json`, `obj`, `off`, `ply`, `stl`, `gltf` or `glb`.
    pub format: Option<String>,
}

pub use dend_protocol::{
    AssetGroup, AssetJoint, AssetSkeleton, AssetSummary, MeshInfo, MeshWarning,
};

/// A bounding-box diagonal above this (in the file's units) is no real
/// asset's: a light year in metres is 1e16, a city in millimetres 1e7.
pub const HUGE_EXTENT: f64 = 1e7;
/// A diagonal below this is no real asset's either (10 nm in metres).
pub const TINY_EXTENT: f64 = 1e-8;
/// A centre farther from the origin than this many diagonals: the pose
/// frames and every viewer's GPU hold float32 positions (24-bit mantissa),
/// which keep only `FAR_FROM_ORIGIN × 2⁻²⁴` ≈ 1/1700 of the mesh's size there.
pub const FAR_FROM_ORIGIN: f64 = 1e4;

/// Warnings about a mesh's extent and placement (see the constants): the
/// mesh is valid and accepted, but a viewer is likely to show nothing or a
/// faceted mess, and the editor says why.
pub fn extent_warnings(lo: [f64; 3], hi: [f64; 3]) -> Vec<MeshWarning> {
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let centre = (0..3)
        .map(|k| (0.5 * (hi[k] + lo[k])).powi(2))
        .sum::<f64>()
        .sqrt();
    let far = lo.iter().chain(&hi).fold(0.0f64, |m, x| m.max(x.abs()));
    let mut out = Vec::new();
    let warn = |code: &str, message: String| MeshWarning {
        code: code.into(),
        message,
    };
    if !diag.is_finite() || diag > HUGE_EXTENT {
        out.push(warn(
            "huge_extent",
            format!(
                "the mesh is {diag:.3e} units across (coordinates up to {far:.3e}): no real asset is; \
                 views and exports in float32 may show nothing. Check the file's units or scale it"
            ),
        ));
    } else if diag < TINY_EXTENT {
        out.push(warn(
            "tiny_extent",
            format!("the mesh is {diag:.3e} units across: check the file's units or scale it"),
        ));
    }
    if diag > 0.0 && centre > FAR_FROM_ORIGIN * diag {
        out.push(warn(
            "far_from_origin",
            format!(
                "the mesh's centre is {:.3e} of its sizes from the origin: float32 views and \
                 exports keep too few digits there and show it faceted. Move it nearer the origin",
                centre / diag
            ),
        ));
    }
    out
}

fn info_of(id: String, m: &Mesh, asset: Option<&Asset>) -> MeshInfo {
    let (lo, hi) = m.bounding_box();
    MeshInfo {
        warnings: extent_warnings(lo, hi),
        id,
        vertices: m.num_vertices(),
        triangles: m.num_triangles(),
        bbox: [lo, hi],
        asset: asset.map(|a| {
            let i = a.info();
            let skinned = i.gltf.as_ref().is_some_and(|g| g.skinned);
            let (skeleton, skin_error) = match skinned.then(|| a.skeleton()) {
                Some(Ok(sk)) => (Some(skeleton_of(sk.info())), None),
                Some(Err(e)) => (None, Some(e.to_string())),
                None => (None, None),
            };
            AssetSummary {
                skeleton,
                skin_error,
                format: i.format.extension().to_owned(),
                name: i.name,
                asset_vertices: i.asset_vertices,
                attributes: i.attributes,
                groups: i
                    .groups
                    .into_iter()
                    .map(|g| AssetGroup {
                        kind: g.kind.name().to_owned(),
                        name: g.name,
                        index: g.index,
                        primitive: g.primitive,
                        triangles: g.triangles,
                        vertices: g.vertices,
                    })
                    .collect(),
            }
        }),
    }
}

fn skeleton_of(s: dend::rig::SkeletonInfo) -> AssetSkeleton {
    AssetSkeleton {
        skin: s.skin,
        joints: s
            .joints
            .into_iter()
            .map(|j| AssetJoint {
                name: j.name,
                index: j.index,
                node: j.node,
                parent: j.parent,
                head: j.head,
                vertices: j.vertices,
                region: j.region,
            })
            .collect(),
        renormalised_vertices: s.renormalised_vertices,
    }
}

/// The asset kept for mesh `id`, read again from its stored bytes.
pub(crate) async fn stored_asset(st: &AppState, id: &str) -> Result<Option<Asset>, ApiError> {
    let key = id.to_owned();
    let Some(stored) = st.store_call(move |s| s.get_asset(&key)).await? else {
        return Ok(None);
    };
    tokio::task::spawn_blocking(move || {
        let f = parse_format(&stored.format)?;
        Asset::read_bytes(&stored.bytes, f, Sidecars::Refuse)
            .map(Some)
            .map_err(|e| ApiError::Internal(format!("stored asset: {e}")))
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))?
}

/// A constraints spec (JSON) with its `{"group": …}` and `{"joint": …}`
/// vertex sets resolved
/// to index lists on mesh `mesh_id`'s asset (`dend::mesh::asset::groups`):
/// what `PUT …/constraints` and the WebSocket's `set_constraints` pass on, so
/// the session, its store and its revival see index lists only. A spec that
/// names no group (or does not parse: the session reports that) is returned
/// as it is; a group the asset does not have, or any group on a mesh
/// without an asset, is 422 `unknown_group` listing the asset's groups.
pub(crate) async fn resolve_groups(
    st: &AppState,
    mesh_id: &str,
    spec: serde_json::Value,
) -> Result<serde_json::Value, ApiError> {
    let Ok(parsed) = serde_json::from_value::<ConstraintsSpec>(spec.clone()) else {
        return Ok(spec);
    };
    if !dend::deform::names_groups(&parsed) {
        return Ok(spec);
    }
    let asset = stored_asset(st, mesh_id).await?;
    let resolved =
        tokio::task::spawn_blocking(move || dend::deform::resolve_groups(asset.as_ref(), &parsed))
            .await
            .map_err(|e| ApiError::Internal(e.to_string()))??;
    serde_json::to_value(resolved).map_err(|e| ApiError::Internal(format!("constraints: {e}")))
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
        "model/gltf-binary" => "glb",
        "model/gltf+json" => "gltf",
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

/// A parsed upload: the welded mesh, and the asset when its layout is kept.
type Parsed = (Mesh, Option<(Asset, StoredAsset)>);

fn parse_mesh(format: &str, body: &[u8], max_vertices: usize) -> Result<Parsed, ApiError> {
    if let Ok(f @ (Format::Gltf | Format::Glb | Format::Obj | Format::Ply)) = parse_format(format) {
        let asset = Asset::read_bytes(body, f, Sidecars::Refuse).map_err(|e| match e {
            IoError::Mesh(e) => ApiError::InvalidMesh(e.to_string()),
            e => ApiError::InvalidMesh(format!("{f}: {e}")),
        })?;
        if asset.positions().len() > max_vertices {
            return Err(ApiError::TooManyVertices {
                got: asset.positions().len(),
                limit: max_vertices,
            });
        }
        let stored = StoredAsset {
            format: f.extension().to_owned(),
            bytes: body.to_vec(),
        };
        return Ok((asset.mesh().clone(), Some((asset, stored))));
    }
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
        .map(|m| (m, None))
        .map_err(|e| ApiError::InvalidMesh(e.to_string()))
}

/// A mesh file format by name (`obj`, `off`, `ply`, `stl`, `gltf`, `glb`).
pub(crate) fn parse_format(name: &str) -> Result<Format, ApiError> {
    Format::ALL
        .into_iter()
        .find(|f| f.extension() == name)
        .ok_or_else(|| {
            ApiError::UnsupportedFormat(format!(
                "`{name}` (use json, obj, off, ply, stl, gltf or glb)"
            ))
        })
}

async fn store_mesh(
    st: &AppState,
    (mesh, asset): Parsed,
) -> Result<(StatusCode, Json<MeshInfo>), ApiError> {
    check_vertices(st, mesh.num_vertices())?;
    let id = crate::auth::new_id();
    let info = info_of(id.clone(), &mesh, asset.as_ref().map(|(a, _)| a));
    let key = id.clone();
    let (admission, max) = (st.mesh_admission.clone(), st.config.max_meshes);
    // the limit check and the insert in one blocking call, under one lock:
    // two uploads racing for the last slot cannot both pass
    let count = st
        .store_call(move |s| {
            let _admitted = admission.lock();
            if s.mesh_count()? >= max {
                return Ok(None);
            }
            // the file before the mesh: a stored mesh always finds its asset
            if let Some((_, stored)) = &asset {
                s.put_asset(&key, stored)?;
            }
            s.put_mesh(&key, Arc::new(mesh))?;
            s.mesh_count().map(Some)
        })
        .await?
        .ok_or(ApiError::TooManyMeshes(max))?;
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
    let parsed = tokio::task::spawn_blocking(move || parse_mesh(&format, &body, max_v))
        .await
        .map_err(|e| ApiError::Internal(e.to_string()))??;
    store_mesh(&st, parsed).await
}

/// `POST /v1/meshes/generate`: a procedural test shape,
/// `{"shape": "bar", "params": {"nu": .., "nv": .., "size": .., ...}}`.
/// The answer is the mesh's info, plus, for a shape with a default edit
/// (the creature, the limb), that edit as `constraints` (index lists, ready
/// for `PUT …/constraints`). The rigged `limb` is stored as its skinned
/// GLB, as an upload of that file would be (its skeleton listed, joint
/// selectors and skeleton exports).
pub async fn generate(
    State(st): State<AppState>,
    body: Result<Json<ShapeSpec>, axum::extract::rejection::JsonRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let Json(spec) = body?;
    let max_v = st.config.max_vertices;
    let (parsed, constraints) = tokio::task::spawn_blocking(move || {
        let invalid = |e: gen::GenError| ApiError::InvalidParams(e.to_string());
        // a rigged shape is kept as its skinned file, as an upload would be
        if let Some(bytes) = gen::generate_asset(&spec, Container::Glb).map_err(invalid)? {
            let parsed = parse_mesh("glb", &bytes, max_v)?;
            let defaults = match &parsed.1 {
                Some((asset, _)) => Some(
                    dend::rig::sample::limb_constraints(asset)
                        .map_err(|e| ApiError::Internal(e.to_string()))?,
                ),
                None => None,
            };
            return Ok((parsed, defaults));
        }
        let mesh = gen::generate(&spec).map_err(invalid)?;
        let defaults =
            (spec.shape == gen::Shape::Creature).then(|| gen::creature_constraints(&mesh));
        Ok::<_, ApiError>(((mesh, None), defaults))
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    let (status, Json(info)) = store_mesh(&st, parsed).await?;
    let mut answer = serde_json::to_value(info).map_err(|e| ApiError::Internal(e.to_string()))?;
    if let (Some(c), Some(obj)) = (constraints, answer.as_object_mut()) {
        let c = serde_json::to_value(c).map_err(|e| ApiError::Internal(e.to_string()))?;
        obj.insert("constraints".into(), c);
    }
    Ok((status, Json(answer)))
}

/// `DELETE /v1/meshes/{id}`: 204; 409 `mesh_in_use` while live or stored
/// sessions use the mesh, 404 when there is none. Frees a `max_meshes`
/// slot, and evicts the mesh's rest operators and cached factors.
pub async fn remove(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let live = st.registry.on_mesh(&id);
    let key = id.clone();
    let stored = st
        .store_call(move |s| s.list_sessions())
        .await?
        .into_iter()
        .filter(|r| r.mesh_id == key)
        .count();
    if live + stored > 0 {
        return Err(ApiError::MeshInUse {
            mesh: id,
            sessions: live.max(stored),
        });
    }
    let key = id.clone();
    let (found, count) = st
        .store_call(move |s| Ok((s.delete_mesh(&key)?, s.mesh_count()?)))
        .await?;
    if !found {
        return Err(ApiError::MeshNotFound(id));
    }
    st.metrics.meshes.set(count as i64);
    let evicted = st.rests.evict(&st.cache, &id);
    tracing::info!(mesh = %id, evicted, "mesh deleted");
    Ok(StatusCode::NO_CONTENT)
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
    let asset = stored_asset(&st, &id).await?;
    Ok(Json(info_of(id, &m, asset.as_ref())))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn codes(lo: [f64; 3], hi: [f64; 3]) -> Vec<String> {
        extent_warnings(lo, hi)
            .into_iter()
            .map(|w| w.code)
            .collect()
    }

    #[test]
    fn extent_warnings_name_absurd_extents_and_placements_only() {
        // real assets in metres, millimetres, and a scan far (but not too
        // far) from its origin: nothing to say
        assert!(codes([-1.0; 3], [1.0; 3]).is_empty());
        assert!(codes([0.0; 3], [1800.0, 400.0, 600.0]).is_empty());
        assert!(codes([1e3; 3], [1e3 + 1.0; 3]).is_empty());
        // a stray 1e30 coordinate
        assert_eq!(codes([-1.0; 3], [1e30, 1.0, 1.0]), ["huge_extent"]);
        assert_eq!(codes([-1.0; 3], [f64::INFINITY, 1.0, 1.0]), ["huge_extent"]);
        assert_eq!(codes([0.0; 3], [1e-9; 3]), ["tiny_extent"]);
        // a unit part placed a hundred thousand units out
        assert_eq!(codes([1e5; 3], [1e5 + 1.0; 3]), ["far_from_origin"]);
        // the messages say what was measured
        let w = extent_warnings([-1.0; 3], [1e30, 1.0, 1.0]);
        assert!(w[0].message.contains("1.000e30"), "{}", w[0].message);
    }
}
