//! Readers of the Botsch–Sorkine deformation-survey benchmark files
//! (Botsch & Sorkine, *On Linear Variational Surface Deformation Methods*,
//! TVCG 2008).
//!
//! - `.sel`: after `#` comment lines, one integer per vertex and line:
//!   `0` fixed, `1` free (deformable region), `2` handle.
//! - `.def`: after `#` comment lines, a 4×4 affine matrix of the handle
//!   transform, **row-major as written**, acting on column vectors:
//!   `p' = M · [p; 1]`, translation in the last column (checked on the survey
//!   bar: a 135° rotation about z; on the cylinder: 120° about y plus a
//!   translation that keeps the handle attached).

use std::path::{Path, PathBuf};

use thiserror::Error;

use super::text_lines;
use crate::mesh::Point;

/// Why a `.sel` or `.def` file could not be read.
#[derive(Debug, Error)]
pub enum SurveyError {
    /// The file could not be read. Fix: check the path.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating-system error (in the message, not as a `source`:
        /// chained reports would print it twice).
        error: std::io::Error,
    },
    /// Malformed content. Fix: the message names the line and what was expected.
    #[error("line {line}: {message}")]
    Parse {
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The selection does not match the mesh. Fix: use the `.sel` made for this mesh.
    #[error("selection has {found} entries but the mesh has {expected} vertices")]
    CountMismatch {
        /// Vertices in the mesh.
        expected: usize,
        /// Entries in the selection.
        found: usize,
    },
}

fn perr(line: usize, message: impl Into<String>) -> SurveyError {
    SurveyError::Parse {
        line,
        message: message.into(),
    }
}

/// The role of a vertex in a `.sel` file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum VertexStatus {
    /// `0`: stays in place.
    Fixed,
    /// `1`: deformable region, solved for.
    Free,
    /// `2`: moved by the handle transform.
    Handle,
}

/// A per-vertex selection from a `.sel` file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selection {
    /// One status per vertex, in vertex order.
    pub status: Vec<VertexStatus>,
}

impl Selection {
    /// Indices of the vertices with status `s`, increasing.
    pub fn indices(&self, s: VertexStatus) -> Vec<u32> {
        (0..self.status.len() as u32)
            .filter(|&i| self.status[i as usize] == s)
            .collect()
    }

    /// Checks that the selection has one entry per vertex of a mesh with `nv` vertices.
    pub fn check_len(&self, nv: usize) -> Result<(), SurveyError> {
        if self.status.len() == nv {
            Ok(())
        } else {
            Err(SurveyError::CountMismatch {
                expected: nv,
                found: self.status.len(),
            })
        }
    }
}

/// A handle transform from a `.def` file: `p' = matrix · [p; 1]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandleTransform {
    /// The 4×4 matrix, `matrix[row][col]`, as written in the file.
    pub matrix: [[f64; 4]; 4],
}

impl HandleTransform {
    /// Applies the transform to a point (the last row is assumed `0 0 0 1`,
    /// which [`parse_def`] checks).
    pub fn apply(&self, p: Point) -> Point {
        let m = &self.matrix;
        std::array::from_fn(|r| m[r][0] * p[0] + m[r][1] * p[1] + m[r][2] * p[2] + m[r][3])
    }
}

/// Parses a `.sel` file.
pub fn parse_sel(bytes: &[u8]) -> Result<Selection, SurveyError> {
    let mut status = Vec::new();
    for line in text_lines(bytes, true) {
        let (ln, text) = line.map_err(|e| perr(e_line(&e), e.message))?;
        let t = text.trim();
        if t.is_empty() {
            continue;
        }
        status.push(match t {
            "0" => VertexStatus::Fixed,
            "1" => VertexStatus::Free,
            "2" => VertexStatus::Handle,
            _ => {
                return Err(perr(
                    ln,
                    format!(
                        "expected a vertex status 0 (fixed), 1 (free) or 2 (handle), found {t:?}"
                    ),
                ))
            }
        });
    }
    if status.is_empty() {
        return Err(perr(1, "no vertex status in the file"));
    }
    Ok(Selection { status })
}

fn e_line(e: &super::ParseError) -> usize {
    match e.position {
        super::Position::Line(l) | super::Position::Byte(l) => l,
        super::Position::Document => 0,
    }
}

/// Parses a `.def` file.
pub fn parse_def(bytes: &[u8]) -> Result<HandleTransform, SurveyError> {
    let mut rows: Vec<[f64; 4]> = Vec::with_capacity(4);
    let mut last = 1;
    for line in text_lines(bytes, true) {
        let (ln, text) = line.map_err(|e| perr(e_line(&e), e.message))?;
        let toks: Vec<&str> = text.split_whitespace().collect();
        if toks.is_empty() {
            continue;
        }
        last = ln;
        if rows.len() == 4 {
            return Err(perr(ln, "content after the 4 matrix rows"));
        }
        if toks.len() != 4 {
            return Err(perr(
                ln,
                format!("matrix row has {} numbers, expected 4", toks.len()),
            ));
        }
        let mut row = [0.0; 4];
        for (v, t) in row.iter_mut().zip(&toks) {
            *v = t
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| perr(ln, format!("expected a finite number, found {t:?}")))?;
        }
        if rows.len() == 3 && row != [0.0, 0.0, 0.0, 1.0] {
            return Err(perr(
                ln,
                "last matrix row must be \"0 0 0 1\" (affine transform)",
            ));
        }
        rows.push(row);
    }
    if rows.len() < 4 {
        return Err(perr(
            last,
            format!("unexpected end of file: {} of 4 matrix rows", rows.len()),
        ));
    }
    Ok(HandleTransform {
        matrix: [rows[0], rows[1], rows[2], rows[3]],
    })
}

fn read(path: &Path) -> Result<Vec<u8>, SurveyError> {
    std::fs::read(path).map_err(|error| SurveyError::Io {
        path: path.to_path_buf(),
        error,
    })
}

/// Reads a `.sel` file.
pub fn read_sel(path: &Path) -> Result<Selection, SurveyError> {
    parse_sel(&read(path)?)
}

/// Reads a `.def` file.
pub fn read_def(path: &Path) -> Result<HandleTransform, SurveyError> {
    parse_def(&read(path)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sel_and_def_parse_and_name_lines() {
        let s = parse_sel(b"# status\n# 3 vertices\n0\n1\n2\n").unwrap();
        assert_eq!(s.indices(VertexStatus::Handle), vec![2]);
        assert!(matches!(
            parse_sel(b"# x\n0\n7\n"),
            Err(SurveyError::Parse { line: 3, .. })
        ));
        let d = parse_def(b"# m\n0 -1 0 1\n1 0 0 0\n0 0 1 0\n0 0 0 1\n").unwrap();
        assert_eq!(d.apply([1.0, 0.0, 0.0]), [1.0, 1.0, 0.0]);
        assert!(matches!(
            parse_def(b"# m\n1 0 0\n"),
            Err(SurveyError::Parse { line: 2, .. })
        ));
        assert!(matches!(
            parse_def(b"1 0 0 0\n0 1 0 0\n"),
            Err(SurveyError::Parse { line: 2, .. })
        ));
    }
}
