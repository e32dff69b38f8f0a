//! `GET /v1/presets`: the named parameter sets a session can start from
//! (`dend::deform::Preset`), with every parameter they set, so that clients
//! build their menus from the server and never copy the numbers.

use axum::Json;
use dend::deform::Preset;
pub use dend_protocol::{PresetInfo, PresetList};

use crate::error::ApiError;

/// The preset list.
pub fn list() -> Result<PresetList, ApiError> {
    Ok(PresetList {
        default: Preset::default().name().to_owned(),
        presets: Preset::ALL
            .into_iter()
            .map(|p| {
                Ok(PresetInfo {
                    name: p.name().to_owned(),
                    label: p.label().to_owned(),
                    description: p.description().to_owned(),
                    params: crate::wire::params(&p.params())?,
                })
            })
            .collect::<Result<_, ApiError>>()?,
    })
}

/// `GET /v1/presets`.
pub async fn get() -> Result<Json<PresetList>, ApiError> {
    Ok(Json(list()?))
}
