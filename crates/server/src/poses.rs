//! Named-pose routes (`/v1/sessions/{id}/poses…`): save the settled pose
//! under a name, list, read, rename, delete and restore (see
//! `session::poses`).

use axum::extract::rejection::BytesRejection;
use axum::extract::FromRequestParts;
use axum::http::request::Parts;
use axum::http::StatusCode;
use axum::response::IntoResponse;
use axum::Json;
use bytes::Bytes;
pub use dend_protocol::{NamedPose as NamedPoseJson, PoseList, RenamePose as PoseName, SavePose};

use crate::auth::{bearer, check_token};
use crate::error::{ApiError, Path};
use crate::session::{pose_list, PoseInfo, SessionHandle};
use crate::sessions::{find, parse_json, pose_json, Authed, PoseJson};
use crate::state::AppState;

/// Extractor: the session and the pose name of the path, the session
/// opened by the bearer token (as `sessions::Authed`).
pub struct AuthedPose(pub SessionHandle, pub String);

impl FromRequestParts<AppState> for AuthedPose {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, st: &AppState) -> Result<Self, ApiError> {
        let Path((id, name)) = Path::<(String, String)>::from_request_parts(parts, st).await?;
        let token = bearer(&parts.headers);
        let s = find(st, &id, token).await?;
        check_token(&s, token)?;
        s.touch();
        Ok(AuthedPose(s, name))
    }
}

/// `GET /v1/sessions/{id}/poses`.
pub async fn list(Authed(s): Authed) -> Result<Json<PoseList>, ApiError> {
    let poses = s.named_poses().await?;
    Ok(Json(PoseList {
        poses: pose_list(&poses),
    }))
}

/// `POST /v1/sessions/{id}/poses`: saves the settled pose (201).
pub async fn save(
    Authed(s): Authed,
    body: Result<Bytes, BytesRejection>,
) -> Result<impl IntoResponse, ApiError> {
    let req: SavePose = parse_json(&body?)?;
    Ok((
        StatusCode::CREATED,
        Json(s.save_pose(&req.name, req.replace).await?),
    ))
}

/// `GET /v1/sessions/{id}/poses/{name}`.
pub async fn get(AuthedPose(s, name): AuthedPose) -> Result<Json<NamedPoseJson>, ApiError> {
    let poses = s.named_poses().await?;
    let (index, p) = poses
        .iter()
        .enumerate()
        .find(|(_, p)| p.name == name)
        .ok_or_else(|| ApiError::PoseNotFound(format!("no pose named `{name}`")))?;
    let info = pose_list(&poses).swap_remove(index);
    Ok(Json(NamedPoseJson {
        info,
        positions: p.pose.clone(),
    }))
}

/// `PATCH /v1/sessions/{id}/poses/{name}`: renames.
pub async fn rename(
    AuthedPose(s, name): AuthedPose,
    body: Result<Bytes, BytesRejection>,
) -> Result<Json<PoseInfo>, ApiError> {
    let req: PoseName = parse_json(&body?)?;
    s.rename_pose(&name, &req.name).await?;
    let poses = s.named_poses().await?;
    pose_list(&poses)
        .into_iter()
        .find(|p| p.name == req.name)
        .map(Json)
        .ok_or_else(|| ApiError::PoseNotFound(format!("no pose named `{}`", req.name)))
}

/// `DELETE /v1/sessions/{id}/poses/{name}` (204).
pub async fn remove(AuthedPose(s, name): AuthedPose) -> Result<StatusCode, ApiError> {
    s.delete_pose(&name).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// `POST /v1/sessions/{id}/poses/{name}/restore`: the named pose becomes
/// the current one (an undo step).
pub async fn restore(AuthedPose(s, name): AuthedPose) -> Result<Json<PoseJson>, ApiError> {
    Ok(pose_json(s.restore_pose(&name).await?))
}
