//! Object File Format: a header `OFF` (or `COFF`, `NOFF`, `CNOFF`, `STOFF`,
//! whose extra columns are ignored), counts `#V #F #E`, then one vertex per
//! line (first three numbers; colour/normal/texture columns ignored) and one
//! face per line `n i1 … in [colour]` (0-based, fanned). `#` starts a
//! comment anywhere. The counts may stand on the header line.

use std::fmt::Write;

use super::text::{
    bounded_capacity, fan, index_u32, parse_count, parse_real, text_lines, write_ascii_body,
};
use super::types::{ParseError, Position, RawMesh};
use crate::mesh::Point;

/// Parses OFF text.
pub(super) fn parse(bytes: &[u8]) -> Result<RawMesh, ParseError> {
    let mut lines = text_lines(bytes, true).filter(|l| match l {
        Ok((_, t)) => !t.trim().is_empty(),
        Err(_) => true,
    });
    let mut last_line = 1;
    let mut next = |what: &str| -> Result<(usize, Vec<&str>), ParseError> {
        match lines.next() {
            Some(Ok((ln, t))) => {
                last_line = ln;
                Ok((ln, t.split_whitespace().collect()))
            }
            Some(Err(e)) => Err(e),
            None => Err(ParseError::line(
                last_line,
                format!("unexpected end of file: expected {what}"),
            )),
        }
    };
    let (ln, head) = next("the OFF header")?;
    let mut counts: Vec<&str> = match head.first() {
        Some(h) if h.ends_with("OFF") && !h.starts_with('4') && !h.starts_with('n') => {
            if head.get(1) == Some(&"BINARY") {
                return Err(ParseError::line(ln, "binary OFF is not supported"));
            }
            head[1..].to_vec()
        }
        Some(h) if h.parse::<usize>().is_ok() => head.clone(),
        _ => {
            return Err(ParseError::line(
                ln,
                format!("expected the OFF header, found {:?}", head.join(" ")),
            ))
        }
    };
    let mut counts_line = ln;
    if counts.is_empty() {
        let (l, c) = next("the counts line \"#V #F #E\"")?;
        counts = c;
        counts_line = l;
    }
    if counts.len() < 2 {
        return Err(ParseError::line(
            counts_line,
            "expected counts \"#V #F [#E]\"",
        ));
    }
    let nv = parse_count(counts[0], counts_line, "the vertex count")?;
    let nf = parse_count(counts[1], counts_line, "the face count")?;
    let mut raw = RawMesh {
        positions: Vec::with_capacity(bounded_capacity(nv, bytes.len(), 6)),
        triangles: Vec::with_capacity(bounded_capacity(nf, bytes.len(), 8)),
    };
    for k in 0..nv {
        let (ln, toks) = next(&format!("vertex {k} of {nv}"))?;
        if toks.len() < 3 {
            return Err(ParseError::line(
                ln,
                format!("vertex {k} has {} numbers, expected 3", toks.len()),
            ));
        }
        let mut p = [0.0; 3];
        for (c, tok) in p.iter_mut().zip(&toks) {
            *c = parse_real(tok, ln, "a vertex coordinate")?;
        }
        raw.positions.push(p);
    }
    let mut poly = Vec::new();
    for k in 0..nf {
        let (ln, toks) = next(&format!("face {k} of {nf}"))?;
        let n = parse_count(toks[0], ln, "the face's corner count")?;
        if n < 3 {
            return Err(ParseError::line(
                ln,
                format!("face {k} has {n} corners, at least 3 needed"),
            ));
        }
        if toks.len() < n + 1 {
            return Err(ParseError::line(
                ln,
                format!(
                    "face {k} announces {n} corners but lists {}",
                    toks.len() - 1
                ),
            ));
        }
        poly.clear();
        for tok in &toks[1..=n] {
            let i = parse_count(tok, ln, "a vertex index")?;
            poly.push(index_u32(i as u64, Position::Line(ln))?);
        }
        fan(&poly, &mut raw.triangles);
    }
    Ok(raw)
}

/// Writes `OFF`, counts, vertices and triangles.
pub(super) fn write(positions: &[Point], triangles: &[[u32; 3]]) -> Vec<u8> {
    let mut s = String::with_capacity(positions.len() * 40 + triangles.len() * 20);
    let _ = writeln!(s, "OFF\n{} {} 0", positions.len(), triangles.len());
    write_ascii_body(&mut s, positions, triangles);
    s.into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coff_with_comments_colours_and_quads() {
        let src = b"COFF # coloured\n# a comment\n4 1 0\n0 0 0 255 0 0 255\n1 0 0 1 2 3 4\n\n1 1 0 1 1 1 1\n0 1 0 1 1 1 1\n4 0 1 2 3 255 0 0\n";
        let raw = parse(src).unwrap();
        assert_eq!(raw.positions[1], [1.0, 0.0, 0.0]);
        assert_eq!(raw.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn truncated_and_huge_counts_are_errors() {
        let e = parse(b"OFF\n3 1 0\n0 0 0\n1 0 0\n").unwrap_err();
        assert_eq!(e.position, Position::Line(4));
        assert!(parse(b"OFF\n18446744073709551615 1 0\n").is_err());
    }
}
