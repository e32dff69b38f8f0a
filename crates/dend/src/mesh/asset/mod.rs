//! Assets: a mesh file kept with its own vertex layout and everything it
//! holds, plus the welded surface the solver deforms.
//!
//! An [`Asset`] has two vertex numberings:
//! - **asset vertices**: the file's own (glTF POSITION elements of the
//!   scene's primitives; OBJ `v` lines; other formats' vertices), which may
//!   be split along UV or normal seams;
//! - **welded vertices**: the solver's [`Mesh`], where seam copies are one
//!   vertex (rule in [`weld`]), with a map asset → welded. Constraint vertex
//!   indices (and `.sel` files) name welded vertices; for a file without
//!   seam copies the two numberings are the same.
//!
//! [`Asset::export`] writes a welded pose back in the asset's layout, in its
//! own format family (glTF/GLB ↔ glTF/GLB, OBJ → OBJ, PLY → PLY); any other target
//! format gets the welded mesh as a plain file.
//!
//! | format | kept (copied) | recomputed |
//! |---|---|---|
//! | glTF / GLB | vertex count and layout, indices, UVs, colours, joints, weights, morph targets, materials, textures, images, skins, animations, extensions, extras, TANGENT `w` | POSITION (local = inverse node matrix × world pose), POSITION `min`/`max`, NORMAL (recomputed, angle-weighted) and TANGENT `xyz` (turned, re-orthogonalised) ([`normals`]); buffers merged into one |
//! | OBJ | every line (`vt`, `g`, `o`, `s`, `usemtl`, `mtllib`, comments, faces with their `v/vt/vn` indices, vertex colours after `v x y z`) | the coordinates of `v` lines and of `vn` lines ([`normals`], recomputed per `vn` index) |
//! | PLY | every byte but the vertices' `x y z` and `nx ny nz` values: extra vertex properties (colours, UVs, …), other elements, comments, faces | `x y z`; `nx ny nz` (recomputed, [`normals`]) |
//!
//! Named parts (OBJ `g`/`o`, glTF nodes, meshes, primitives) are kept for
//! constraints that select vertices by them ([`groups`]).
//! | OFF, STL | vertices and triangles | positions (written as a plain mesh) |

pub mod groups;
mod morph;
pub mod normals;
mod obj;
mod ply;
pub mod sample;
pub use crate::mesh::weld;

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::mesh::io::gltf::{Container, GltfAsset, GltfSummary, MorphTarget, Shading, Sidecars};
use crate::mesh::io::{self, Format, IoError};
use crate::mesh::{Mesh, Point};
use groups::{welded_vertices, GroupInfo, GroupRef, Part};
use normals::{group_shading, Shade};
use obj::ObjAsset;
use ply::PlyAsset;
use weld::Weld;

pub use morph::MorphExportError;

/// What kept the file's own data.
#[derive(Debug, Clone)]
enum Source {
    Gltf(Box<GltfAsset>),
    Obj(ObjAsset),
    Ply(PlyAsset),
    /// A format whose extra data is not kept (OFF, STL, JSON).
    Plain,
}

/// A mesh file with its own layout, and its welded surface.
#[derive(Debug, Clone)]
pub struct Asset {
    format: Format,
    source: Source,
    /// Asset vertex positions (world space for glTF), `#A×3`.
    positions: Vec<Point>,
    /// Triangles over asset vertices, in file order.
    triangles: Vec<[u32; 3]>,
    weld: Weld,
    mesh: Mesh,
    dropped: usize,
    /// Named parts (OBJ `g`/`o`, glTF nodes, meshes, primitives).
    parts: Vec<Part>,
}

/// What `dend info` and the server report about an asset.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct AssetInfo {
    /// The file format.
    pub format: Format,
    /// The asset's name: the glTF scene's (else its first deformed mesh's),
    /// the name on the OBJ's first `o` or `g` line.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Vertices in the file's layout.
    pub asset_vertices: usize,
    /// Vertices of the welded surface the solver deforms.
    pub welded_vertices: usize,
    /// Triangles in the file (fanned).
    pub triangles: usize,
    /// Degenerate file triangles (a repeated vertex after welding, or zero
    /// area as [`Mesh::new`] judges it) left out of the welded surface; the
    /// file keeps them and export writes their vertices like any other.
    #[serde(default)]
    pub dropped_triangles: usize,
    /// What the file holds besides positions and triangles, as kept by
    /// export (`TEXCOORD_0`, `vt`, `usemtl`, `skin`, …).
    pub attributes: Vec<String>,
    /// glTF counts (meshes, primitives, skins, …), for glTF/GLB.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gltf: Option<GltfSummary>,
    /// The named parts constraints can select by (`{"group": …}`, see
    /// [`groups`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub groups: Vec<GroupInfo>,
}

fn parse_error(format: Format, e: io::ParseError) -> IoError {
    IoError::Parse {
        format,
        position: e.position,
        message: e.message,
    }
}

impl Asset {
    /// Reads `bytes` as `format`, keeping the layout for glTF/GLB and OBJ.
    /// Side-car glTF buffers are read as `sidecars` says.
    pub fn read_bytes(
        bytes: &[u8],
        format: Format,
        sidecars: Sidecars<'_>,
    ) -> Result<Self, IoError> {
        let mut parts = Vec::new();
        let (source, positions, triangles) = match format {
            Format::Gltf | Format::Glb => {
                let g = GltfAsset::parse(bytes, sidecars)
                    .map_err(|e| parse_error(format, io::gltf_parse_error(&e)))?;
                let (p, t) = (g.positions().to_vec(), g.triangles().to_vec());
                parts = groups::gltf_parts(g.parts());
                (Source::Gltf(Box::new(g)), p, t)
            }
            Format::Obj => {
                let mut o = ObjAsset::parse(bytes).map_err(|e| parse_error(format, e))?;
                let (p, t) = (o.positions.clone(), o.triangles.clone());
                parts = std::mem::take(&mut o.groups);
                (Source::Obj(o), p, t)
            }
            Format::Ply => {
                let o = PlyAsset::parse(bytes).map_err(|e| parse_error(format, e))?;
                let (p, t) = (o.positions.clone(), o.triangles.clone());
                (Source::Ply(o), p, t)
            }
            _ => {
                let raw = io::parse_bytes(bytes, format).map_err(|e| parse_error(format, e))?;
                (Source::Plain, raw.positions, raw.triangles)
            }
        };
        let mut asset = Self::assemble(format, source, positions, triangles)?;
        asset.parts = parts;
        Ok(asset)
    }

    /// Reads the file at `path` (format from its extension; glTF side-car
    /// buffers from its folder).
    pub fn read_path(path: &Path) -> Result<Self, IoError> {
        let format = Format::from_path(path)?;
        let bytes = std::fs::read(path).map_err(|error| IoError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        let dir = path.parent().unwrap_or(Path::new("."));
        Self::read_bytes(&bytes, format, Sidecars::Folder(dir))
    }

    /// A plain asset of `mesh` (nothing kept besides the mesh).
    pub fn from_mesh(mesh: Mesh, format: Format) -> Self {
        let n = mesh.num_vertices();
        Asset {
            format,
            source: Source::Plain,
            positions: mesh.positions().to_vec(),
            triangles: mesh.triangles().to_vec(),
            weld: Weld {
                to_welded: (0..n as u32).collect(),
                welded: n,
            },
            mesh,
            dropped: 0,
            parts: Vec::new(),
        }
    }

    fn assemble(
        format: Format,
        source: Source,
        positions: Vec<Point>,
        triangles: Vec<[u32; 3]>,
    ) -> Result<Self, IoError> {
        let weld = match source {
            // plain formats keep their numbering (STL is welded by its reader)
            Source::Plain => Weld {
                to_welded: (0..positions.len() as u32).collect(),
                welded: positions.len(),
            },
            _ => weld::weld(&positions, &triangles),
        };
        let welded = weld.positions(&positions);
        let mut tris = weld.triangles(&triangles);
        let all = tris.len();
        if !matches!(source, Source::Plain) {
            weld::drop_degenerate(&welded, &mut tris);
        }
        let dropped = all - tris.len();
        let mesh = Mesh::new(welded, tris)?;
        Ok(Asset {
            format,
            source,
            positions,
            triangles,
            weld,
            mesh,
            dropped,
            parts: Vec::new(),
        })
    }

    /// The welded surface the solver deforms.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The format the asset was read from.
    pub fn format(&self) -> Format {
        self.format
    }

    /// The glTF document kept, for an asset read from glTF/GLB.
    pub fn gltf(&self) -> Option<&GltfAsset> {
        match &self.source {
            Source::Gltf(g) => Some(g),
            _ => None,
        }
    }

    /// Asset vertex → welded vertex, `#A`.
    pub fn to_welded(&self) -> &[u32] {
        &self.weld.to_welded
    }

    /// Asset vertex positions (glTF: world space).
    pub fn positions(&self) -> &[Point] {
        &self.positions
    }

    /// Triangles over asset vertices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Counts and kept attributes.
    pub fn info(&self) -> AssetInfo {
        let name = match &self.source {
            Source::Gltf(g) => g.summary().name.clone(),
            Source::Obj(o) => o.name.clone(),
            _ => None,
        };
        let (attributes, gltf) = match &self.source {
            Source::Gltf(g) => {
                let s = g.summary().clone();
                let mut a = s.attributes.clone();
                if s.materials > 0 {
                    a.push(format!("materials: {}", s.materials));
                }
                if s.skins > 0 {
                    a.push(format!("skins: {}", s.skins));
                }
                if s.morph_targets > 0 {
                    a.push(format!("morph targets: {}", s.morph_targets));
                }
                if s.animations > 0 {
                    a.push(format!("animations: {}", s.animations));
                }
                (a, Some(s))
            }
            Source::Obj(o) => (o.kept(), None),
            Source::Ply(o) => (o.kept(), None),
            Source::Plain => (Vec::new(), None),
        };
        AssetInfo {
            format: self.format,
            name,
            asset_vertices: self.positions.len(),
            welded_vertices: self.mesh.num_vertices(),
            triangles: self.triangles.len(),
            dropped_triangles: self.dropped,
            attributes,
            gltf,
            groups: self.groups(),
        }
    }

    /// The welded `pose` (`#W×3`) on the asset layout: asset vertex `a` at
    /// `pose[to_welded[a]]`.
    pub fn asset_pose(&self, pose: &[Point]) -> Result<Vec<Point>, IoError> {
        if pose.len() != self.mesh.num_vertices() {
            return Err(crate::mesh::MeshError::VertexCountMismatch {
                expected: self.mesh.num_vertices(),
                got: pose.len(),
            }
            .into());
        }
        Ok(self.weld.spread(pose))
    }

    /// What an [`export`](Self::export) as `format` leaves out: nothing in
    /// the asset's own format family, else every attribute the asset holds
    /// besides positions (`TEXCOORD_0`, `NORMAL`, `skins: 1`, `vt: 120`, …,
    /// as [`AssetInfo::attributes`] lists them), since the other formats
    /// get the welded surface as a plain mesh: positions and triangles.
    pub fn dropped_by(&self, format: Format) -> Vec<String> {
        let own = matches!(
            (&self.source, format),
            (Source::Gltf(_), Format::Gltf | Format::Glb)
                | (Source::Obj(_), Format::Obj)
                | (Source::Ply(_), Format::Ply)
        );
        if own {
            Vec::new()
        } else {
            let mut a = self.info().attributes;
            a.retain(|a| a != "POSITION");
            a
        }
    }

    /// Writes the welded `pose` as `format`: in the asset's own layout when
    /// `format` is of the asset's family (glTF/GLB for a glTF asset, OBJ for
    /// an OBJ asset, PLY for a PLY asset), else as a plain mesh of the welded
    /// surface.
    pub fn export(&self, pose: &[Point], format: Format) -> Result<Vec<u8>, IoError> {
        let asset_pose = self.asset_pose(pose)?;
        match (&self.source, format) {
            (Source::Gltf(g), Format::Gltf | Format::Glb) => {
                let container = if format == Format::Glb {
                    Container::Glb
                } else {
                    Container::Json
                };
                Ok(g.export(&asset_pose, &self.gltf_shading(g, &asset_pose), container))
            }
            (Source::Obj(o), Format::Obj) => Ok(o.export(&asset_pose)),
            (Source::Ply(o), Format::Ply) => {
                let file = o.normals();
                let shades = self.vertex_shades(&file, &asset_pose);
                let normals: Vec<Option<Point>> = file
                    .iter()
                    .zip(&shades)
                    .map(|(n, s)| n.and_then(|n| s.normal(n)))
                    .collect();
                Ok(o.export(&asset_pose, &normals))
            }
            _ => Ok(io::to_bytes(pose, self.mesh.triangles(), format)),
        }
    }

    /// The [`Shade`] of each asset vertex's normal group (groups: welded
    /// vertex × the file normal's bits; see [`normals`]).
    fn vertex_shades(&self, file_normals: &[Option<Point>], pose: &[Point]) -> Vec<Shade> {
        let mut ids = std::collections::HashMap::new();
        let group: Vec<u32> = (0..self.positions.len())
            .map(|a| {
                let n = file_normals.get(a).copied().flatten();
                let key = (self.weld.to_welded[a], n.map(|n| n.map(f64::to_bits)));
                let next = ids.len() as u32;
                *ids.entry(key).or_insert(next)
            })
            .collect();
        let corner: Vec<[u32; 3]> = self
            .triangles
            .iter()
            .map(|t| t.map(|a| group[a as usize]))
            .collect();
        let shades = group_shading(&self.positions, pose, &self.triangles, &corner, ids.len());
        group.iter().map(|&g| shades[g as usize]).collect()
    }

    /// The normals and tangents [`Asset::export`] writes for `pose` (asset
    /// layout, world space) of a glTF asset; empty for other assets.
    pub fn gltf_pose_shading(&self, pose: &[Point]) -> Shading {
        match &self.source {
            Source::Gltf(g) => self.gltf_shading(g, pose),
            _ => Shading::default(),
        }
    }

    /// New normals (recomputed) and tangents (turned, orthogonalised), world
    /// space, for a glTF pose: see [`normals`].
    fn gltf_shading(&self, g: &GltfAsset, pose: &[Point]) -> Shading {
        let shades = self.vertex_shades(g.normals(), pose);
        let normals = (0..self.positions.len())
            .map(|a| g.normals()[a].and_then(|n| shades[a].normal(n)))
            .collect();
        let tangents = (0..self.positions.len())
            .map(|a| g.tangents()[a].and_then(|t| shades[a].tangent(t, g.normals()[a])))
            .collect();
        Shading { normals, tangents }
    }
}

impl Asset {
    /// The asset's named parts, with the welded vertices each selects.
    pub fn groups(&self) -> Vec<GroupInfo> {
        self.parts
            .iter()
            .map(|p| GroupInfo {
                kind: p.kind,
                name: p.name.clone(),
                index: p.index,
                primitive: p.primitive,
                triangles: p.triangles(),
                vertices: welded_vertices([p], &self.triangles, &self.weld.to_welded, &self.mesh)
                    .len(),
            })
            .collect()
    }

    /// The welded vertices `group` selects (sorted): the union of the
    /// matching parts' vertices; `None` when no part matches (see
    /// `Asset::group_vertices`, which says which parts there are).
    pub(crate) fn matching_vertices(&self, group: &GroupRef) -> Option<Vec<u32>> {
        let hits: Vec<&Part> = self.parts.iter().filter(|p| p.matches(group)).collect();
        if hits.is_empty() {
            return None;
        }
        Some(welded_vertices(
            hits,
            &self.triangles,
            &self.weld.to_welded,
            &self.mesh,
        ))
    }

    /// The asset's parts, as an unknown group's error lists them.
    pub(crate) fn part_names(&self) -> Vec<String> {
        self.parts.iter().map(Part::to_string).collect()
    }
}

impl Asset {
    /// The asset as read plus one morph target per `(name, welded pose)`
    /// (each `#W×3`) on every deformed primitive, as `format` (glTF or GLB);
    /// with `animation`, an animation keying the weights through them in
    /// order. Normals of each pose are those [`Asset::export`] writes.
    pub fn export_morph_targets(
        &self,
        poses: &[(String, &[Point])],
        animation: bool,
        format: Format,
    ) -> Result<Vec<u8>, MorphExportError> {
        let container = match format {
            Format::Glb => Container::Glb,
            Format::Gltf => Container::Json,
            requested => {
                return Err(MorphExportError::NotGltf {
                    asset: self.format,
                    requested,
                })
            }
        };
        let Source::Gltf(g) = &self.source else {
            return Err(MorphExportError::NotGltf {
                asset: self.format,
                requested: format,
            });
        };
        let targets = poses
            .iter()
            .map(|(name, pose)| {
                let pose = self.asset_pose(pose)?;
                let shading = self.gltf_shading(g, &pose);
                Ok(MorphTarget {
                    name: name.clone(),
                    pose,
                    shading,
                })
            })
            .collect::<Result<Vec<_>, IoError>>()?;
        Ok(g.export_morph_targets(&targets, animation, container))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degenerate_asset_triangles_are_left_out_of_the_welded_surface() {
        // a quad, a triangle repeating a vertex and a collinear sliver
        let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0 0\nf 1 2 3 4\nf 1 2 1\nf 1 5 2\n";
        let a = Asset::read_bytes(obj.as_bytes(), Format::Obj, Sidecars::Refuse).unwrap();
        assert_eq!(a.mesh().triangles(), &[[0, 1, 2], [0, 2, 3]]);
        let info = a.info();
        assert_eq!((info.triangles, info.dropped_triangles), (4, 2));
        // the file keeps them: an identity export is the input
        assert_eq!(
            a.export(a.mesh().positions(), Format::Obj).unwrap(),
            obj.as_bytes()
        );
        // plain formats stay strict
        let off = "OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n";
        assert!(Asset::read_bytes(off.as_bytes(), Format::Off, Sidecars::Refuse).is_err());
    }
}
