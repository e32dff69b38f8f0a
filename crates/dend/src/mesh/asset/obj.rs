//! The OBJ asset: the file's lines kept as they are, with the `v` and `vn`
//! lines located so that export rewrites only their coordinates.
//!
//! Positions and faces are read as [`crate::mesh::io`]'s OBJ reader reads
//! them (fan triangulation, negative indices); `vn` indices of face corners
//! (`i//n`, `i/t/n`) are recorded so recomputed normals are grouped per `vn`
//! (see [`super::normals`]). Everything else (`vt`, `g`, `o`, `s`, `usemtl`,
//! `mtllib`, comments, the faces themselves) is copied byte for byte.

use std::fmt::Write as _;

use std::collections::HashMap;

use super::groups::{GroupKind, Part};
use super::normals::group_shading;
use crate::mesh::io::{fan, fmt_real, index_u32, parse_real, text_lines, ParseError, Position};
use crate::mesh::{norm, Point};

/// An OBJ file kept line by line.
#[derive(Debug, Clone)]
pub(crate) struct ObjAsset {
    /// The file's lines (split at `\n`, each keeping a trailing `\r`).
    lines: Vec<String>,
    /// Line index of each `v`.
    v_lines: Vec<usize>,
    /// Line index of each `vn`.
    vn_lines: Vec<usize>,
    /// `vn` vectors as read.
    vn: Vec<Point>,
    /// Positions of the `v` lines.
    pub positions: Vec<Point>,
    /// Fanned triangles over `v`.
    pub triangles: Vec<[u32; 3]>,
    /// `vn` index of each triangle corner (`u32::MAX`: none).
    corner_vn: Vec<[u32; 3]>,
    /// Counts of `vt`, `g`/`o`, `usemtl`, `mtllib` lines.
    counts: [usize; 4],
    /// The name on the first `o` or `g` line.
    pub name: Option<String>,
    /// The `g` and `o` names and the triangles after them.
    pub groups: Vec<Part>,
}

/// The current `g` names and `o` name while reading faces.
#[derive(Default)]
struct Current {
    /// Part index of each name, by (kind, name).
    ids: HashMap<(GroupKind, String), usize>,
    /// The parts the next faces belong to.
    now: Vec<usize>,
    /// The `o` part among them.
    object: Option<usize>,
}

impl Current {
    fn part(&mut self, parts: &mut Vec<Part>, kind: GroupKind, name: &str) -> usize {
        *self.ids.entry((kind, name.to_owned())).or_insert_with(|| {
            parts.push(Part::named(kind, name));
            parts.len() - 1
        })
    }

    /// A `g` line: the faces after it belong to each of its names (none for
    /// a bare `g`) and to the current `o`.
    fn group(&mut self, parts: &mut Vec<Part>, names: &[&str]) {
        self.now = names
            .iter()
            .map(|n| self.part(parts, GroupKind::G, n))
            .collect();
        self.now.extend(self.object);
    }

    /// An `o` line: a new object, and no `g` group until the next `g`.
    fn object(&mut self, parts: &mut Vec<Part>, name: &str) {
        self.object = (!name.is_empty()).then(|| self.part(parts, GroupKind::O, name));
        self.now = self.object.into_iter().collect();
    }

    /// Triangles `range` (just read) belong to the current parts.
    fn add(&self, parts: &mut [Part], range: std::ops::Range<usize>) {
        for &p in &self.now {
            parts[p].push(range.clone());
        }
    }
}

fn resolve(tok: &str, defined: usize, ln: usize, what: &str) -> Result<u32, ParseError> {
    let i: i64 = tok
        .parse()
        .map_err(|_| ParseError::line(ln, format!("expected a {what} index, found {tok:?}")))?;
    let z = match i {
        0 => {
            return Err(ParseError::line(
                ln,
                format!("{what} index 0 (OBJ is 1-based)"),
            ))
        }
        i if i > 0 => i - 1,
        i => defined as i64 + i,
    };
    if z < 0 {
        return Err(ParseError::line(
            ln,
            format!("relative {what} index {i} points before the first"),
        ));
    }
    index_u32(z as u64, Position::Line(ln))
}

impl ObjAsset {
    /// Parses OBJ text, keeping its lines.
    pub fn parse(bytes: &[u8]) -> Result<Self, ParseError> {
        let mut a = ObjAsset {
            lines: Vec::new(),
            v_lines: Vec::new(),
            vn_lines: Vec::new(),
            vn: Vec::new(),
            positions: Vec::new(),
            triangles: Vec::new(),
            corner_vn: Vec::new(),
            counts: [0; 4],
            name: None,
            groups: Vec::new(),
        };
        let mut current = Current::default();
        let mut poly: Vec<(u32, u32)> = Vec::new();
        let mut fanned: Vec<[u32; 3]> = Vec::new();
        for line in text_lines(bytes, true) {
            let (ln, text) = line?;
            let mut toks = text.split_whitespace();
            match toks.next() {
                Some(kw @ ("v" | "vn")) => {
                    let mut p = [0.0; 3];
                    for (k, c) in p.iter_mut().enumerate() {
                        let tok = toks.next().ok_or_else(|| {
                            ParseError::line(ln, format!("{kw} has {k} coordinates, expected 3"))
                        })?;
                        *c = parse_real(tok, ln, "a coordinate")?;
                    }
                    if kw == "v" {
                        a.v_lines.push(ln - 1);
                        a.positions.push(p);
                    } else {
                        a.vn_lines.push(ln - 1);
                        a.vn.push(p);
                    }
                }
                Some("f") => {
                    poly.clear();
                    for tok in toks {
                        let mut parts = tok.split('/');
                        let v =
                            resolve(parts.next().unwrap_or(""), a.positions.len(), ln, "vertex")?;
                        let n = match parts.nth(1) {
                            Some(n) if !n.is_empty() => resolve(n, a.vn.len(), ln, "normal")?,
                            _ => u32::MAX,
                        };
                        if n != u32::MAX && n as usize >= a.vn.len() {
                            return Err(ParseError::line(
                                ln,
                                format!("normal index {} past the {} vn lines", n + 1, a.vn.len()),
                            ));
                        }
                        poly.push((v, n));
                    }
                    if poly.len() < 3 {
                        return Err(ParseError::line(
                            ln,
                            format!("face has {} corners, at least 3 needed", poly.len()),
                        ));
                    }
                    // fan corner positions in the polygon, then map to (v, vn)
                    let slots: Vec<u32> = (0..poly.len() as u32).collect();
                    fanned.clear();
                    fan(&slots, &mut fanned);
                    let start = a.triangles.len();
                    for t in &fanned {
                        a.triangles.push(t.map(|s| poly[s as usize].0));
                        a.corner_vn.push(t.map(|s| poly[s as usize].1));
                    }
                    current.add(&mut a.groups, start..a.triangles.len());
                }
                Some("vt") => a.counts[0] += 1,
                Some(kw @ ("g" | "o")) => {
                    a.counts[1] += 1;
                    let words: Vec<&str> = toks.collect();
                    if kw == "g" {
                        current.group(&mut a.groups, &words);
                    } else {
                        current.object(&mut a.groups, &words.join(" "));
                    }
                    let name = words.join(" ");
                    if a.name.is_none() && !name.is_empty() {
                        a.name = Some(name);
                    }
                }
                Some("usemtl") => a.counts[2] += 1,
                Some("mtllib") => a.counts[3] += 1,
                _ => {}
            }
        }
        a.lines = bytes
            .split(|&b| b == b'\n')
            .map(|l| String::from_utf8_lossy(l).into_owned())
            .collect();
        Ok(a)
    }

    /// What the file holds besides `v` and `f`.
    pub fn kept(&self) -> Vec<String> {
        let mut out = Vec::new();
        let names = ["vt", "g/o", "usemtl", "mtllib"];
        if !self.vn.is_empty() {
            out.push(format!("vn: {}", self.vn.len()));
        }
        for (n, c) in names.iter().zip(self.counts) {
            if c > 0 {
                out.push(format!("{n}: {c}"));
            }
        }
        out
    }

    /// The file with `pose` (one point per `v`) in its `v` lines and the
    /// `vn` lines recomputed on it (angle-weighted over the corners that use
    /// each `vn`; see [`super::normals`]).
    pub fn export(&self, pose: &[Point]) -> Vec<u8> {
        let mut lines = self.lines.clone();
        for (k, &l) in self.v_lines.iter().enumerate() {
            if pose[k] != self.positions[k] {
                lines[l] = replace_coords(&self.lines[l], "v", pose[k]);
            }
        }
        let groups = self.vn.len() + 1;
        let corner: Vec<[u32; 3]> = self
            .corner_vn
            .iter()
            .map(|c| {
                c.map(|n| {
                    if n == u32::MAX {
                        self.vn.len() as u32
                    } else {
                        n
                    }
                })
            })
            .collect();
        let shades = group_shading(&self.positions, pose, &self.triangles, &corner, groups);
        for (k, shade) in shades.iter().take(self.vn.len()).enumerate() {
            let n = self.vn[k];
            let len = norm(n);
            let u = if len > 0.0 { n.map(|x| x / len) } else { n };
            if let Some(new) = shade.normal(u) {
                lines[self.vn_lines[k]] = replace_coords(&self.lines[self.vn_lines[k]], "vn", new);
            }
        }
        lines.join("\n").into_bytes()
    }
}

/// `line` with its first three coordinates replaced by `p` (trailing tokens,
/// such as vertex colours, kept; a trailing comment dropped).
fn replace_coords(line: &str, kw: &str, p: Point) -> String {
    let cr = if line.ends_with('\r') { "\r" } else { "" };
    let body = line.split('#').next().unwrap_or("");
    let rest: Vec<&str> = body.split_whitespace().skip(4).collect();
    let mut s = format!(
        "{kw} {} {} {}",
        fmt_real(p[0]),
        fmt_real(p[1]),
        fmt_real(p[2])
    );
    for t in rest {
        let _ = write!(s, " {t}");
    }
    s.push_str(cr);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUAD: &str = "mtllib a.mtl\no quad\nv 0 0 0\nv 1 0 0\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvn 0 0 1\nusemtl red\nf 1/1/1 2/2/1 3/3/1 4/1/1\n";

    #[test]
    fn identity_export_is_byte_identical() {
        let a = ObjAsset::parse(QUAD.as_bytes()).unwrap();
        assert_eq!(a.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(a.export(&a.positions), QUAD.as_bytes());
    }

    #[test]
    fn export_rewrites_only_v_and_vn_lines() {
        let a = ObjAsset::parse(QUAD.as_bytes()).unwrap();
        // rotate the quad a quarter turn about x: the normal becomes -y
        let pose: Vec<Point> = a
            .positions
            .iter()
            .map(|p| [p[0], -p[2] + 0.0, p[1]])
            .collect();
        let out = String::from_utf8(a.export(&pose)).unwrap();
        let before: Vec<&str> = QUAD.lines().collect();
        let after: Vec<&str> = out.lines().collect();
        assert_eq!(before.len(), after.len());
        for (b, o) in before.iter().zip(&after) {
            if b.starts_with("v ") || b.starts_with("vn ") {
                continue;
            }
            assert_eq!(b, o);
        }
        assert_eq!(after[4], "v 1.0 0.0 1.0 0.5 0.5 0.5");
        let vn: Vec<f64> = after[9]
            .split_whitespace()
            .skip(1)
            .map(|t| t.parse().unwrap())
            .collect();
        assert!(
            (vn[0]).abs() < 1e-12 && (vn[1] + 1.0).abs() < 1e-12 && vn[2].abs() < 1e-12,
            "{vn:?}"
        );
    }
}
