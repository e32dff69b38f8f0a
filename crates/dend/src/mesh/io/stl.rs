//! STL, ASCII and binary. STL is a triangle soup; corners are **welded** into
//! shared vertices when their coordinates are exactly equal (bitwise, with
//! `-0.0` treated as `0.0`), numbered in order of first appearance. Facet
//! normals are ignored (orientation comes from the corner order).
//!
//! Binary is recognised by its size (`84 + 50·n` bytes for `n` facets);
//! otherwise a file starting with `solid` is read as ASCII, anything else as
//! (malformed) binary.

use std::collections::HashMap;
use std::fmt::Write;

use super::text::{bounded_capacity, fmt_real, parse_real, text_lines};
use super::types::{Encoding, ParseError, RawMesh};
use crate::mesh::{cross, sub, Point};

/// Collects corners and welds equal ones.
struct Welder {
    raw: RawMesh,
    index: HashMap<[u64; 3], u32>,
}

impl Welder {
    fn new(facets: usize) -> Self {
        Welder {
            raw: RawMesh {
                positions: Vec::with_capacity(facets / 2 + 1),
                triangles: Vec::with_capacity(facets),
            },
            index: HashMap::with_capacity(facets / 2 + 1),
        }
    }
    fn corner(&mut self, p: Point) -> u32 {
        // `+ 0.0` maps -0.0 to 0.0; NaN payloads stay distinct (rejected later).
        let key = p.map(|c| (c + 0.0).to_bits());
        let n = self.raw.positions.len() as u32;
        let raw = &mut self.raw;
        *self.index.entry(key).or_insert_with(|| {
            raw.positions.push(p);
            n
        })
    }
}

/// Parses STL bytes (ASCII or binary).
pub(super) fn parse(bytes: &[u8]) -> Result<RawMesh, ParseError> {
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if 84 + 50 * n == bytes.len() {
            return parse_binary(bytes);
        }
    }
    let start = bytes
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(bytes.len());
    if bytes[start..].starts_with(b"solid") {
        parse_ascii(bytes)
    } else {
        parse_binary(bytes)
    }
}

fn parse_binary(bytes: &[u8]) -> Result<RawMesh, ParseError> {
    if bytes.len() < 84 {
        return Err(ParseError::byte(
            bytes.len(),
            format!(
                "truncated binary STL: {} bytes, the header alone is 84",
                bytes.len()
            ),
        ));
    }
    let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
    let expected = 84 + 50 * n;
    if bytes.len() < expected {
        let complete = (bytes.len() - 84) / 50;
        return Err(ParseError::byte(
            84 + 50 * complete,
            format!("truncated binary STL: header announces {n} facets, only {complete} complete"),
        ));
    }
    if bytes.len() > expected {
        return Err(ParseError::byte(
            expected,
            format!("{} trailing bytes after {n} facets", bytes.len() - expected),
        ));
    }
    let mut w = Welder::new(bounded_capacity(n, bytes.len(), 50));
    for f in 0..n {
        let base = 84 + 50 * f + 12;
        let mut tri = [0u32; 3];
        for (k, t) in tri.iter_mut().enumerate() {
            let mut p = [0.0; 3];
            for (c, v) in p.iter_mut().enumerate() {
                let o = base + 12 * k + 4 * c;
                *v =
                    f32::from_le_bytes([bytes[o], bytes[o + 1], bytes[o + 2], bytes[o + 3]]) as f64;
            }
            *t = w.corner(p);
        }
        w.raw.triangles.push(tri);
    }
    Ok(w.raw)
}

fn parse_ascii(bytes: &[u8]) -> Result<RawMesh, ParseError> {
    let mut w = Welder::new(bounded_capacity(usize::MAX, bytes.len(), 200));
    let mut corners: Vec<u32> = Vec::with_capacity(3);
    let mut in_loop = false;
    let mut ended = false;
    let mut last = 1;
    for line in text_lines(bytes, false) {
        let (ln, text) = line?;
        last = ln;
        let toks: Vec<&str> = text.split_whitespace().collect();
        let bad = |m: &str| ParseError::line(ln, format!("{m}: {:?}", text.trim()));
        match toks.first().copied() {
            None => {}
            Some(_) if ended => return Err(bad("content after endsolid")),
            Some("solid") | Some("facet") | Some("endfacet") => {}
            Some("outer") => {
                if in_loop {
                    return Err(bad("nested outer loop"));
                }
                in_loop = true;
                corners.clear();
            }
            Some("vertex") => {
                if !in_loop {
                    return Err(bad("vertex outside an outer loop"));
                }
                if toks.len() != 4 {
                    return Err(bad("expected \"vertex x y z\""));
                }
                let mut p = [0.0; 3];
                for (c, t) in p.iter_mut().zip(&toks[1..]) {
                    *c = parse_real(t, ln, "a vertex coordinate")?;
                }
                corners.push(w.corner(p));
                if corners.len() > 3 {
                    return Err(bad("facet with more than 3 vertices"));
                }
            }
            Some("endloop") => {
                if corners.len() != 3 {
                    return Err(bad(&format!(
                        "facet has {} vertices, expected 3",
                        corners.len()
                    )));
                }
                w.raw.triangles.push([corners[0], corners[1], corners[2]]);
                in_loop = false;
            }
            Some("endsolid") => ended = true,
            Some(_) => return Err(bad("unrecognised line")),
        }
    }
    if in_loop {
        return Err(ParseError::line(
            last,
            "unexpected end of file inside a facet",
        ));
    }
    if !ended {
        return Err(ParseError::line(
            last,
            "unexpected end of file: no endsolid",
        ));
    }
    Ok(w.raw)
}

fn normal(positions: &[Point], t: &[u32; 3]) -> Point {
    let [a, b, c] = t.map(|i| positions[i as usize]);
    let n = cross(sub(b, a), sub(c, a));
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if l > 0.0 {
        n.map(|x| x / l)
    } else {
        [0.0; 3]
    }
}

/// Writes STL (ASCII, or binary little-endian with `f32` coordinates).
pub(super) fn write(positions: &[Point], triangles: &[[u32; 3]], enc: Encoding) -> Vec<u8> {
    if enc == Encoding::Ascii {
        let mut s = String::from("solid dend\n");
        for t in triangles {
            let n = normal(positions, t);
            let _ = writeln!(
                s,
                "facet normal {} {} {}\nouter loop",
                fmt_real(n[0]),
                fmt_real(n[1]),
                fmt_real(n[2])
            );
            for &i in t {
                let p = positions[i as usize];
                let _ = writeln!(
                    s,
                    "vertex {} {} {}",
                    fmt_real(p[0]),
                    fmt_real(p[1]),
                    fmt_real(p[2])
                );
            }
            s.push_str("endloop\nendfacet\n");
        }
        s.push_str("endsolid dend\n");
        return s.into_bytes();
    }
    let mut out = Vec::with_capacity(84 + 50 * triangles.len());
    let mut header = [b' '; 80];
    header[..16].copy_from_slice(b"binary STL: dend");
    out.extend_from_slice(&header);
    out.extend_from_slice(&(triangles.len() as u32).to_le_bytes());
    for t in triangles {
        let n = normal(positions, t);
        let corners = t.map(|i| positions[i as usize]);
        for p in std::iter::once(n).chain(corners) {
            for c in p {
                out.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn welds_exactly_equal_corners_only() {
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ];
        let t = vec![[0, 1, 2], [2, 1, 3]];
        for enc in [Encoding::Ascii, Encoding::BinaryLittleEndian] {
            let raw = parse(&write(&p, &t, enc)).unwrap();
            assert_eq!(raw.positions, p);
            assert_eq!(raw.triangles, t);
        }
        let src = b"solid s\nfacet normal 0 0 1\nouter loop\nvertex -0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n\
facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 1e-300\nvertex 0 -1 0\nendloop\nendfacet\nendsolid s\n";
        let raw = parse(src).unwrap();
        assert_eq!(
            raw.positions.len(),
            5,
            "-0 welds with 0; 1e-300 does not weld with 0"
        );
    }
}
