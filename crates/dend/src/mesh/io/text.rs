//! Helpers shared by the text readers and writers (OBJ, OFF, ASCII PLY
//! and STL): lines, numbers, indices, polygon fans and exact formatting.

use super::types::{ParseError, Position};
use crate::mesh::Point;

/// Lines of `bytes` as `(1-based number, text)`, with `#` comments removed
/// when `strip_comments`. Invalid UTF-8 is an error naming the line.
pub(crate) fn text_lines(
    bytes: &[u8],
    strip_comments: bool,
) -> impl Iterator<Item = Result<(usize, &str), ParseError>> {
    bytes.split(|&b| b == b'\n').enumerate().map(move |(i, l)| {
        let s = std::str::from_utf8(l)
            .map_err(|_| ParseError::line(i + 1, "invalid UTF-8 (binary data in a text file?)"))?;
        let s = if strip_comments {
            s.split('#').next().unwrap_or("")
        } else {
            s
        };
        Ok((i + 1, s.trim_end_matches('\r')))
    })
}

/// Parses a coordinate token.
pub(crate) fn parse_real(tok: &str, line: usize, what: &str) -> Result<f64, ParseError> {
    tok.parse::<f64>()
        .map_err(|_| ParseError::line(line, format!("expected a number for {what}, found {tok:?}")))
}

/// Parses a non-negative count or index token.
pub(crate) fn parse_count(tok: &str, line: usize, what: &str) -> Result<usize, ParseError> {
    tok.parse::<usize>().map_err(|_| {
        ParseError::line(
            line,
            format!("expected a non-negative integer for {what}, found {tok:?}"),
        )
    })
}

/// Converts a 0-based index to `u32`.
pub(crate) fn index_u32(i: u64, pos: Position) -> Result<u32, ParseError> {
    u32::try_from(i)
        .ok()
        .filter(|&i| i != u32::MAX)
        .ok_or(ParseError {
            position: pos,
            message: format!("vertex index {i} too large"),
        })
}

/// Fans polygon `poly` into `out`: `(p0, p_k, p_k+1)` for `k = 1..n-2`.
pub(crate) fn fan(poly: &[u32], out: &mut Vec<[u32; 3]>) {
    for k in 1..poly.len().saturating_sub(1) {
        out.push([poly[0], poly[k], poly[k + 1]]);
    }
}

/// A capacity guess bounded by what `input_len` bytes can hold at
/// `min_bytes` per item.
pub(crate) fn bounded_capacity(count: usize, input_len: usize, min_bytes: usize) -> usize {
    count.min(input_len / min_bytes.max(1) + 1)
}

/// Formats an `f64` so that parsing it gives the same value.
pub(crate) fn fmt_real(x: f64) -> String {
    format!("{x:?}")
}

/// The vertex and face lines OFF and ASCII PLY share: `x y z` (exact
/// round trip) per vertex, then `3 a b c` per triangle.
pub(crate) fn write_ascii_body(s: &mut String, positions: &[Point], triangles: &[[u32; 3]]) {
    use std::fmt::Write;
    for p in positions {
        let _ = writeln!(
            s,
            "{} {} {}",
            fmt_real(p[0]),
            fmt_real(p[1]),
            fmt_real(p[2])
        );
    }
    for t in triangles {
        let _ = writeln!(s, "3 {} {} {}", t[0], t[1], t[2]);
    }
}
