//! The PLY asset: the file's bytes kept as they are, with the location of
//! every vertex's `x y z` (and `nx ny nz`) recorded by the reader, so that
//! export rewrites only those values: extra vertex properties (colours, UVs,
//! custom data), other elements, comments and the faces are copied byte for
//! byte. Binary values are written in their declared type and byte order
//! (integer types rounded); ASCII lines holding a rewritten value are
//! re-joined with single spaces.

use crate::mesh::io::ply::{parse_located, Body, Layout, Loc, Scalar};
use crate::mesh::io::{fmt_real, ParseError};
use crate::mesh::Point;

/// A PLY file with its vertex value locations.
#[derive(Debug, Clone)]
pub(crate) struct PlyAsset {
    bytes: Vec<u8>,
    layout: Layout,
    /// Vertex positions.
    pub positions: Vec<Point>,
    /// Fanned triangles.
    pub triangles: Vec<[u32; 3]>,
}

fn encode(v: f64, ty: Scalar, big_endian: bool) -> Vec<u8> {
    let r = v.round();
    let mut b = match ty {
        Scalar::F32 => (v as f32).to_le_bytes().to_vec(),
        Scalar::F64 => v.to_le_bytes().to_vec(),
        Scalar::I8 => (r as i8).to_le_bytes().to_vec(),
        Scalar::U8 => (r as u8).to_le_bytes().to_vec(),
        Scalar::I16 => (r as i16).to_le_bytes().to_vec(),
        Scalar::U16 => (r as u16).to_le_bytes().to_vec(),
        Scalar::I32 => (r as i32).to_le_bytes().to_vec(),
        Scalar::U32 => (r as u32).to_le_bytes().to_vec(),
    };
    if big_endian {
        b.reverse();
    }
    b
}

impl PlyAsset {
    /// Parses PLY bytes, keeping them.
    pub fn parse(bytes: &[u8]) -> Result<Self, ParseError> {
        let mut layout = Layout::default();
        let raw = parse_located(bytes, Some(&mut layout))?;
        Ok(PlyAsset {
            bytes: bytes.to_vec(),
            layout,
            positions: raw.positions,
            triangles: raw.triangles,
        })
    }

    /// The file's unit normals per vertex (None without `nx ny nz`).
    pub fn normals(&self) -> Vec<Option<Point>> {
        let mut out = vec![None; self.positions.len()];
        for (o, (_, n)) in out.iter_mut().zip(&self.layout.normals) {
            let len = crate::mesh::norm(*n);
            *o = (len > 0.0 && len.is_finite()).then(|| n.map(|x| x / len));
        }
        out
    }

    /// What the file holds besides `x y z` and faces.
    pub fn kept(&self) -> Vec<String> {
        let mut out = Vec::new();
        if !self.layout.normals.is_empty() {
            out.push("nx ny nz".to_owned());
        }
        out.extend(self.layout.extra.iter().cloned());
        out.extend(
            self.layout
                .other_elements
                .iter()
                .map(|e| format!("element {e}")),
        );
        out
    }

    /// The file with `pose` in its `x y z` and `normals` (one per vertex;
    /// None keeps the file's) in its `nx ny nz`.
    pub fn export(&self, pose: &[Point], normals: &[Option<Point>]) -> Vec<u8> {
        let mut edits: Vec<(Loc, f64)> = Vec::new();
        for (k, locs) in self.layout.xyz.iter().enumerate() {
            if pose[k] != self.positions[k] {
                edits.extend(locs.iter().zip(pose[k]).map(|(l, v)| (*l, v)));
            }
        }
        for (k, (locs, _)) in self.layout.normals.iter().enumerate() {
            if let Some(Some(n)) = normals.get(k) {
                edits.extend(locs.iter().zip(*n).map(|(l, v)| (*l, v)));
            }
        }
        let big = self.layout.body == Some(Body::Be);
        if self.layout.body != Some(Body::Ascii) {
            let mut out = self.bytes.clone();
            for (loc, v) in edits {
                if let Loc::Byte(at, ty) = loc {
                    out[at..at + ty.size()].copy_from_slice(&encode(v, ty, big));
                }
            }
            return out;
        }
        let mut lines: Vec<Vec<u8>> = self
            .bytes
            .split(|&b| b == b'\n')
            .map(<[u8]>::to_vec)
            .collect();
        let mut by_line: std::collections::BTreeMap<usize, Vec<(usize, f64, Scalar)>> =
            Default::default();
        for (loc, v) in edits {
            if let Loc::Token(line, tok, ty) = loc {
                by_line.entry(line).or_default().push((tok, v, ty));
            }
        }
        for (line, toks) in by_line {
            let text = String::from_utf8_lossy(&lines[line]).into_owned();
            let cr = if text.ends_with('\r') { "\r" } else { "" };
            let mut words: Vec<String> = text.split_whitespace().map(str::to_owned).collect();
            for (tok, v, ty) in toks {
                if let Some(w) = words.get_mut(tok) {
                    *w = match ty {
                        Scalar::F32 | Scalar::F64 => fmt_real(v),
                        _ => format!("{}", v.round()),
                    };
                }
            }
            lines[line] = format!("{}{cr}", words.join(" ")).into_bytes();
        }
        lines.join(&b'\n')
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "ply\nformat FMT 1.0\ncomment kept\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\nproperty float u\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";

    #[test]
    fn ascii_export_rewrites_only_positions_and_normals() {
        let src = HEADER.replace("FMT", "ascii")
            + "0 0 0 0 0 1 255 0.25\n1 0 0 0 0 1 128 0.5\n0 1 0 0 0 1 7 0.75\n3 0 1 2\n";
        let a = PlyAsset::parse(src.as_bytes()).unwrap();
        assert_eq!(a.kept(), vec!["nx ny nz", "red", "u"]);
        assert_eq!(a.export(&a.positions, &[None; 3]), src.as_bytes());
        let pose: Vec<Point> = a
            .positions
            .iter()
            .map(|p| [p[0], p[1], p[2] + 2.0])
            .collect();
        let out = String::from_utf8(a.export(&pose, &[None; 3])).unwrap();
        assert!(out.contains("\n1.0 0.0 2.0 0 0 1 128 0.5\n"), "{out}");
        assert!(out.ends_with("3 0 1 2\n"));
    }

    #[test]
    fn binary_export_writes_declared_types_in_place() {
        for (fmt, big) in [("binary_little_endian", false), ("binary_big_endian", true)] {
            let mut src = HEADER.replace("FMT", fmt).into_bytes();
            for (p, c) in [
                ([0.0f32, 0.0, 0.0], 255u8),
                ([1.0, 0.0, 0.0], 128),
                ([0.0, 1.0, 0.0], 7),
            ] {
                for x in p.iter().chain(&[0.0, 0.0, 1.0]) {
                    src.extend(encode(f64::from(*x), Scalar::F32, big));
                }
                src.push(c);
                src.extend(encode(0.5, Scalar::F32, big));
            }
            src.extend([3u8]);
            for i in [0i32, 1, 2] {
                src.extend(encode(f64::from(i), Scalar::I32, big));
            }
            let a = PlyAsset::parse(&src).unwrap();
            let pose: Vec<Point> = a
                .positions
                .iter()
                .map(|p| [p[0] + 0.5, p[1], p[2]])
                .collect();
            let out = a.export(&pose, &[None; 3]);
            assert_eq!(out.len(), src.len());
            let back = PlyAsset::parse(&out).unwrap();
            assert_eq!(back.positions, pose);
            // the colours, UVs and faces are the same bytes
            let diff: Vec<usize> = (0..src.len()).filter(|&i| src[i] != out[i]).collect();
            assert!(diff.iter().all(|&i| i >= HEADER.len()), "{fmt}");
            assert_eq!(back.kept(), a.kept());
        }
    }
}
