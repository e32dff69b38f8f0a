//! The frame header, its constants and encodings, and the byte-level
//! helpers both frame versions and the `delta` payload share.

use bytes::Bytes;
use serde::{Deserialize, Serialize};

/// Magic bytes at the start of every frame.
pub const FRAME_MAGIC: [u8; 4] = *b"DEND";
/// The frame format version a connection gets when it asks for nothing.
pub const FRAME_VERSION: u16 = 2;
/// The frame format version with a level, an encoding and a box.
pub const FRAME_VERSION_3: u16 = 3;
/// Header size of version 2 frames, in bytes.
pub const FRAME_HEADER_BYTES: usize = 40;
/// Header size of version 3 frames, in bytes.
pub const FRAME_V3_HEADER_BYTES: usize = 96;
/// Flag bit: the solve had converged when this frame was taken.
pub const FLAG_CONVERGED: u16 = 1;
/// Flag bit: the server stopped iterating (converged, or its iteration
/// budget spent without converging) until the targets change again.
pub const FLAG_SETTLED: u16 = 2;
/// Level of a frame that shows the full mesh's solve.
pub const LEVEL_FULL: u8 = 0;
/// Level of a frame that shows a coarse level's solve, prolongated.
pub const LEVEL_COARSE: u8 = 1;
/// The largest quantised coordinate of `q16`.
pub(crate) const Q16_MAX: f64 = 65535.0;

/// How a version 3 frame stores positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameEncoding {
    /// 32-bit floats, 12 bytes per vertex (the full precision of frames;
    /// the f64 pose is `GET /v1/sessions/{id}/pose` and the exports).
    F32,
    /// 16 bits per coordinate in the frame's box, 6 bytes per vertex.
    Q16,
    /// Grid-index changes since the connection's previous frame,
    /// varint-coded and deflated ([`delta`]): what moved costs bytes.
    Delta,
}

impl FrameEncoding {
    /// Its byte in the header.
    pub fn code(self) -> u8 {
        match self {
            FrameEncoding::F32 => 0,
            FrameEncoding::Q16 => 1,
            FrameEncoding::Delta => 2,
        }
    }

    /// The encoding a header byte names.
    pub fn from_code(c: u8) -> Option<Self> {
        match c {
            0 => Some(FrameEncoding::F32),
            1 => Some(FrameEncoding::Q16),
            2 => Some(FrameEncoding::Delta),
            _ => None,
        }
    }

    /// Its name in the query string (`f32`, `q16`).
    pub fn name(self) -> &'static str {
        match self {
            FrameEncoding::F32 => "f32",
            FrameEncoding::Q16 => "q16",
            FrameEncoding::Delta => "delta",
        }
    }

    /// Bytes per vertex of the payload (`None`: `delta`, whose length
    /// depends on what moved).
    pub fn vertex_bytes(self) -> Option<usize> {
        match self {
            FrameEncoding::F32 => Some(12),
            FrameEncoding::Q16 => Some(6),
            FrameEncoding::Delta => None,
        }
    }
}

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
    /// Which level's solve the pose shows: [`LEVEL_FULL`] or
    /// [`LEVEL_COARSE`] (version 3 frames only; version 2 reads as full).
    pub level: u8,
}

/// A frame buffer with room for the version 2 header, vertices already
/// written. Built on the solver thread, the header filled in by the session.
#[derive(Debug)]
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

    /// Writes the header and freezes the (version 2) frame.
    pub fn finish(mut self, h: &FrameHeader) -> Bytes {
        write_common(&mut self.0, h, FRAME_VERSION);
        Bytes::from(self.0)
    }
}

/// The first 40 bytes, common to versions 2 and 3.
fn write_common(b: &mut [u8], h: &FrameHeader, version: u16) {
    b[0..4].copy_from_slice(&FRAME_MAGIC);
    b[4..6].copy_from_slice(&version.to_le_bytes());
    let flags =
        if h.converged { FLAG_CONVERGED } else { 0 } | if h.settled { FLAG_SETTLED } else { 0 };
    b[6..8].copy_from_slice(&flags.to_le_bytes());
    b[8..16].copy_from_slice(&h.revision.to_le_bytes());
    b[16..24].copy_from_slice(&h.ack_seq.to_le_bytes());
    b[24..28].copy_from_slice(&h.iteration.to_le_bytes());
    b[28..32].copy_from_slice(&h.vertex_count.to_le_bytes());
    b[32..40].copy_from_slice(&h.objective.to_le_bytes());
}

/// The bounding box `[min, max]` of positions (zeros when there are none).
pub fn bounding_box<P: Copy + Into<f64>>(positions: &[[P; 3]]) -> [[f64; 3]; 2] {
    if positions.is_empty() {
        return [[0.0; 3]; 2];
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in positions {
        for k in 0..3 {
            let x: f64 = p[k].into();
            lo[k] = lo[k].min(x);
            hi[k] = hi[k].max(x);
        }
    }
    [lo, hi]
}

/// Writes the first 96 bytes of a version 3 frame (header, level,
/// encoding, box) into `b`.
pub(crate) fn write_v3_header(
    b: &mut [u8],
    h: &FrameHeader,
    encoding: FrameEncoding,
    [lo, hi]: [[f64; 3]; 2],
) {
    write_common(b, h, FRAME_VERSION_3);
    b[40] = h.level;
    b[41] = encoding.code();
    for k in 0..3 {
        b[48 + 8 * k..56 + 8 * k].copy_from_slice(&lo[k].to_le_bytes());
        b[72 + 8 * k..80 + 8 * k].copy_from_slice(&hi[k].to_le_bytes());
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
    /// Not the magic `DEND`.
    #[error("not a DEND frame (wrong magic)")]
    Magic,
    /// A version this decoder does not read (it reads 2 and 3).
    #[error("frame format version {0} is not supported (2 and 3 are)")]
    Version(u16),
    /// A version 3 encoding byte that names no encoding.
    #[error("unknown frame encoding {0}")]
    Encoding(u8),
    /// A version 3 level other than 0 (full) or 1 (coarse).
    #[error("unknown frame level {0}")]
    Level(u8),
    /// A version 3 box with a non-finite bound, or a minimum above its maximum.
    #[error("the frame's box is not a finite box (min above max or NaN)")]
    Box,
    /// A `delta` payload that does not decode.
    #[error("bad delta frame: {0}")]
    Delta(&'static str),
    /// A `delta` frame against a frame this decoder does not hold (a
    /// client that missed a frame reconnects).
    #[error("the delta frame applies to revision {base}, the decoder holds {have:?}")]
    Base {
        /// The revision the frame's changes apply to.
        base: u64,
        /// The revision the decoder holds.
        have: Option<u64>,
    },
}

pub(crate) fn u16_at(b: &[u8], o: usize) -> u16 {
    u16::from_le_bytes([b[o], b[o + 1]])
}
pub(crate) fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]])
}
pub(crate) fn u64_at(b: &[u8], o: usize) -> u64 {
    let mut a = [0; 8];
    a.copy_from_slice(&b[o..o + 8]);
    u64::from_le_bytes(a)
}
pub(crate) fn f64_at(b: &[u8], o: usize) -> f64 {
    f64::from_bits(u64_at(b, o))
}
pub(crate) fn f32_at(b: &[u8], o: usize) -> f32 {
    f32::from_bits(u32_at(b, o))
}
