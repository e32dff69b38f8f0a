//! `GET /v1/sessions/{id}/export?format=glb&as=skeleton[&corrective=false]`
//! and `…&as=skeleton-animation`: the session's glTF/GLB as uploaded with
//! poses fitted onto its rig (`dend::rig::export_skeleton`): the current
//! pose in the joint nodes, or one keyframe per named pose in save order
//! (the current pose, named `pose`, when none is saved); each pose's
//! corrective as a morph target unless `corrective=false`.
//!
//! The response reports the fit in headers: `X-Dend-Fit-Residual-Max` and
//! `X-Dend-Fit-Residual-Mean` (the skinned poses without their correctives
//! against the solved ones, as fractions of the rest bounding-box
//! diagonal: the largest and the mean over the poses),
//! `X-Dend-Fit-Poses` (how many poses) and, when the skin's weights had to
//! be normalised, `X-Dend-Warning`.

use axum::http::{header, HeaderName, HeaderValue};
use axum::response::{IntoResponse, Response};

use crate::error::ApiError;
use crate::session::SessionHandle;
use crate::state::AppState;
use dend::mesh::io::Format;

/// `corrective=`: absent, `true`/`1` keep the correctives, `false`/`0`
/// leaves them out; anything else is 400 `invalid_query`.
pub(crate) fn corrective(q: Option<&str>) -> Result<bool, ApiError> {
    match q {
        None | Some("true" | "1") => Ok(true),
        Some("false" | "0") => Ok(false),
        Some(other) => Err(ApiError::InvalidQuery(format!(
            "corrective={other} (true or false)"
        ))),
    }
}

/// The skeleton export of session `s` as `format` (glb or gltf).
pub(crate) async fn export(
    st: &AppState,
    s: &SessionHandle,
    format: Format,
    animation: bool,
    corrective: bool,
) -> Result<Response, ApiError> {
    let named = if animation {
        s.named_poses().await?
    } else {
        std::sync::Arc::new(Vec::new())
    };
    let poses = crate::morph_export::poses_to_export(s, &named).await?;
    let asset = crate::meshes::stored_asset(st, &s.info().mesh_id)
        .await?
        .ok_or_else(|| {
            ApiError::NotSkinned(
                "a skeleton export needs a skinned mesh uploaded as glTF/GLB (this one was not kept as a file)"
                    .into(),
            )
        })?;
    let out = tokio::task::spawn_blocking(move || {
        let refs: Vec<(String, &[[f64; 3]])> = poses
            .iter()
            .map(|(n, p)| (n.clone(), p.as_slice()))
            .collect();
        dend::rig::export_skeleton(&asset, &refs, animation, corrective, format)
            .map_err(|e| crate::error::rig_error(&e, e.to_string()))
    })
    .await
    .map_err(|e| ApiError::Internal(e.to_string()))??;
    let ct = match format {
        Format::Gltf => "model/gltf+json",
        _ => "model/gltf-binary",
    };
    let max = out.fits.iter().map(|f| f.residual.max).fold(0.0, f64::max);
    let mean = out.fits.iter().map(|f| f.residual.mean).sum::<f64>() / out.fits.len().max(1) as f64;
    let mut resp = ([(header::CONTENT_TYPE, ct)], out.bytes).into_response();
    let h = resp.headers_mut();
    let mut set = |name: &'static str, value: String| {
        if let Ok(v) = HeaderValue::from_str(&value) {
            let _ = h.insert(HeaderName::from_static(name), v);
        }
    };
    set("x-dend-fit-residual-max", format!("{max:e}"));
    set("x-dend-fit-residual-mean", format!("{mean:e}"));
    set("x-dend-fit-poses", out.fits.len().to_string());
    if out.renormalised > 0 {
        set(
            "x-dend-warning",
            format!(
                "{} vertices' skin weights did not sum to one and were normalised",
                out.renormalised
            ),
        );
    }
    Ok(resp)
}
