//! `GET /v1/presets`: the named parameter sets a session can start from
//! (`dend::deform::Preset`), with every parameter they set, so that clients
//! build their menus from the server and never copy the numbers.

use axum::Json;
use dend::deform::{Params, Preset};
use serde::Serialize;

/// One preset as listed.
#[derive(Debug, Serialize)]
pub struct PresetInfo {
    /// The name a session's `params.preset` takes.
    pub name: &'static str,
    /// A short title for a menu.
    pub label: &'static str,
    /// What the preset is for.
    pub description: &'static str,
    /// Every parameter the preset sets (the session parameters' JSON).
    pub params: Params,
}

/// The answer of `GET /v1/presets`.
#[derive(Debug, Serialize)]
pub struct PresetList {
    /// The preset of a session whose parameters name none.
    pub default: &'static str,
    /// Every preset, the default first.
    pub presets: Vec<PresetInfo>,
}

/// The preset list.
pub fn list() -> PresetList {
    PresetList {
        default: Preset::default().name(),
        presets: Preset::ALL
            .into_iter()
            .map(|p| PresetInfo {
                name: p.name(),
                label: p.label(),
                description: p.description(),
                params: p.params(),
            })
            .collect(),
    }
}

/// `GET /v1/presets`.
pub async fn get() -> Json<PresetList> {
    Json(list())
}
