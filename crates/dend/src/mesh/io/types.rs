//! What the readers produce and report: a mesh as parsed, where a parse
//! error is and what it says, and how binary formats are written.

use std::fmt;

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::mesh::{Mesh, MeshError, Point};

/// How binary-capable formats (PLY, STL) are written. OBJ and OFF are always text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Encoding {
    /// Text. Coordinates are written in Rust's shortest round-trip form, so
    /// reading them back gives the same `f64` values.
    Ascii,
    /// Binary little-endian (PLY: `double` coordinates, `uint` indices; STL:
    /// `f32` coordinates as the format prescribes, so STL is lossy for f64).
    #[default]
    BinaryLittleEndian,
    /// Binary big-endian (PLY only; STL is always little-endian).
    BinaryBigEndian,
}

/// Where in the input a parse error happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Position {
    /// 1-based line number (text formats).
    Line(usize),
    /// 0-based byte offset (binary formats).
    Byte(usize),
    /// A structural problem of a glTF document; the message names the element
    /// (`accessor 3`, `mesh 0 primitive 1`, …).
    Document,
}

impl fmt::Display for Position {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Position::Line(l) => write!(f, "line {l}"),
            Position::Byte(b) => write!(f, "byte {b}"),
            Position::Document => f.write_str("document"),
        }
    }
}

/// A malformed or truncated input, with the position of the problem.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
#[error("{position}: {message}")]
pub struct ParseError {
    /// Where the problem is.
    pub position: Position,
    /// What is wrong.
    pub message: String,
}

impl ParseError {
    pub(crate) fn line(line: usize, message: impl Into<String>) -> Self {
        ParseError {
            position: Position::Line(line),
            message: message.into(),
        }
    }
    pub(crate) fn byte(byte: usize, message: impl Into<String>) -> Self {
        ParseError {
            position: Position::Byte(byte),
            message: message.into(),
        }
    }
}

/// Positions and triangles as parsed, not yet validated.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RawMesh {
    /// Vertex positions, `#V×3`.
    pub positions: Vec<Point>,
    /// Triangles, `#F×3` (polygons already fanned).
    pub triangles: Vec<[u32; 3]>,
}

impl RawMesh {
    /// Validates into a [`Mesh`].
    pub fn into_mesh(self) -> Result<Mesh, MeshError> {
        Mesh::new(self.positions, self.triangles)
    }
}
