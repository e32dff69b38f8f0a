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
mod header;

pub use header::{
    bounding_box, FrameBody, FrameEncoding, FrameError, FrameHeader, FLAG_CONVERGED, FLAG_SETTLED,
    FRAME_HEADER_BYTES, FRAME_MAGIC, FRAME_V3_HEADER_BYTES, FRAME_VERSION, FRAME_VERSION_3,
    LEVEL_COARSE, LEVEL_FULL,
};
use header::{f32_at, f64_at, u16_at, u32_at, u64_at, write_v3_header, Q16_MAX};

use bytes::Bytes;

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
