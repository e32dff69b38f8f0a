//! Session routes (their authentication is `auth.rs`).

use axum::extract::rejection::{BytesRejection, JsonRejection};
use axum::extract::{FromRequestParts, State};
use axum::http::request::Parts;
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use bytes::Bytes;
use nalgebra::{Quaternion, Unit, UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::auth::{bearer, check_token};
use crate::error::{ApiError, Path, Query};
use crate::meshes::parse_format;
use crate::session::{Delta, PoseSnapshot, SessionHandle};
use crate::state::AppState;
use dend::deform::Params;
use dend::mesh::io::Format;
pub use dend_protocol::ws::{CreateSessionOf, DeltaJson, DragRequest};
use dend_protocol::ConstraintsAccepted;

/// Looks a live session up, re-opening a stored one
/// ([`SessionRegistry::find`](crate::registry::SessionRegistry::find)).
pub(crate) async fn find(
    st: &AppState,
    id: &str,
    token: Option<&str>,
) -> Result<SessionHandle, ApiError> {
    st.registry.find(id, token).await
}

/// Extractor: the session named in the path, opened by the bearer token.
pub struct Authed(pub SessionHandle);

impl FromRequestParts<AppState> for Authed {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, st: &AppState) -> Result<Self, ApiError> {
        let Path(id) = Path::<String>::from_request_parts(parts, st).await?;
        let token = bearer(&parts.headers);
        let s = find(st, &id, token).await?;
        check_token(&s, token)?;
        s.touch();
        Ok(Authed(s))
    }
}

/// `POST /v1/sessions`.
pub async fn create(
    State(st): State<AppState>,
    body: Result<Json<CreateSessionOf<serde_json::Value>>, JsonRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let Json(req) = body?;
    let params_json = if req.params.is_null() {
        serde_json::json!({})
    } else {
        req.params
    };
    let params: Params = serde_json::from_value(params_json.clone())
        .map_err(|e| ApiError::InvalidParams(e.to_string()))?;
    params.validate()?;
    let created = st.registry.create(req.mesh_id, params).await?;
    Ok((StatusCode::CREATED, Json(created)))
}

/// `GET /v1/sessions/{id}`.
pub async fn info(Authed(s): Authed) -> impl IntoResponse {
    Json(s.info())
}

/// `DELETE /v1/sessions/{id}`.
pub async fn remove(State(st): State<AppState>, Authed(s): Authed) -> StatusCode {
    st.registry.close(&s).await;
    StatusCode::NO_CONTENT
}

/// `PUT /v1/sessions/{id}/constraints`: 202 while the factor builds. An
/// `If-Match: <constraints_revision>` header (quoted or not) makes the edit
/// conditional: 409 `stale_constraints` when another edit came first.
pub async fn set_constraints(
    State(st): State<AppState>,
    Authed(s): Authed,
    headers: HeaderMap,
    body: Result<Json<serde_json::Value>, JsonRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let if_revision = match headers.get(header::IF_MATCH) {
        None => None,
        Some(v) => Some(
            v.to_str()
                .ok()
                .map(|t| t.trim().trim_matches('"'))
                .and_then(|t| t.parse::<u64>().ok())
                .ok_or_else(|| {
                    ApiError::InvalidConstraints(
                        "If-Match must be a constraints revision (an integer)".into(),
                    )
                })?,
        ),
    };
    let Json(spec) = body?;
    let spec = crate::meshes::resolve_groups(&st, &s.info().mesh_id, spec).await?;
    let state = s.set_constraints(spec, if_revision).await?;
    let revision = s.info().constraints_revision;
    Ok((
        StatusCode::ACCEPTED,
        [(header::ETAG, format!("\"{revision}\""))],
        Json(ConstraintsAccepted {
            state,
            constraints_revision: revision,
        }),
    ))
}

fn finite<const N: usize>(v: &[Option<f64>; N], what: &str) -> Result<[f64; N], ApiError> {
    let mut out = [0.0; N];
    for (i, x) in v.iter().enumerate() {
        match x {
            Some(x) if x.is_finite() => out[i] = *x,
            _ => {
                return Err(ApiError::NonFinite(format!(
                    "`{what}[{i}]` is NaN, infinite or null"
                )))
            }
        }
    }
    Ok(out)
}

/// Validates a drag's delta (finite, non-degenerate, not both
/// rotations) and converts it.
pub fn to_delta(d: &DeltaJson) -> Result<Delta, ApiError> {
    let t = match &d.translate {
        Some(t) => finite(t, "translate")?,
        None => [0.0; 3],
    };
    let rotation = match (&d.rotate, &d.quaternion) {
        (Some(_), Some(_)) => {
            return Err(ApiError::InvalidJson(
                "give `rotate` or `quaternion`, not both".into(),
            ));
        }
        (Some(r), None) => {
            let axis = finite(&r.axis, "rotate.axis")?;
            let [degrees] = finite(&[r.degrees], "rotate.degrees")?;
            let axis = Unit::try_new(Vector3::from(axis), 1e-12)
                .ok_or_else(|| ApiError::NonFinite("`rotate.axis` has zero length".into()))?;
            UnitQuaternion::from_axis_angle(&axis, degrees.to_radians())
        }
        (None, Some(q)) => {
            let q = finite(q, "quaternion")?;
            let q = Quaternion::new(q[3], q[0], q[1], q[2]);
            if q.norm() < 1e-12 {
                return Err(ApiError::NonFinite("`quaternion` has zero length".into()));
            }
            UnitQuaternion::from_quaternion(q)
        }
        (None, None) => UnitQuaternion::identity(),
    };
    Ok(Delta {
        rotation,
        translation: t,
    })
}

/// Parses a JSON body; the non-standard literals `NaN`/`Infinity` (as
/// Python's `json.dumps` writes them) get `non_finite`, other errors
/// `invalid_json`.
pub(crate) fn parse_json<T: serde::de::DeserializeOwned>(body: &[u8]) -> Result<T, ApiError> {
    serde_json::from_slice(body).map_err(|e| {
        let text = String::from_utf8_lossy(body);
        if e.is_syntax() && (text.contains("NaN") || text.contains("Infinity")) {
            ApiError::NonFinite(format!("NaN or Infinity in the JSON ({e})"))
        } else {
            ApiError::InvalidJson(e.to_string())
        }
    })
}

pub use dend_protocol::PoseJson;

pub(crate) fn pose_json(p: PoseSnapshot) -> Json<PoseJson> {
    let h = p.header;
    Json(PoseJson {
        revision: h.revision,
        ack_seq: h.ack_seq,
        iteration: h.iteration,
        converged: h.converged,
        settled: h.settled,
        objective: h.objective.is_finite().then_some(h.objective),
        positions: p.positions.to_vec(),
    })
}

/// `POST /v1/sessions/{id}/drag`: applies a delta and solves.
pub async fn drag(
    Authed(s): Authed,
    body: Result<Bytes, BytesRejection>,
) -> Result<Json<PoseJson>, ApiError> {
    let req: DragRequest = parse_json(&body?)?;
    let delta = to_delta(&req.delta)?;
    let max_iters = req.max_iters.unwrap_or(s.params().max_iters).max(1);
    Ok(pose_json(
        s.drag_solve(&req.handle, delta, max_iters).await?,
    ))
}

/// `GET /v1/sessions/{id}/pose`: JSON, or raw f32 LE xyz with
/// `Accept: application/octet-stream`.
pub async fn pose(Authed(s): Authed, headers: HeaderMap) -> Result<Response, ApiError> {
    let p = s.pose().await?;
    let binary = headers
        .get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.contains("application/octet-stream"));
    if !binary {
        return Ok(pose_json(p).into_response());
    }
    let mut buf = Vec::with_capacity(p.positions.len() * 12);
    for v in p.positions.iter() {
        for c in v {
            buf.extend_from_slice(&(*c as f32).to_le_bytes());
        }
    }
    Ok((
        [
            (header::CONTENT_TYPE, "application/octet-stream".to_owned()),
            (
                header::HeaderName::from_static("x-dend-revision"),
                p.header.revision.to_string(),
            ),
            (
                header::HeaderName::from_static("x-dend-vertex-count"),
                p.positions.len().to_string(),
            ),
        ],
        buf,
    )
        .into_response())
}

/// `?format=` of an export.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExportQuery {
    /// `obj` (default), `off`, `ply`, `stl`, `gltf` or `glb`.
    pub format: Option<String>,
    /// `pose` (default), `morph-targets` (see `morph_export`), `skeleton`
    /// or `skeleton-animation` (see `skeleton_export`).
    #[serde(rename = "as")]
    pub export_as: Option<String>,
    /// With `as=morph-targets`: 1 adds the animation through the poses.
    pub animation: Option<u8>,
    /// With `as=skeleton[-animation]`: `false` (or 0) leaves the
    /// corrective morph targets out.
    pub corrective: Option<String>,
    /// With `as=pose`: `current` (default) or `rest`, the mesh's rest
    /// positions (what a client joining a posed session measures motions
    /// from, e.g. a joint's head carried by its region).
    pub pose: Option<String>,
}

/// `GET /v1/sessions/{id}/export?format=obj|off|ply|stl|gltf|glb`: the
/// current pose as a mesh file (PLY and STL binary little-endian). A mesh
/// uploaded as glTF/GLB (OBJ, PLY) exported as glTF/GLB (OBJ, PLY) keeps the file's
/// layout and attributes (`dend::mesh::asset::Asset::export`); otherwise the
/// welded surface is written as a plain mesh.
pub async fn export(
    State(st): State<AppState>,
    Authed(s): Authed,
    Query(q): Query<ExportQuery>,
) -> Result<Response, ApiError> {
    let format = parse_format(
        &q.format
            .unwrap_or_else(|| "obj".into())
            .to_ascii_lowercase(),
    )?;
    use crate::morph_export::ExportAs;
    let rest_pose = match q.pose.as_deref() {
        None | Some("current") => false,
        Some("rest") => true,
        Some(other) => {
            return Err(ApiError::InvalidQuery(format!(
                "pose={other} (current or rest)"
            )))
        }
    };
    let how = crate::morph_export::wanted(q.export_as.as_deref())?;
    if rest_pose && how != ExportAs::Pose {
        return Err(ApiError::InvalidQuery(
            "pose=rest goes with as=pose (the other exports write the named poses)".into(),
        ));
    }
    match how {
        ExportAs::Pose => {}
        ExportAs::MorphTargets => {
            return crate::morph_export::export(&st, &s, format, q.animation == Some(1)).await
        }
        how @ (ExportAs::Skeleton | ExportAs::SkeletonAnimation) => {
            let corrective = crate::skeleton_export::corrective(q.corrective.as_deref())?;
            let animation = how == ExportAs::SkeletonAnimation;
            return crate::skeleton_export::export(&st, &s, format, animation, corrective).await;
        }
    }
    let rest = s.rest().clone();
    let positions = if rest_pose {
        std::sync::Arc::new(rest.mesh().positions().to_vec())
    } else {
        s.pose().await?.positions
    };
    let asset = crate::meshes::stored_asset(&st, &s.info().mesh_id).await?;
    let (bytes, dropped) = tokio::task::spawn_blocking(move || match asset {
        Some(a) => a
            .export(&positions, format)
            .map(|b| (b, a.dropped_by(format)))
            .map_err(|e| ApiError::Internal(e.to_string())),
        None => Ok((
            dend::mesh::io::to_bytes(&positions, rest.mesh().triangles(), format),
            Vec::new(),
        )),
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    let ct = match format {
        Format::Glb => "model/gltf-binary".to_owned(),
        Format::Gltf => "model/gltf+json".to_owned(),
        f => format!("model/{}", f.extension()),
    };
    let mut res = ([(header::CONTENT_TYPE, ct)], bytes).into_response();
    if let Some(w) = export_warnings(format, &dropped) {
        res.headers_mut()
            .insert(header::HeaderName::from_static(EXPORT_WARNINGS), w);
    }
    Ok(res)
}

/// The export header that lists what the file leaves out: a JSON array of
/// `{code, message}` (`attributes_dropped`), absent when nothing is.
pub const EXPORT_WARNINGS: &str = "dend-warnings";

/// The `Dend-Warnings` value of an export as `format` that leaves out the
/// asset's `dropped` attributes (none: no header).
fn export_warnings(format: Format, dropped: &[String]) -> Option<header::HeaderValue> {
    if dropped.is_empty() {
        return None;
    }
    let ext = format.extension();
    let w = [crate::meshes::MeshWarning {
        code: "attributes_dropped".into(),
        message: format!(
            "{} keeps positions and triangles only: this mesh's {} are not in the file; \
             export in the format it was uploaded as to keep them",
            ext.to_ascii_uppercase(),
            dropped.join(", ")
        ),
    }];
    // JSON escapes anything outside printable ASCII a header cannot hold
    let json = serde_json::to_string(&w).ok()?;
    let mut ascii = String::with_capacity(json.len());
    for c in json.chars() {
        if c.is_ascii() {
            ascii.push(c);
        } else {
            for u in c.encode_utf16(&mut [0; 2]) {
                ascii.push_str(&format!("\\u{u:04x}"));
            }
        }
    }
    header::HeaderValue::from_str(&ascii).ok()
}

/// `POST /v1/sessions/{id}/undo`.
pub async fn undo(Authed(s): Authed) -> Result<Json<PoseJson>, ApiError> {
    Ok(pose_json(s.undo().await?))
}

/// `POST /v1/sessions/{id}/redo`.
pub async fn redo(Authed(s): Authed) -> Result<Json<PoseJson>, ApiError> {
    Ok(pose_json(s.redo().await?))
}

/// `POST /v1/sessions/{id}/reset`.
pub async fn reset(Authed(s): Authed) -> Result<Json<PoseJson>, ApiError> {
    Ok(pose_json(s.reset().await?))
}
