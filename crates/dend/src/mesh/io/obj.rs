//! Wavefront OBJ: `v x y z [w | r g b]` and `f` lines; everything else
//! (`vt`, `vn`, `g`, `o`, `s`, `usemtl`, `mtllib`, `l`, `p`, …) is ignored.
//!
//! Face corners may be `i`, `i/t`, `i//n` or `i/t/n`; indices are 1-based, and
//! negative indices count back from the last vertex defined so far (`-1` is
//! the latest). Polygons are triangulated by fan.

use std::fmt::Write;

use super::text::{fan, fmt_real, index_u32, parse_real, text_lines};
use super::types::{ParseError, Position, RawMesh};
use crate::mesh::Point;

/// Parses OBJ text.
pub(super) fn parse(bytes: &[u8]) -> Result<RawMesh, ParseError> {
    let mut raw = RawMesh::default();
    let mut poly: Vec<u32> = Vec::new();
    for line in text_lines(bytes, true) {
        let (ln, text) = line?;
        let mut toks = text.split_whitespace();
        match toks.next() {
            Some("v") => {
                let mut p = [0.0; 3];
                for (k, c) in p.iter_mut().enumerate() {
                    let tok = toks.next().ok_or_else(|| {
                        ParseError::line(ln, format!("vertex has {k} coordinates, expected 3"))
                    })?;
                    *c = parse_real(tok, ln, "a vertex coordinate")?;
                }
                raw.positions.push(p);
            }
            Some("f") => {
                poly.clear();
                for tok in toks {
                    let idx = tok.split('/').next().unwrap_or("");
                    let i: i64 = idx.parse().map_err(|_| {
                        ParseError::line(ln, format!("expected a vertex index, found {tok:?}"))
                    })?;
                    let nv = raw.positions.len() as i64;
                    let zero_based = match i {
                        0 => return Err(ParseError::line(ln, "vertex index 0 (OBJ is 1-based)")),
                        i if i > 0 => i - 1,
                        i => nv + i,
                    };
                    if zero_based < 0 {
                        return Err(ParseError::line(
                            ln,
                            format!("relative index {i} points before the first vertex ({nv} defined so far)"),
                        ));
                    }
                    poly.push(index_u32(zero_based as u64, Position::Line(ln))?);
                }
                if poly.len() < 3 {
                    return Err(ParseError::line(
                        ln,
                        format!("face has {} corners, at least 3 needed", poly.len()),
                    ));
                }
                fan(&poly, &mut raw.triangles);
            }
            _ => {}
        }
    }
    Ok(raw)
}

/// Writes `v` and `f` lines (1-based indices).
pub(super) fn write(positions: &[Point], triangles: &[[u32; 3]]) -> Vec<u8> {
    let mut s = String::with_capacity(positions.len() * 40 + triangles.len() * 20);
    s.push_str("# written by dend\n");
    for p in positions {
        let _ = writeln!(
            s,
            "v {} {} {}",
            fmt_real(p[0]),
            fmt_real(p[1]),
            fmt_real(p[2])
        );
    }
    for t in triangles {
        let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_indices_slashes_and_fan() {
        let src = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf -4/1/1 -3//1 3/3 4 # quad\n";
        let raw = parse(src).unwrap();
        assert_eq!(raw.positions.len(), 4);
        assert_eq!(raw.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(
            parse(b"v 0 0 0\nf 0 1 2\n").unwrap_err().position,
            Position::Line(2)
        );
        assert!(parse(b"v 0 0 0\nf -2 1 1\n").is_err());
    }
}
