//! `GET /v1/sessions/{id}/curvature`: per-vertex curvatures of the current
//! pose, for the editor's colour map (mean curvature `H`, Gaussian
//! curvature `K`, and `G = H² − K`, the density of the total curvature's
//! gradient term, paper eq. (12)). Computed by the same operators as
//! `dend curvature` (`dend::operators::Operators`), in the mesh's own units.

use axum::Json;
pub use dend_protocol::Curvature as CurvatureJson;

use crate::error::ApiError;
use crate::sessions::Authed;
use dend::operators::Operators;

/// `GET /v1/sessions/{id}/curvature`.
pub async fn curvature(Authed(s): Authed) -> Result<Json<CurvatureJson>, ApiError> {
    let pose = s.pose().await?;
    let rest = s.rest().clone();
    let revision = pose.header.revision;
    let out = tokio::task::spawn_blocking(move || {
        let mesh = rest
            .mesh()
            .with_positions(pose.positions.to_vec())
            .map_err(|e| ApiError::Internal(format!("pose as a mesh: {e}")))?;
        let op = Operators::new(&mesh);
        let (s, s2) = (op.scale, op.scale * op.scale);
        Ok::<_, ApiError>(CurvatureJson {
            revision,
            mean: op.mean_curvature.iter().map(|h| h / s).collect(),
            gaussian: op.gaussian_curvature.iter().map(|k| k / s2).collect(),
            g: op.g.iter().map(|g| g / s2).collect(),
        })
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    Ok(Json(out))
}
