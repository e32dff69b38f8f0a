//! Entry points shared by the cargo-fuzz targets (`fuzz/`) and the test
//! that replays their corpus (`tests/it/fuzz_replay.rs`): each takes arbitrary
//! bytes and must return (an error is fine), never panic.

use std::sync::OnceLock;

use crate::ws::decode_client_msg;
use dend::deform::ConstraintsSpec;
use dend::mesh::io::{parse_bytes, survey, Format};
use dend::mesh::Mesh;

/// A 4×4 vertex grid (18 triangles) to resolve fuzzed constraints on.
fn small_mesh() -> &'static Mesh {
    static MESH: OnceLock<Mesh> = OnceLock::new();
    MESH.get_or_init(|| {
        let n = 4u32;
        let positions = (0..n * n)
            .map(|k| [(k % n) as f64, (k / n) as f64, 0.0])
            .collect();
        let mut triangles = vec![];
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = j * n + i;
                triangles.push([a, a + 1, a + n + 1]);
                triangles.push([a, a + n + 1, a + n]);
            }
        }
        Mesh::new(positions, triangles)
            .unwrap_or_else(|e| unreachable!("the fixed grid is valid: {e}"))
    })
}

/// Parses `data` as a constraints spec and resolves it on a small mesh;
/// true when it resolved.
pub fn constraints_json(data: &[u8]) -> bool {
    let Ok(spec) = serde_json::from_slice::<ConstraintsSpec>(data) else {
        return false;
    };
    match spec.resolve(small_mesh()) {
        Ok(c) => {
            // what the server does next with resolved constraints
            let _ = c.constrained();
            c.handles
                .iter()
                .all(|h| h.target.rotation.coords.iter().all(|x| x.is_finite()))
        }
        Err(e) => {
            let _ = crate::ApiError::from(e);
            false
        }
    }
}

/// Decodes `data` as a client WebSocket message as the server does; true
/// when it was accepted.
pub fn ws_message(data: &[u8]) -> bool {
    let Ok(text) = std::str::from_utf8(data) else {
        return false;
    };
    decode_client_msg(text).is_ok()
}

/// Decodes `data` as a binary pose frame (version 2 or 3) as clients do;
/// true when it decoded (and its vertex count matched its positions).
pub fn pose_frame(data: &[u8]) -> bool {
    dend_protocol::decode_frame_full(data)
        .is_ok_and(|f| f.positions.len() == f.header.vertex_count as usize)
}

/// Reads `data` as a mesh file in `format` and validates the result as
/// `Mesh::new` does; true when it gave a mesh.
pub fn mesh_file(data: &[u8], format: Format) -> bool {
    parse_bytes(data, format).is_ok_and(|raw| raw.into_mesh().is_ok())
}

/// Reads `data` as a glTF asset (GLB, or glTF JSON with data-URI buffers;
/// side-car files refused) as uploads are read, welds and validates it, and
/// exports it at rest and under a shear in both containers; true when it
/// gave an asset.
pub fn gltf_asset(data: &[u8]) -> bool {
    use dend::mesh::asset::Asset;
    use dend::mesh::io::gltf::Sidecars;
    let Ok(a) = Asset::read_bytes(data, Format::Glb, Sidecars::Refuse) else {
        return false;
    };
    let rest = a.mesh().positions();
    let sheared: Vec<_> = rest
        .iter()
        .map(|p| [p[0] + 0.5 * p[2], p[1], p[2]])
        .collect();
    for pose in [rest, &sheared[..]] {
        for f in [Format::Glb, Format::Gltf] {
            let _ = a.export(pose, f);
        }
    }
    true
}

/// Reads `data` as a survey `.sel` vertex-status file; true when it parsed.
pub fn sel_file(data: &[u8]) -> bool {
    survey::parse_sel(data).is_ok()
}

/// Reads `data` as a survey `.def` handle transform; true when it parsed.
pub fn def_file(data: &[u8]) -> bool {
    survey::parse_def(data).is_ok()
}
