//! The binary pose frame pushed over WebSocket (and returned by
//! `GET /v1/sessions/{id}/pose` with `Accept: application/octet-stream`).
//!
//! Layout, all little-endian, 40-byte header then the vertices (format
//! version 2; version 1 had no objective and no `settled` flag):
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | `[u8; 4]` | magic `"DEND"` |
//! | 4 | `u16` | format version ([`FRAME_VERSION`]) |
//! | 6 | `u16` | flags: bit 0 = converged, bit 1 = settled (the server stopped iterating until the next change) |
//! | 8 | `u64` | session revision |
//! | 16 | `u64` | last applied client sequence number (ack) |
//! | 24 | `u32` | DEND iterations since the targets last changed |
//! | 28 | `u32` | vertex count `n` |
//! | 32 | `f64` | the solver's objective at this pose (NaN before any solve) |
//! | 40 | `f32 × 3n` | x, y, z of each vertex (mesh units) |

use bytes::Bytes;
use serde::{Deserialize, Serialize};

/// Magic bytes at the start of every frame.
pub const FRAME_MAGIC: [u8; 4] = *b"DEND";
/// Frame format version.
pub const FRAME_VERSION: u16 = 2;
/// Header size in bytes.
pub const FRAME_HEADER_BYTES: usize = 40;
/// Flag bit: the solve had converged when this frame was taken.
pub const FLAG_CONVERGED: u16 = 1;
/// Flag bit: the server stopped iterating (converged, or its iteration
/// budget spent without converging) until the targets change again.
pub const FLAG_SETTLED: u16 = 2;

/// The header fields of a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameHeader {
    /// Session revision (increases with every frame and state change).
    pub revision: u64,
    /// Last applied client sequence number.
    pub ack_seq: u64,
    /// DEND iterations since the targets last changed.
    pub iteration: u32,
    /// Whether the solve had converged.
    pub converged: bool,
    /// Whether the server stopped iterating until the next change.
    pub settled: bool,
    /// The solver's objective at this pose (NaN when unknown).
    pub objective: f64,
    /// Number of vertices that follow.
    pub vertex_count: u32,
}

/// A frame buffer with room for the header, vertices already written.
/// Built on the solver thread, the header filled in by the session.
pub struct FrameBody(Vec<u8>);

impl FrameBody {
    /// Converts a pose to f32 little-endian after an empty header.
    pub fn from_pose(pose: &[[f64; 3]]) -> Self {
        let mut buf = Vec::with_capacity(FRAME_HEADER_BYTES + pose.len() * 12);
        buf.resize(FRAME_HEADER_BYTES, 0);
        for p in pose {
            for c in p {
                buf.extend_from_slice(&(*c as f32).to_le_bytes());
            }
        }
        FrameBody(buf)
    }

    /// Writes the header and freezes the frame.
    pub fn finish(mut self, h: &FrameHeader) -> Bytes {
        let b = &mut self.0;
        b[0..4].copy_from_slice(&FRAME_MAGIC);
        b[4..6].copy_from_slice(&FRAME_VERSION.to_le_bytes());
        let flags =
            if h.converged { FLAG_CONVERGED } else { 0 } | if h.settled { FLAG_SETTLED } else { 0 };
        b[6..8].copy_from_slice(&flags.to_le_bytes());
        b[8..16].copy_from_slice(&h.revision.to_le_bytes());
        b[16..24].copy_from_slice(&h.ack_seq.to_le_bytes());
        b[24..28].copy_from_slice(&h.iteration.to_le_bytes());
        b[28..32].copy_from_slice(&h.vertex_count.to_le_bytes());
        b[32..40].copy_from_slice(&h.objective.to_le_bytes());
        Bytes::from(self.0)
    }
}

/// Why a byte buffer is not a valid frame.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum FrameError {
    /// Shorter than the header, or than the header's vertex count needs.
    #[error("frame has {got} bytes, expected {expected}")]
    Length {
        /// Bytes received.
        got: usize,
        /// Bytes the header announces.
        expected: usize,
    },
    /// Wrong magic or unknown version.
    #[error("not a DEND v{FRAME_VERSION} frame")]
    Magic,
}

/// Decodes a frame into its header and f32 vertices.
pub fn decode_frame(b: &[u8]) -> Result<(FrameHeader, Vec<[f32; 3]>), FrameError> {
    if b.len() < FRAME_HEADER_BYTES {
        return Err(FrameError::Length {
            got: b.len(),
            expected: FRAME_HEADER_BYTES,
        });
    }
    let u16_at = |o: usize| u16::from_le_bytes([b[o], b[o + 1]]);
    let u32_at = |o: usize| u32::from_le_bytes(b[o..o + 4].try_into().unwrap_or([0; 4]));
    let u64_at = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().unwrap_or([0; 8]));
    if b[0..4] != FRAME_MAGIC || u16_at(4) != FRAME_VERSION {
        return Err(FrameError::Magic);
    }
    let h = FrameHeader {
        converged: u16_at(6) & FLAG_CONVERGED != 0,
        settled: u16_at(6) & FLAG_SETTLED != 0,
        revision: u64_at(8),
        ack_seq: u64_at(16),
        iteration: u32_at(24),
        vertex_count: u32_at(28),
        objective: f64::from_bits(u64_at(32)),
    };
    let expected = FRAME_HEADER_BYTES + h.vertex_count as usize * 12;
    if b.len() != expected {
        return Err(FrameError::Length {
            got: b.len(),
            expected,
        });
    }
    let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap_or([0; 4]));
    let verts = (0..h.vertex_count as usize)
        .map(|i| {
            let o = FRAME_HEADER_BYTES + 12 * i;
            [f(o), f(o + 4), f(o + 8)]
        })
        .collect();
    Ok((h, verts))
}

/// A mesh as the API describes it: the answer of upload, generate and
/// `GET /v1/meshes/{id}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MeshInfo {
    /// Mesh id.
    pub id: String,
    /// Vertex count.
    pub vertices: usize,
    /// Triangle count.
    pub triangles: usize,
    /// Bounding box `[min, max]`.
    pub bbox: [[f64; 3]; 2],
    /// For uploads kept as assets (glTF/GLB, OBJ, PLY): the file's format, its
    /// own vertex count (seam copies included; `vertices` counts the welded
    /// surface the sessions deform) and what export keeps besides positions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub asset: Option<AssetSummary>,
}

/// What an uploaded asset holds (see [`MeshInfo::asset`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct AssetSummary {
    /// `glb`, `gltf`, `obj` or `ply`.
    pub format: String,
    /// The glTF scene's (else first mesh's) name, the name on the OBJ's first `o`/`g` line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Vertices in the file's own layout.
    pub asset_vertices: usize,
    /// Attributes and counts kept by export (`TEXCOORD_0`, `JOINTS_0`,
    /// `skins: 1`, `vt: 120`, …).
    pub attributes: Vec<String>,
    /// The named parts constraints can select by (`{"group": …}`): OBJ
    /// `g`/`o` names, glTF nodes, meshes and primitives.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub groups: Vec<AssetGroup>,
}

/// A named part of an uploaded asset (see [`AssetSummary::groups`]).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct AssetGroup {
    /// `g`, `o`, `node`, `mesh` or `primitive`.
    pub kind: String,
    /// Its name (a primitive's is its mesh's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The glTF node or mesh index (a primitive's mesh).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index: Option<usize>,
    /// A primitive's index in its mesh.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub primitive: Option<usize>,
    /// Asset triangles in it.
    pub triangles: usize,
    /// Welded vertices (the ones sessions deform) it selects.
    pub vertices: usize,
}

/// A pose as JSON: the answer of drags, undo/redo/reset and
/// `GET /v1/sessions/{id}/pose`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseJson {
    /// Session revision.
    pub revision: u64,
    /// Last applied client sequence number.
    pub ack_seq: u64,
    /// Iterations since the targets last changed.
    pub iteration: u32,
    /// Whether the solve converged.
    pub converged: bool,
    /// Whether the server stopped iterating until the next change
    /// (converged, or its iteration budget spent).
    #[serde(default)]
    pub settled: bool,
    /// The solver's objective at this pose (absent before any solve).
    #[serde(default)]
    pub objective: Option<f64>,
    /// `#V×3` positions, mesh units.
    pub positions: Vec<[f64; 3]>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_round_trips_and_layout_is_fixed() {
        let pose = [[1.0, -2.0, 3.5], [0.25, 0.0, -1e3]];
        let h = FrameHeader {
            revision: 7,
            ack_seq: 0x0102_0304_0506_0708,
            iteration: 9,
            converged: true,
            settled: false,
            objective: 12.5,
            vertex_count: 2,
        };
        let bytes = FrameBody::from_pose(&pose).finish(&h);
        assert_eq!(bytes.len(), 40 + 24);
        assert_eq!(&bytes[0..4], b"DEND");
        assert_eq!(bytes[4], 2, "format version 2");
        assert_eq!(bytes[6], 1, "converged flag is bit 0 of the flags");
        assert_eq!(bytes[16], 0x08, "ack seq is little-endian at offset 16");
        assert_eq!(&bytes[32..40], &12.5f64.to_le_bytes());
        assert_eq!(&bytes[40..44], &1.0f32.to_le_bytes());
        let (h2, v) = decode_frame(&bytes).unwrap();
        assert_eq!(h2, h);
        assert_eq!(v, vec![[1.0, -2.0, 3.5], [0.25, 0.0, -1e3]]);
        let settled = FrameBody::from_pose(&pose).finish(&FrameHeader { settled: true, ..h });
        assert_eq!(settled[6], 3, "settled flag is bit 1");
        assert!(decode_frame(&settled).unwrap().0.settled);
        assert_eq!(
            decode_frame(&bytes[..48]),
            Err(FrameError::Length {
                got: 48,
                expected: 64
            })
        );
        assert_eq!(
            decode_frame(b"XEND00000000000000000000000000000000000"),
            Err(FrameError::Length {
                got: 39,
                expected: 40
            })
        );
        assert_eq!(
            decode_frame(b"XEND000000000000000000000000000000000000"),
            Err(FrameError::Magic)
        );
    }
}
