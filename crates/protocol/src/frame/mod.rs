//! The binary pose frame pushed over WebSocket (and returned by
//! `GET /v1/sessions/{id}/pose` with `Accept: application/octet-stream`),
//! in its two versions; `api/ws-protocol.md` is the reference.
//!
//! **Version 2** (the default of a connection that asks for nothing), all
//! little-endian, 40-byte header then the vertices:
//!
//! | offset | type | field |
//! |---|---|---|
//! | 0 | `[u8; 4]` | magic `"DEND"` |
//! | 4 | `u16` | format version, 2 |
//! | 6 | `u16` | flags: bit 0 = converged, bit 1 = settled (the server stopped iterating until the next change) |
//! | 8 | `u64` | session revision |
//! | 16 | `u64` | last applied client sequence number (ack) |
//! | 24 | `u32` | DEND iterations since the targets last changed |
//! | 28 | `u32` | vertex count `n` |
//! | 32 | `f64` | the solver's objective at this pose (NaN before any solve) |
//! | 40 | `f32 × 3n` | x, y, z of each vertex (mesh units) |
//!
//! **Version 3** (asked for with `?encoding=`): the same first 40 bytes
//! (version 3), then
//!
//! | offset | type | field |
//! |---|---|---|
//! | 40 | `u8` | level: 0 = the full mesh, 1 = a coarse preview (prolongated to every vertex) |
//! | 41 | `u8` | encoding: 0 = `f32`, 1 = `q16`, 2 = `delta` |
//! | 42 | `[u8; 6]` | reserved, zero |
//! | 48 | `f64 × 3` | box min: the pose's own bounding box |
//! | 72 | `f64 × 3` | box max |
//! | 96 | payload | `f32 × 3n` (`f32`), `u16 × 3n` (`q16`), or the `delta` payload ([`delta`]) |
//!
//! In `q16`, coordinate `k` of a vertex is `min[k] + q · (max[k] −
//! min[k]) / 65535`: the error is at most 1/131070 of the box's extent
//! along that axis, so under 1e-5 of its diagonal, at half the bytes of
//! `f32`. The box is the pose's, sent with every frame, so it always
//! covers the pose however far it moves from the rest mesh.

pub mod delta;

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
const Q16_MAX: f64 = 65535.0;

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

/// Encodes a version 3 frame of `positions` (its box computed from them).
/// The header's `vertex_count` is taken from `positions`. In `delta`, a
/// key frame: changes against a previous frame are a connection's
/// [`delta::DeltaEncoder`]'s.
pub fn encode_frame_v3<P: Copy + Into<f64>>(
    h: &FrameHeader,
    positions: &[[P; 3]],
    encoding: FrameEncoding,
) -> Bytes {
    let Some(vertex_bytes) = encoding.vertex_bytes() else {
        return delta::DeltaEncoder::new().encode(h, positions);
    };
    let n = positions.len();
    let [lo, hi] = bounding_box(positions);
    let mut b = vec![0u8; FRAME_V3_HEADER_BYTES + n * vertex_bytes];
    let h = FrameHeader {
        vertex_count: n as u32,
        ..*h
    };
    write_v3_header(&mut b, &h, encoding, [lo, hi]);
    let out = &mut b[FRAME_V3_HEADER_BYTES..];
    match encoding {
        FrameEncoding::F32 | FrameEncoding::Delta => {
            for (p, o) in positions.iter().zip(out.chunks_exact_mut(12)) {
                for k in 0..3 {
                    let x: f64 = p[k].into();
                    o[4 * k..4 * k + 4].copy_from_slice(&(x as f32).to_le_bytes());
                }
            }
        }
        FrameEncoding::Q16 => {
            let scale: [f64; 3] = std::array::from_fn(|k| {
                let ext = hi[k] - lo[k];
                if ext > 0.0 {
                    Q16_MAX / ext
                } else {
                    0.0
                }
            });
            for (p, o) in positions.iter().zip(out.chunks_exact_mut(6)) {
                for k in 0..3 {
                    let x: f64 = p[k].into();
                    let q = ((x - lo[k]) * scale[k]).round().clamp(0.0, Q16_MAX) as u16;
                    o[2 * k..2 * k + 2].copy_from_slice(&q.to_le_bytes());
                }
            }
        }
    }
    Bytes::from(b)
}

/// Re-encodes a version 2 frame (as the session produces them) as version
/// 3 in `encoding`, with the header `h` (its level included).
pub fn reencode_v2(
    v2: &[u8],
    h: &FrameHeader,
    encoding: FrameEncoding,
) -> Result<Bytes, FrameError> {
    let (_, positions) = decode_frame(v2)?;
    Ok(encode_frame_v3(h, &positions, encoding))
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

/// A decoded frame: its header, positions and (version 3) box and encoding.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedFrame {
    /// The header.
    pub header: FrameHeader,
    /// Positions, mesh units.
    pub positions: Vec<[f32; 3]>,
    /// The format version (2 or 3).
    pub version: u16,
    /// The encoding (`f32` for version 2).
    pub encoding: FrameEncoding,
    /// The box of a version 3 frame.
    pub bbox: Option<[[f64; 3]; 2]>,
}

fn u16_at(b: &[u8], o: usize) -> u16 {
    u16::from_le_bytes([b[o], b[o + 1]])
}
fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]])
}
fn u64_at(b: &[u8], o: usize) -> u64 {
    let mut a = [0; 8];
    a.copy_from_slice(&b[o..o + 8]);
    u64::from_le_bytes(a)
}
fn f64_at(b: &[u8], o: usize) -> f64 {
    f64::from_bits(u64_at(b, o))
}
fn f32_at(b: &[u8], o: usize) -> f32 {
    f32::from_bits(u32_at(b, o))
}

/// Decodes a frame of version 2 or 3 into its header and positions.
pub fn decode_frame(b: &[u8]) -> Result<(FrameHeader, Vec<[f32; 3]>), FrameError> {
    decode_frame_full(b).map(|f| (f.header, f.positions))
}

/// Decodes a frame of version 2 or 3, with its box and encoding (a
/// `delta` frame only if it is a key frame: a stream of them needs a
/// [`FrameDecoder`]).
pub fn decode_frame_full(b: &[u8]) -> Result<DecodedFrame, FrameError> {
    FrameDecoder::new().decode(b)
}

/// A connection's frame decoder: it holds the last `delta` frame, which
/// the next one's changes apply to.
#[derive(Debug, Clone, Default)]
pub struct FrameDecoder {
    delta: delta::DeltaDecoder,
}

impl FrameDecoder {
    /// A decoder that has seen no frame.
    pub fn new() -> Self {
        Self::default()
    }

    /// Decodes the next frame of the connection.
    pub fn decode(&mut self, b: &[u8]) -> Result<DecodedFrame, FrameError> {
        decode_with(b, &mut self.delta)
    }
}

fn decode_with(b: &[u8], delta: &mut delta::DeltaDecoder) -> Result<DecodedFrame, FrameError> {
    if b.len() < FRAME_HEADER_BYTES {
        return Err(FrameError::Length {
            got: b.len(),
            expected: FRAME_HEADER_BYTES,
        });
    }
    if b[0..4] != FRAME_MAGIC {
        return Err(FrameError::Magic);
    }
    let version = u16_at(b, 4);
    let mut h = FrameHeader {
        converged: u16_at(b, 6) & FLAG_CONVERGED != 0,
        settled: u16_at(b, 6) & FLAG_SETTLED != 0,
        revision: u64_at(b, 8),
        ack_seq: u64_at(b, 16),
        iteration: u32_at(b, 24),
        vertex_count: u32_at(b, 28),
        objective: f64_at(b, 32),
        level: LEVEL_FULL,
    };
    let n = h.vertex_count as usize;
    let (start, encoding, bbox) = match version {
        FRAME_VERSION => (FRAME_HEADER_BYTES, FrameEncoding::F32, None),
        FRAME_VERSION_3 => {
            if b.len() < FRAME_V3_HEADER_BYTES {
                return Err(FrameError::Length {
                    got: b.len(),
                    expected: FRAME_V3_HEADER_BYTES,
                });
            }
            h.level = b[40];
            if h.level > LEVEL_COARSE {
                return Err(FrameError::Level(h.level));
            }
            let enc = FrameEncoding::from_code(b[41]).ok_or(FrameError::Encoding(b[41]))?;
            let lo: [f64; 3] = std::array::from_fn(|k| f64_at(b, 48 + 8 * k));
            let hi: [f64; 3] = std::array::from_fn(|k| f64_at(b, 72 + 8 * k));
            let finite_box =
                (0..3).all(|k| lo[k].is_finite() && hi[k].is_finite() && lo[k] <= hi[k]);
            if !finite_box {
                return Err(FrameError::Box);
            }
            (FRAME_V3_HEADER_BYTES, enc, Some([lo, hi]))
        }
        v => return Err(FrameError::Version(v)),
    };
    let Some(vertex_bytes) = encoding.vertex_bytes() else {
        let positions = delta.positions(b, &h)?;
        return Ok(DecodedFrame {
            header: h,
            positions,
            version,
            encoding,
            bbox,
        });
    };
    let expected = n
        .checked_mul(vertex_bytes)
        .and_then(|p| p.checked_add(start))
        .unwrap_or(usize::MAX);
    if b.len() != expected {
        return Err(FrameError::Length {
            got: b.len(),
            expected,
        });
    }
    let payload = &b[start..];
    let positions = match (encoding, bbox) {
        (FrameEncoding::Q16, Some([lo, hi])) => {
            let step: [f64; 3] = std::array::from_fn(|k| (hi[k] - lo[k]) / Q16_MAX);
            payload
                .chunks_exact(6)
                .map(|c| {
                    std::array::from_fn(|k| (lo[k] + f64::from(u16_at(c, 2 * k)) * step[k]) as f32)
                })
                .collect()
        }
        _ => payload
            .chunks_exact(12)
            .map(|c| std::array::from_fn(|k| f32_at(c, 4 * k)))
            .collect(),
    };
    Ok(DecodedFrame {
        header: h,
        positions,
        version,
        encoding,
        bbox,
    })
}

#[cfg(test)]
mod tests;
