//! `GET /v1/sessions/{id}/export?format=glb&as=morph-targets[&animation=1]`:
//! the session's mesh file as uploaded (glTF/GLB) plus one morph target
//! per named pose, in save order, or the current pose (named `pose`) when
//! none is saved (`dend::mesh::asset::Asset::export_morph_targets`).

use axum::http::header;
use axum::response::{IntoResponse, Response};

use crate::error::ApiError;
use crate::session::SessionHandle;
use crate::state::AppState;
use dend::mesh::asset::MorphExportError;
use dend::mesh::io::Format;

/// What an export's `as=` asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ExportAs {
    /// `pose` (the default): the current pose as a mesh file.
    Pose,
    /// `morph-targets`: one morph target per named pose.
    MorphTargets,
    /// `skeleton`: the current pose fitted onto the rig
    /// (`crate::skeleton_export`).
    Skeleton,
    /// `skeleton-animation`: every named pose fitted, one keyframe each.
    SkeletonAnimation,
}

/// The export's `as=`; any other value is 422 `unsupported_export`.
pub(crate) fn wanted(export_as: Option<&str>) -> Result<ExportAs, ApiError> {
    match export_as {
        None | Some("pose") => Ok(ExportAs::Pose),
        Some("morph-targets") => Ok(ExportAs::MorphTargets),
        Some("skeleton") => Ok(ExportAs::Skeleton),
        Some("skeleton-animation") => Ok(ExportAs::SkeletonAnimation),
        Some(other) => Err(ApiError::UnsupportedExport(format!(
            "unknown export `as={other}` (pose, morph-targets, skeleton or skeleton-animation)"
        ))),
    }
}

/// The morph-target export of session `s` as `format` (glb or gltf).
pub(crate) async fn export(
    st: &AppState,
    s: &SessionHandle,
    format: Format,
    animation: bool,
) -> Result<Response, ApiError> {
    let poses = poses_to_export(s, &s.named_poses().await?).await?;
    let asset = crate::meshes::stored_asset(st, &s.info().mesh_id)
        .await?
        .ok_or_else(|| {
            ApiError::UnsupportedExport(
                "morph targets need a mesh uploaded as glTF/GLB (this one was not kept as a file)"
                    .into(),
            )
        })?;
    let bytes = tokio::task::spawn_blocking(move || {
        let refs: Vec<(String, &[[f64; 3]])> = poses
            .iter()
            .map(|(n, p)| (n.clone(), p.as_slice()))
            .collect();
        asset
            .export_morph_targets(&refs, animation, format)
            .map_err(|e| match e {
                MorphExportError::NotGltf { .. } => ApiError::UnsupportedExport(e.to_string()),
                MorphExportError::Pose(e) => ApiError::Internal(e.to_string()),
            })
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    let ct = match format {
        Format::Gltf => "model/gltf+json",
        _ => "model/gltf-binary",
    };
    Ok(([(header::CONTENT_TYPE, ct)], bytes).into_response())
}

/// The poses an export writes: the session's `named` poses in order, or
/// its current pose as "pose" when it has none.
pub(crate) async fn poses_to_export(
    s: &SessionHandle,
    named: &[crate::store::NamedPose],
) -> Result<Vec<(String, Vec<[f64; 3]>)>, ApiError> {
    Ok(if named.is_empty() {
        vec![("pose".into(), s.pose().await?.positions.to_vec())]
    } else {
        named
            .iter()
            .map(|p| (p.name.clone(), p.pose.clone()))
            .collect()
    })
}
