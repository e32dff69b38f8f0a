//! Version 3's `delta` encoding (code 2): the compact stream of a drag.
//!
//! While a handle is dragged, most of a mesh moves little between two
//! frames and much of it does not move at all, so `q16` (6 bytes per vertex
//! whatever moved) spends its bytes on what the client already has. In
//! `delta`, every vertex sits on a grid fixed for a run of frames, and a
//! frame sends the change of each vertex's grid index since the previous
//! frame on the connection (whose revision it names), varint-coded and
//! deflated. A vertex that did not move costs about nothing; one that
//! moved a few grid steps, a byte or two before deflate.
//!
//! Payload (after the 96-byte version 3 header, whose box is the pose's):
//!
//! | offset | type | field |
//! |---|---|---|
//! | 96 | `u8` | 1: a key frame (indices are absolute), 0: changes since the frame of revision `base` |
//! | 97 | `u8` | prediction: 0 = each value is the change itself, 1 = the change minus the vertex's previous change (a vertex moving steadily costs about nothing); 0 in a key frame |
//! | 98 | `[u8; 6]` | reserved, zero |
//! | 104 | `u64` | `base`: the revision of the frame the changes apply to (the frame's own revision in a key frame) |
//! | 112 | `f64` | grid step `h` |
//! | 120 | `f64 × 3` | grid origin `o` |
//! | 144 | `u32` | length of the inflated stream, in bytes |
//! | 148 | deflate (raw, RFC 1951) | `3n` zigzag LEB128 varints: the x index changes of every vertex, then the y, then the z |
//!
//! A coordinate is `o[k] + q · h`, where `q` is its grid index, with
//! `h = diagonal / 16384` of the key frame's box. A key frame rounds every
//! coordinate to the nearest index; a later frame changes an index only
//! when the coordinate has moved more than 0.85 steps from the index the
//! client shows (so a vertex that jitters costs nothing): the error is at
//! most `0.85 h` per axis, `1.47 h ≈ 9e-5` of the diagonal per vertex. The
//! grid changes only at a key frame: the first `delta` frame of a
//! connection, the first after a frame in another encoding (a settled
//! frame goes out in `f32`), after a change of vertex count, when an index
//! leaves the `i32` range, and when the pose's diagonal has shrunk below
//! `16384 h / 1.05`; so the error stays under `9.4e-5` of the diagonal of
//! the pose shown.

use std::io::Write;

use bytes::Bytes;
use flate2::{write::DeflateEncoder, Compression, Decompress, FlushDecompress, Status};

use super::header::{
    bounding_box, f64_at, u32_at, u64_at, write_v3_header, FrameEncoding, FrameError, FrameHeader,
    FRAME_V3_HEADER_BYTES,
};

/// Grid steps along the diagonal of a key frame's box.
pub const DELTA_GRID_DIVISIONS: f64 = 16384.0;
/// A coordinate keeps the index a client shows while it is within this
/// many grid steps of it (a key frame rounds to the nearest, half a step).
pub const DELTA_HOLD_STEPS: f64 = 0.85;
/// A key frame replaces the grid when the pose's diagonal has shrunk by
/// more than this factor since the grid's key frame.
const DELTA_SHRINK: f64 = 1.05;
/// Offset of the deflated stream in a `delta` frame.
pub const DELTA_STREAM_OFFSET: usize = FRAME_V3_HEADER_BYTES + 52;

/// The grid a run of `delta` frames shares.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Grid {
    origin: [f64; 3],
    step: f64,
}

impl Grid {
    /// The grid of a key frame whose pose has the box `[lo, _]` and the
    /// diagonal `diag`: origin at the box's minimum,
    /// `DELTA_GRID_DIVISIONS` steps along its diagonal.
    fn of([lo, _]: [[f64; 3]; 2], diag: f64) -> Self {
        let step = if diag.is_finite() && diag > 0.0 {
            diag / DELTA_GRID_DIVISIONS
        } else {
            1.0
        };
        let origin = lo.map(|x| if x.is_finite() { x } else { 0.0 });
        Grid { origin, step }
    }

    /// The grid indices of `positions` (`None` when one leaves `i32`):
    /// the nearest, or, given the indices `held` shown now, the held index
    /// of every coordinate still within [`DELTA_HOLD_STEPS`] of it (a vertex
    /// that jitters by less than the error allowed costs no change).
    fn quantise<P: Copy + Into<f64>>(
        &self,
        positions: &[[P; 3]],
        held: Option<&[i32]>,
        q: &mut Vec<i32>,
    ) -> Option<()> {
        q.clear();
        for (i, p) in positions.iter().enumerate() {
            for (k, (&x, o)) in p.iter().zip(self.origin).enumerate() {
                let x: f64 = x.into();
                let t = (x - o) / self.step;
                let kept = held.map(|h| h[3 * i + k]);
                let t = match kept {
                    Some(h) if (t - f64::from(h)).abs() <= DELTA_HOLD_STEPS => f64::from(h),
                    _ => t.round(),
                };
                // NaN fails both comparisons: refused like an overflow
                if !(t >= f64::from(i32::MIN) && t <= f64::from(i32::MAX)) {
                    return None;
                }
                q.push(t as i32);
            }
        }
        Some(())
    }
}

fn zigzag(d: i32) -> u32 {
    ((d << 1) ^ (d >> 31)) as u32
}

fn unzigzag(z: u32) -> i32 {
    ((z >> 1) as i32) ^ -((z & 1) as i32)
}

/// Bytes of the LEB128 varint of `z`.
fn varint_len(z: u32) -> usize {
    1 + (32 - z.leading_zeros() as usize).saturating_sub(1) / 7
}

fn put_varint(out: &mut Vec<u8>, mut z: u32) {
    while z >= 0x80 {
        out.push((z as u8) | 0x80);
        z >>= 7;
    }
    out.push(z as u8);
}

/// What a connection's encoder remembers of the last frame it sent.
#[derive(Debug, Clone, Default)]
pub struct DeltaEncoder {
    /// The grid and revision of the last `delta` frame sent (`None`: the
    /// next is a key frame).
    base: Option<(Grid, u64)>,
    /// The grid indices of the last frame sent, 3 per vertex.
    q: Vec<i32>,
    /// The change of each index in the last frame sent (zero after a key
    /// frame): what prediction 1 extrapolates.
    dq: Vec<i32>,
    /// Scratch: the new indices and the varint stream.
    next: Vec<i32>,
    stream: Vec<u8>,
}

impl DeltaEncoder {
    /// An encoder whose first frame is a key frame.
    pub fn new() -> Self {
        Self::default()
    }

    /// The client's pose is no longer the last `delta` frame (a frame in
    /// another encoding went out): the next frame is a key frame.
    pub fn reset(&mut self) {
        self.base = None;
    }

    /// Encodes `positions` as a `delta` frame with header `h` (its
    /// `vertex_count` taken from `positions`), against the last frame this
    /// encoder made, or as a key frame.
    pub fn encode<P: Copy + Into<f64>>(&mut self, h: &FrameHeader, positions: &[[P; 3]]) -> Bytes {
        let n = positions.len();
        let bbox = bounding_box(positions);
        let diag = (0..3)
            .map(|k| (bbox[1][k] - bbox[0][k]).powi(2))
            .sum::<f64>()
            .sqrt();
        // a grid coarser than 1.05 steps per 16384th of the pose's
        // diagonal (the pose shrank since the key frame) is replaced
        let mut against = self.base.filter(|(g, _)| {
            let shrunk = g.step > DELTA_SHRINK * diag / DELTA_GRID_DIVISIONS;
            self.q.len() == 3 * n && !shrunk
        });
        let grid = match against {
            Some((g, _))
                if g.quantise(positions, Some(&self.q), &mut self.next)
                    .is_some() =>
            {
                g
            }
            _ => {
                against = None;
                let g = Grid::of(bbox, diag);
                if g.quantise(positions, None, &mut self.next).is_none() {
                    // non-finite or astronomically spread positions: all at
                    // the origin rather than a panic (the solver never
                    // publishes such a pose)
                    self.next.clear();
                    self.next.resize(3 * n, 0);
                }
                g
            }
        };
        // prediction 1 when it makes fewer varint bytes than 0
        let predict = against.is_some() && {
            let (mut plain, mut extrapolated) = (0usize, 0usize);
            for ((now, was), last) in self.next.iter().zip(&self.q).zip(&self.dq) {
                let d = now.wrapping_sub(*was);
                plain += varint_len(zigzag(d));
                extrapolated += varint_len(zigzag(d.wrapping_sub(*last)));
            }
            extrapolated < plain
        };
        if against.is_none() {
            self.dq.clear();
            self.dq.resize(3 * n, 0);
        }
        self.stream.clear();
        for k in 0..3 {
            for i in 0..n {
                let j = 3 * i + k;
                let now = self.next[j];
                let value = match against {
                    Some(_) => {
                        let d = now.wrapping_sub(self.q[j]);
                        let v = if predict {
                            d.wrapping_sub(self.dq[j])
                        } else {
                            d
                        };
                        self.dq[j] = d;
                        v
                    }
                    None => now,
                };
                put_varint(&mut self.stream, zigzag(value));
            }
        }
        let mut out = Vec::with_capacity(DELTA_STREAM_OFFSET + self.stream.len() / 4 + 64);
        out.resize(DELTA_STREAM_OFFSET, 0);
        let h = FrameHeader {
            vertex_count: n as u32,
            ..*h
        };
        write_v3_header(&mut out, &h, FrameEncoding::Delta, bbox);
        let p = FRAME_V3_HEADER_BYTES;
        out[p] = u8::from(against.is_none());
        out[p + 1] = u8::from(predict);
        let base = against.map_or(h.revision, |(_, r)| r);
        out[p + 8..p + 16].copy_from_slice(&base.to_le_bytes());
        out[p + 16..p + 24].copy_from_slice(&grid.step.to_le_bytes());
        for k in 0..3 {
            out[p + 24 + 8 * k..p + 32 + 8 * k].copy_from_slice(&grid.origin[k].to_le_bytes());
        }
        out[p + 48..p + 52].copy_from_slice(&(self.stream.len() as u32).to_le_bytes());
        // level 2: 12-15 % smaller than level 1 on a 50k-vertex drag's
        // frames for ~0.5 ms more; level 6 gains 3 % more for 5-10x the time
        let mut z = DeflateEncoder::new(out, Compression::new(2));
        // writing into a Vec cannot fail
        z.write_all(&self.stream).expect("deflate into memory");
        let out = z.finish().expect("deflate into memory");
        std::mem::swap(&mut self.q, &mut self.next);
        self.base = Some((grid, h.revision));
        Bytes::from(out)
    }
}

/// What a client's decoder remembers of the last `delta` frame it read.
#[derive(Debug, Clone, Default)]
pub struct DeltaDecoder {
    /// Revision of the last frame decoded, its grid indices, and their
    /// last change.
    base: Option<u64>,
    q: Vec<i32>,
    dq: Vec<i32>,
}

impl DeltaDecoder {
    /// A decoder that holds no frame (it reads key frames only).
    pub fn new() -> Self {
        Self::default()
    }

    /// Decodes the positions of a `delta` frame whose version 3 header
    /// (`h`, already checked) says `n` vertices; `b` is the whole frame.
    pub(crate) fn positions(
        &mut self,
        b: &[u8],
        h: &FrameHeader,
    ) -> Result<Vec<[f32; 3]>, FrameError> {
        let n = h.vertex_count as usize;
        // held again only if this frame decodes whole
        let held = self.base.take();
        if b.len() < DELTA_STREAM_OFFSET {
            return Err(FrameError::Length {
                got: b.len(),
                expected: DELTA_STREAM_OFFSET,
            });
        }
        let p = FRAME_V3_HEADER_BYTES;
        let key = match b[p] {
            0 => false,
            1 => true,
            _ => return Err(FrameError::Delta("the key byte is neither 0 nor 1")),
        };
        let predict = match (b[p + 1], key) {
            (0, _) => false,
            (1, false) => true,
            _ => return Err(FrameError::Delta("unknown prediction")),
        };
        let base = u64_at(b, p + 8);
        let step = f64_at(b, p + 16);
        let origin: [f64; 3] = std::array::from_fn(|k| f64_at(b, p + 24 + 8 * k));
        if !(step.is_finite() && step > 0.0 && origin.iter().all(|o| o.is_finite())) {
            return Err(FrameError::Delta("the grid is not a finite grid"));
        }
        let len = u32_at(b, p + 48) as usize;
        // every index change is 1 to 5 bytes
        let need = n.saturating_mul(3);
        if len < need || len > need.saturating_mul(5) {
            return Err(FrameError::Delta(
                "the stream length does not fit the vertex count",
            ));
        }
        if !key && (held != Some(base) || self.q.len() != need) {
            return Err(FrameError::Base { base, have: held });
        }
        // at most one byte more than announced is inflated: a frame that
        // inflates to more costs no more memory than an honest one
        let mut stream = Vec::new();
        stream.reserve_exact(len + 1);
        let status = Decompress::new(false)
            .decompress_vec(
                &b[DELTA_STREAM_OFFSET..],
                &mut stream,
                FlushDecompress::Finish,
            )
            .map_err(|_| FrameError::Delta("the stream does not inflate"))?;
        if stream.len() > len {
            return Err(FrameError::Delta("the stream is not as long as announced"));
        }
        // a deflate stream cut before its last block is malformed (as
        // browsers' DecompressionStream finds it), not a short stream
        if status != Status::StreamEnd {
            return Err(FrameError::Delta("the stream does not inflate"));
        }
        if stream.len() != len {
            return Err(FrameError::Delta("the stream is not as long as announced"));
        }
        if key {
            self.q.clear();
            self.q.resize(need, 0);
            self.dq.clear();
            self.dq.resize(need, 0);
        }
        let mut at = 0;
        for k in 0..3 {
            for i in 0..n {
                let mut z: u32 = 0;
                let mut shift = 0;
                loop {
                    let Some(&byte) = stream.get(at) else {
                        return Err(FrameError::Delta("the stream ends inside a varint"));
                    };
                    at += 1;
                    if shift == 28 && byte > 0x0f {
                        return Err(FrameError::Delta("a varint overflows 32 bits"));
                    }
                    z |= u32::from(byte & 0x7f) << shift;
                    if byte & 0x80 == 0 {
                        break;
                    }
                    shift += 7;
                }
                let j = 3 * i + k;
                let v = unzigzag(z);
                if key {
                    self.q[j] = v;
                } else {
                    let d = if predict {
                        v.wrapping_add(self.dq[j])
                    } else {
                        v
                    };
                    self.q[j] = self.q[j].wrapping_add(d);
                    self.dq[j] = d;
                }
            }
        }
        if at != len {
            return Err(FrameError::Delta(
                "the stream has bytes past its last varint",
            ));
        }
        self.base = Some(h.revision);
        Ok(self
            .q
            .chunks_exact(3)
            .map(|c| std::array::from_fn(|k| (origin[k] + f64::from(c[k]) * step) as f32))
            .collect())
    }
}

#[cfg(test)]
#[path = "delta_tests.rs"]
mod tests;
