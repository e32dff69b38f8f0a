//! Mesh readers and writers: OBJ, OFF, PLY (ASCII, binary little- and
//! big-endian), STL (ASCII and binary), glTF 2.0 (`.gltf`, `.glb`), plus a JSON form for the server and the
//! Botsch–Sorkine survey `.sel`/`.def` files ([`survey`]).
//!
//! Reading has two stages: [`parse_bytes`] turns bytes into a [`RawMesh`]
//! (positions and triangles, no validation; every malformed or truncated input
//! is a [`ParseError`] with a line or byte position, never a panic), and
//! [`read_bytes`] then validates it with [`Mesh::new`].
//!
//! Conventions shared by all readers:
//! - **Polygons are triangulated by fan**: a face `v0 v1 … vk` becomes
//!   `(v0, v1, v2), (v0, v2, v3), …, (v0, vk-1, vk)` (OBJ, OFF, PLY).
//! - **STL is welded**: STL stores three corners per facet; corners whose
//!   coordinates are *exactly* equal (bitwise, after mapping `-0.0` to `0.0`)
//!   become one vertex, numbered in order of first appearance. Nearly-equal
//!   corners are not merged.
//! - Normals, texture coordinates, colours and other per-vertex properties are
//!   ignored by these plain readers (a [`crate::mesh::asset::Asset`] keeps them
//!   for glTF/GLB and OBJ); unreferenced vertices are kept (see [`crate::mesh`]).
//! - glTF/GLB ([`gltf`]) read as the scene's welded surface, positions `f32`.
//! - Header counts (OFF, PLY, STL) never drive allocation beyond what the
//!   input's length can hold.
//!
//! The parsers are hand-written: the crates available (`tobj`, `ply-rs`,
//! `stl_io`) report no line/byte position for errors and pre-allocate from
//! header counts, which the error-position and bounded-allocation
//! requirements rule out.

pub mod gltf;
mod obj;
mod off;
pub(crate) mod ply;
mod stl;
pub mod survey;
mod text;
mod types;

pub(crate) use text::{fan, fmt_real, index_u32, parse_real, text_lines};
pub use types::{Encoding, ParseError, Position, RawMesh};

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::{Mesh, MeshError, Point};

/// A mesh file format, chosen from the file extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// Wavefront OBJ (`.obj`): text, 1-based (or negative relative) indices.
    Obj,
    /// Object File Format (`.off`, also `COFF`/`NOFF` headers): text.
    Off,
    /// Polygon File Format (`.ply`): ASCII or binary.
    Ply,
    /// Stereolithography (`.stl`): ASCII or binary, triangle soup (welded).
    Stl,
    /// glTF 2.0 JSON (`.gltf`), buffers embedded as data URIs or side-car
    /// files ([`gltf`]).
    Gltf,
    /// glTF 2.0 binary (`.glb`) ([`gltf`]).
    Glb,
}

impl Format {
    /// All formats, in a fixed order.
    pub const ALL: [Format; 6] = [
        Format::Obj,
        Format::Off,
        Format::Ply,
        Format::Stl,
        Format::Gltf,
        Format::Glb,
    ];

    /// The format named by `path`'s extension (case-insensitive).
    pub fn from_path(path: &Path) -> Result<Format, IoError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("obj") => Ok(Format::Obj),
            Some("off") => Ok(Format::Off),
            Some("ply") => Ok(Format::Ply),
            Some("stl") => Ok(Format::Stl),
            Some("gltf") => Ok(Format::Gltf),
            Some("glb") => Ok(Format::Glb),
            _ => Err(IoError::UnknownFormat {
                path: path.to_path_buf(),
            }),
        }
    }

    /// The usual file extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Obj => "obj",
            Format::Off => "off",
            Format::Ply => "ply",
            Format::Stl => "stl",
            Format::Gltf => "gltf",
            Format::Glb => "glb",
        }
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Format::Obj => "OBJ",
            Format::Off => "OFF",
            Format::Ply => "PLY",
            Format::Stl => "STL",
            Format::Gltf => "glTF",
            Format::Glb => "GLB",
        })
    }
}

/// Why a mesh could not be read or written.
#[derive(Debug, Error)]
pub enum IoError {
    /// The file could not be opened, read or written. Fix: check the path and permissions.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error (in the message, not as a `source`:
        /// chained reports would print it twice).
        error: std::io::Error,
    },
    /// The extension names no supported format. Fix: use `.obj`, `.off`, `.ply`, `.stl`, `.gltf` or `.glb`.
    #[error("{path}: unknown mesh format (expected .obj, .off, .ply, .stl, .gltf or .glb)")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The content is malformed or truncated. Fix: repair or re-export the file.
    #[error("{format} parse error at {position}: {message}")]
    Parse {
        /// The format being read.
        format: Format,
        /// Where the problem is.
        position: Position,
        /// What is wrong.
        message: String,
    },
    /// The file parsed but the mesh is invalid (NaN, bad index, non-manifold, …).
    /// (The validation's message is in this one, not a `source`: chained
    /// reports would print it twice.)
    #[error("invalid mesh: {0}")]
    Mesh(MeshError),
    /// The JSON form `{positions, triangles}` is malformed.
    #[error("JSON mesh parse error at line {line}, column {column}: {message}")]
    Json {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
}

impl From<MeshError> for IoError {
    fn from(e: MeshError) -> Self {
        IoError::Mesh(e)
    }
}

impl IoError {
    fn parse(format: Format, e: ParseError) -> Self {
        IoError::Parse {
            format,
            position: e.position,
            message: e.message,
        }
    }
}

/// Parses `bytes` in `format` without validating the mesh (used by the fuzzers).
///
/// glTF/GLB give the scene's welded surface without its degenerate
/// triangles (see [`crate::mesh::asset`]);
/// side-car buffers are refused here ([`crate::mesh::asset::Asset::read_path`]
/// reads them).
pub fn parse_bytes(bytes: &[u8], format: Format) -> Result<RawMesh, ParseError> {
    match format {
        Format::Obj => obj::parse(bytes),
        Format::Off => off::parse(bytes),
        Format::Ply => ply::parse(bytes),
        Format::Stl => stl::parse(bytes),
        Format::Gltf | Format::Glb => parse_gltf(bytes, gltf::Sidecars::Refuse),
    }
}

fn parse_gltf(bytes: &[u8], sidecars: gltf::Sidecars<'_>) -> Result<RawMesh, ParseError> {
    let g = gltf::GltfAsset::parse(bytes, sidecars).map_err(|e| gltf_parse_error(&e))?;
    let w = crate::mesh::weld::weld(g.positions(), g.triangles());
    let positions = w.positions(g.positions());
    let mut triangles = w.triangles(g.triangles());
    crate::mesh::weld::drop_degenerate(&positions, &mut triangles);
    Ok(RawMesh {
        positions,
        triangles,
    })
}

/// A glTF error as a [`ParseError`] (GLB offsets and JSON lines kept).
pub(crate) fn gltf_parse_error(e: &gltf::GltfError) -> ParseError {
    let position = match e {
        gltf::GltfError::Glb { offset, .. } => Position::Byte(*offset),
        gltf::GltfError::Json { line, .. } => Position::Line(*line),
        _ => Position::Document,
    };
    ParseError {
        position,
        message: e.to_string(),
    }
}

/// Parses and validates `bytes` in `format`.
pub fn read_bytes(bytes: &[u8], format: Format) -> Result<Mesh, IoError> {
    let raw = parse_bytes(bytes, format).map_err(|e| IoError::parse(format, e))?;
    Ok(raw.into_mesh()?)
}

/// Reads the file at `path` (format from its extension) without validating.
pub fn parse_path(path: &Path) -> Result<RawMesh, IoError> {
    let format = Format::from_path(path)?;
    let bytes = std::fs::read(path).map_err(|error| IoError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    match format {
        Format::Gltf | Format::Glb => {
            let dir = path.parent().unwrap_or(Path::new("."));
            parse_gltf(&bytes, gltf::Sidecars::Folder(dir))
        }
        _ => parse_bytes(&bytes, format),
    }
    .map_err(|e| IoError::parse(format, e))
}

/// Reads and validates the mesh at `path` (format from its extension).
pub fn read_path(path: &Path) -> Result<Mesh, IoError> {
    Ok(parse_path(path)?.into_mesh()?)
}

/// Serialises `positions`/`triangles` (a rest mesh or a deformed pose) in
/// `format` with the default [`Encoding`] (binary for PLY and STL).
pub fn to_bytes(positions: &[Point], triangles: &[[u32; 3]], format: Format) -> Vec<u8> {
    to_bytes_with(positions, triangles, format, Encoding::default())
}

/// Serialises `positions`/`triangles` in `format` with `encoding` (ignored by
/// the text-only OBJ and OFF and by glTF/GLB, whose positions are `f32`; STL
/// has no big-endian form and writes little-endian).
pub fn to_bytes_with(
    positions: &[Point],
    triangles: &[[u32; 3]],
    format: Format,
    encoding: Encoding,
) -> Vec<u8> {
    match format {
        Format::Obj => obj::write(positions, triangles),
        Format::Off => off::write(positions, triangles),
        Format::Ply => ply::write(positions, triangles, encoding),
        Format::Stl => stl::write(positions, triangles, encoding),
        Format::Gltf => gltf::write_mesh(positions, triangles, gltf::Container::Json),
        Format::Glb => gltf::write_mesh(positions, triangles, gltf::Container::Glb),
    }
}

/// Writes `mesh` to `path` (format from the extension, default encoding).
pub fn write_path(path: &Path, mesh: &Mesh) -> Result<(), IoError> {
    write_path_with(
        path,
        mesh.positions(),
        mesh.triangles(),
        Encoding::default(),
    )
}

/// Writes `positions`/`triangles` to `path` (format from the extension).
pub fn write_path_with(
    path: &Path,
    positions: &[Point],
    triangles: &[[u32; 3]],
    encoding: Encoding,
) -> Result<(), IoError> {
    let format = Format::from_path(path)?;
    std::fs::write(path, to_bytes_with(positions, triangles, format, encoding)).map_err(|error| {
        IoError::Io {
            path: path.to_path_buf(),
            error,
        }
    })
}

/// The JSON form of a mesh used by the server:
/// `{"positions": [[x,y,z], …], "triangles": [[i,j,k], …]}` (0-based indices).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JsonMesh {
    /// Vertex positions, `#V×3`.
    pub positions: Vec<Point>,
    /// Triangles, `#F×3`, 0-based.
    pub triangles: Vec<[u32; 3]>,
}

/// Parses the JSON form without validating.
pub fn parse_json(bytes: &[u8]) -> Result<RawMesh, IoError> {
    let m: JsonMesh = serde_json::from_slice(bytes).map_err(|e| IoError::Json {
        line: e.line(),
        column: e.column(),
        message: e.to_string(),
    })?;
    Ok(RawMesh {
        positions: m.positions,
        triangles: m.triangles,
    })
}

/// Parses and validates the JSON form.
pub fn read_json(bytes: &[u8]) -> Result<Mesh, IoError> {
    Ok(parse_json(bytes)?.into_mesh()?)
}
