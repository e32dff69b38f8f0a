//! Polygon File Format: `ascii`, `binary_little_endian` and
//! `binary_big_endian` bodies.
//!
//! The `vertex` element's `x`, `y`, `z` properties (any numeric type) are
//! read; every other property and element is skipped by its declared type.
//! Faces come from the `face` element's `vertex_indices` (or `vertex_index`)
//! list, with any count/index types, and are fanned.
//! Header errors name a line; binary body errors a byte offset.

use std::fmt::Write;

use super::text::{bounded_capacity, fan, index_u32, write_ascii_body};
use super::types::{Encoding, ParseError, Position, RawMesh};
use crate::mesh::Point;

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    pub(crate) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Debug, Clone)]
enum Prop {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
}

/// A PLY body encoding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Body {
    Ascii,
    Le,
    Be,
}

/// Reads scalars from the body, ASCII tokens or binary.
struct Reader<'a> {
    body: Body,
    bytes: &'a [u8],
    pos: usize,
    /// ASCII: current line's tokens and 1-based line number.
    line: usize,
    toks: Vec<&'a str>,
    tok: usize,
}

impl<'a> Reader<'a> {
    fn err(&self, msg: impl Into<String>) -> ParseError {
        match self.body {
            Body::Ascii => ParseError::line(self.line, msg),
            _ => ParseError::byte(self.pos, msg),
        }
    }

    fn next_token(&mut self) -> Result<&'a str, ParseError> {
        while self.tok >= self.toks.len() {
            if self.pos >= self.bytes.len() {
                return Err(self.err("unexpected end of file"));
            }
            let rest = &self.bytes[self.pos..];
            let n = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            let text = std::str::from_utf8(&rest[..n])
                .map_err(|_| ParseError::line(self.line + 1, "invalid UTF-8 in ASCII body"))?;
            self.pos += n + 1;
            self.line += 1;
            self.toks = text.split_whitespace().collect();
            self.tok = 0;
        }
        self.tok += 1;
        Ok(self.toks[self.tok - 1])
    }

    fn read(&mut self, ty: Scalar) -> Result<f64, ParseError> {
        if self.body == Body::Ascii {
            let t = self.next_token()?;
            return t
                .parse::<f64>()
                .map_err(|_| self.err(format!("expected a number, found {t:?}")));
        }
        let n = ty.size();
        let Some(b) = self.bytes.get(self.pos..self.pos + n) else {
            return Err(self.err(format!(
                "truncated: {n}-byte value needed, {} bytes left",
                self.bytes.len().saturating_sub(self.pos)
            )));
        };
        let mut a = [0u8; 8];
        a[..n].copy_from_slice(b);
        if self.body == Body::Be {
            a[..n].reverse();
        }
        self.pos += n;
        Ok(match ty {
            Scalar::I8 => a[0] as i8 as f64,
            Scalar::U8 => a[0] as f64,
            Scalar::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes(a),
        })
    }

    /// Reads a non-negative integer (a list count or an index).
    fn read_uint(&mut self, ty: Scalar, what: &str) -> Result<u64, ParseError> {
        let at = self.pos;
        let v = self.read(ty)?;
        if v >= 0.0 && v.fract() == 0.0 && v < 1.8e19 {
            Ok(v as u64)
        } else {
            let mut e = self.err(format!("{what} must be a non-negative integer, found {v}"));
            if self.body != Body::Ascii {
                e.position = Position::Byte(at);
            }
            Err(e)
        }
    }
}

fn parse_header(bytes: &[u8]) -> Result<(Body, Vec<Element>, usize, usize), ParseError> {
    let mut pos = 0;
    let mut body = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut ln = 0;
    loop {
        ln += 1;
        if pos >= bytes.len() {
            return Err(ParseError::line(
                ln,
                "unexpected end of file in the header (no end_header)",
            ));
        }
        let rest = &bytes[pos..];
        let n = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        pos += n + 1;
        let text = std::str::from_utf8(&rest[..n])
            .map_err(|_| ParseError::line(ln, "invalid UTF-8 in the header"))?;
        let toks: Vec<&str> = text.split_whitespace().collect();
        let bad = |m: &str| ParseError::line(ln, format!("{m}: {:?}", text.trim()));
        if ln == 1 {
            if toks != ["ply"] {
                return Err(bad("not a PLY file (first line must be \"ply\")"));
            }
            continue;
        }
        match toks.as_slice() {
            ["format", f, _ver] => {
                body = Some(match *f {
                    "ascii" => Body::Ascii,
                    "binary_little_endian" => Body::Le,
                    "binary_big_endian" => Body::Be,
                    _ => return Err(bad("unknown PLY format")),
                })
            }
            ["comment", ..] | ["obj_info", ..] | [] => {}
            ["element", name, count] => {
                let count = count
                    .parse::<usize>()
                    .map_err(|_| bad("bad element count"))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", ct, it, name] => {
                let (Some(ct), Some(it)) = (Scalar::from_name(ct), Scalar::from_name(it)) else {
                    return Err(bad("unknown property type"));
                };
                if matches!(ct, Scalar::F32 | Scalar::F64) {
                    return Err(bad("list count type must be an integer type"));
                }
                match elements.last_mut() {
                    Some(e) => e.props.push(Prop::List(name.to_string(), ct, it)),
                    None => return Err(bad("property before any element")),
                }
            }
            ["property", ty, name] => {
                let Some(ty) = Scalar::from_name(ty) else {
                    return Err(bad("unknown property type"));
                };
                match elements.last_mut() {
                    Some(e) => e.props.push(Prop::Scalar(name.to_string(), ty)),
                    None => return Err(bad("property before any element")),
                }
            }
            ["end_header"] => {
                let Some(body) = body else {
                    return Err(bad("end_header before any format line"));
                };
                return Ok((body, elements, pos.min(bytes.len()), ln));
            }
            _ => return Err(bad("unrecognised header line")),
        }
    }
}

/// Where one vertex property value is stored in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Loc {
    /// Binary: byte offset and type.
    Byte(usize, Scalar),
    /// ASCII: 0-based line index in the file, token index on that line, and
    /// the declared type.
    Token(usize, usize, Scalar),
}

/// Where a PLY file keeps each vertex's `x y z` and `nx ny nz` (for
/// [`crate::mesh::asset`], which rewrites only those values).
#[derive(Debug, Clone, Default)]
pub(crate) struct Layout {
    /// The body encoding (None before parsing).
    pub body: Option<Body>,
    /// `x y z` of each vertex.
    pub xyz: Vec<[Loc; 3]>,
    /// `nx ny nz` of each vertex, when the vertex element has all three.
    pub normals: Vec<([Loc; 3], Point)>,
    /// The names of the vertex element's other properties.
    pub extra: Vec<String>,
    /// Other elements than `vertex` and `face`.
    pub other_elements: Vec<String>,
}

/// Parses PLY bytes.
pub(super) fn parse(bytes: &[u8]) -> Result<RawMesh, ParseError> {
    parse_located(bytes, None)
}

/// Parses PLY bytes, recording where vertex values are in `layout`.
pub(crate) fn parse_located(
    bytes: &[u8],
    mut layout: Option<&mut Layout>,
) -> Result<RawMesh, ParseError> {
    let (body, elements, start, header_lines) = parse_header(bytes)?;
    if let Some(l) = layout.as_deref_mut() {
        l.body = Some(body);
    }
    let mut r = Reader {
        body,
        bytes,
        pos: start,
        line: header_lines,
        toks: Vec::new(),
        tok: 0,
    };
    let mut raw = RawMesh::default();
    let mut poly: Vec<u32> = Vec::new();
    for el in &elements {
        if el.props.is_empty() {
            continue;
        }
        let plan = ElementPlan::new(el, &mut raw, layout.as_deref_mut(), bytes.len())?;
        for k in 0..el.count {
            let rec = plan.read_record(&mut r, el, k, &mut poly, &mut raw.triangles)?;
            if plan.is_vertex {
                raw.positions.push(rec.position);
                if let Some(l) = layout.as_deref_mut() {
                    l.xyz.push(rec.locs);
                    if plan.nxyz[0] != usize::MAX {
                        l.normals.push(rec.normal);
                    }
                }
            }
        }
    }
    if !elements
        .iter()
        .any(|el| el.name == "vertex" && !el.props.is_empty())
    {
        return Err(ParseError::line(1, "no vertex element in the header"));
    }
    Ok(raw)
}

/// Which of an element's properties are read as what.
struct ElementPlan {
    /// The `vertex` element (with properties).
    is_vertex: bool,
    /// The property indices of x, y, z (vertex element; else `usize::MAX`).
    xyz: [usize; 3],
    /// The property indices of nx, ny, nz (vertex element with all three;
    /// else `usize::MAX`).
    nxyz: [usize; 3],
    /// The property index of the face element's vertex index list.
    face_list: Option<usize>,
}

/// One record's vertex values, and where they are in the file.
struct Record {
    position: Point,
    locs: [Loc; 3],
    normal: ([Loc; 3], Point),
}

impl ElementPlan {
    /// The plan of `el`; reserves `raw`'s vertices or triangles and records
    /// the vertex element's other properties and the other elements in
    /// `layout`.
    fn new(
        el: &Element,
        raw: &mut RawMesh,
        layout: Option<&mut Layout>,
        len: usize,
    ) -> Result<ElementPlan, ParseError> {
        let none = ElementPlan {
            is_vertex: false,
            xyz: [usize::MAX; 3],
            nxyz: [usize::MAX; 3],
            face_list: None,
        };
        let min_bytes = el.props.len();
        let named = |axis: &str| {
            el.props
                .iter()
                .position(|p| matches!(p, Prop::Scalar(n, _) if n == axis))
        };
        match el.name.as_str() {
            "vertex" => {
                let mut xyz = [usize::MAX; 3];
                for (k, axis) in ["x", "y", "z"].iter().enumerate() {
                    xyz[k] = named(axis).ok_or_else(|| {
                        ParseError::line(1, format!("vertex element has no {axis} property"))
                    })?;
                }
                raw.positions
                    .reserve(bounded_capacity(el.count, len, min_bytes));
                let nxyz = match (named("nx"), named("ny"), named("nz")) {
                    (Some(a), Some(b), Some(c)) => [a, b, c],
                    _ => [usize::MAX; 3],
                };
                if let Some(l) = layout {
                    l.extra = el
                        .props
                        .iter()
                        .enumerate()
                        .filter(|(j, _)| !xyz.contains(j) && !nxyz.contains(j))
                        .map(|(_, p)| match p {
                            Prop::Scalar(n, _) | Prop::List(n, ..) => n.clone(),
                        })
                        .collect();
                }
                Ok(ElementPlan {
                    is_vertex: true,
                    xyz,
                    nxyz,
                    face_list: None,
                })
            }
            "face" => {
                let i = el
                    .props
                    .iter()
                    .position(|p| matches!(p, Prop::List(n, ..) if n == "vertex_indices" || n == "vertex_index"))
                    .ok_or_else(|| ParseError::line(1, "face element has no vertex_indices list"))?;
                raw.triangles
                    .reserve(bounded_capacity(el.count, len, min_bytes * 4));
                Ok(ElementPlan {
                    face_list: Some(i),
                    ..none
                })
            }
            _ => {
                if let Some(l) = layout {
                    l.other_elements.push(el.name.clone());
                }
                Ok(none)
            }
        }
    }

    /// Reads record `k` of `el`: its vertex values (a vertex element), its
    /// polygon fanned into `triangles` (the face element), or skips it.
    fn read_record(
        &self,
        r: &mut Reader,
        el: &Element,
        k: usize,
        poly: &mut Vec<u32>,
        triangles: &mut Vec<[u32; 3]>,
    ) -> Result<Record, ParseError> {
        let mut rec = Record {
            position: [0.0; 3],
            locs: [Loc::Token(0, 0, Scalar::F64); 3],
            normal: ([Loc::Token(0, 0, Scalar::F64); 3], [0.0; 3]),
        };
        for (j, prop) in el.props.iter().enumerate() {
            match prop {
                Prop::Scalar(_, ty) => {
                    let at = r.pos;
                    let v = r.read(*ty)?;
                    let loc = match r.body {
                        Body::Ascii => Loc::Token(r.line - 1, r.tok - 1, *ty),
                        _ => Loc::Byte(at, *ty),
                    };
                    if let Some(c) = self.xyz.iter().position(|&x| x == j) {
                        rec.position[c] = v;
                        rec.locs[c] = loc;
                    }
                    if let Some(c) = self.nxyz.iter().position(|&x| x == j) {
                        rec.normal.0[c] = loc;
                        rec.normal.1[c] = v;
                    }
                }
                Prop::List(_, ct, it) => {
                    let n = r.read_uint(*ct, "a list count")?;
                    let is_faces = self.face_list == Some(j);
                    if is_faces && n < 3 {
                        return Err(r.err(format!("face {k} has {n} corners, at least 3 needed")));
                    }
                    poly.clear();
                    for _ in 0..n {
                        if is_faces {
                            let at = r.pos;
                            let i = r.read_uint(*it, "a vertex index")?;
                            let pos = match r.body {
                                Body::Ascii => Position::Line(r.line),
                                _ => Position::Byte(at),
                            };
                            poly.push(index_u32(i, pos)?);
                        } else {
                            r.read(*it)?;
                        }
                    }
                    if is_faces {
                        fan(poly, triangles);
                    }
                }
            }
        }
        Ok(rec)
    }
}

/// Writes PLY: `double` x y z and a `uchar`/`uint` `vertex_indices` list.
pub(super) fn write(positions: &[Point], triangles: &[[u32; 3]], enc: Encoding) -> Vec<u8> {
    let fmt = match enc {
        Encoding::Ascii => "ascii",
        Encoding::BinaryLittleEndian => "binary_little_endian",
        Encoding::BinaryBigEndian => "binary_big_endian",
    };
    let mut h = String::new();
    let _ = write!(
        h,
        "ply\nformat {fmt} 1.0\ncomment written by dend\nelement vertex {}\n\
         property double x\nproperty double y\nproperty double z\nelement face {}\n\
         property list uchar uint vertex_indices\nend_header\n",
        positions.len(),
        triangles.len()
    );
    let mut out = h.into_bytes();
    match enc {
        Encoding::Ascii => {
            let mut s = String::new();
            write_ascii_body(&mut s, positions, triangles);
            out.extend_from_slice(s.as_bytes());
        }
        Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
            let be = enc == Encoding::BinaryBigEndian;
            out.reserve(positions.len() * 24 + triangles.len() * 13);
            for p in positions {
                for c in p {
                    out.extend_from_slice(&if be { c.to_be_bytes() } else { c.to_le_bytes() });
                }
            }
            for t in triangles {
                out.push(3);
                for i in t {
                    out.extend_from_slice(&if be { i.to_be_bytes() } else { i.to_le_bytes() });
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skips_extra_properties_and_elements() {
        let src = b"ply\nformat ascii 1.0\ncomment hi\nelement vertex 4\nproperty float nx\n\
property float x\nproperty list uchar int junk\nproperty float y\nproperty float z\n\
element face 1\nproperty uchar flags\nproperty list uchar int vertex_index\n\
element edge 1\nproperty int a\nproperty int b\nend_header\n\
9 0 2 7 7 0 0\n9 1 0 0 0\n9 1 0 1 0\n9 0 0 1 0\n5 4 0 1 2 3\n0 1\n";
        let raw = parse(src).unwrap();
        assert_eq!(raw.positions[2], [1.0, 1.0, 0.0]);
        assert_eq!(raw.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn truncated_binary_names_a_byte() {
        let full = write(
            &[[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            &[[0, 1, 2]],
            Encoding::BinaryLittleEndian,
        );
        let cut = &full[..full.len() - 2];
        let e = parse(cut).unwrap_err();
        assert!(matches!(e.position, Position::Byte(_)), "{e}");
    }
}
