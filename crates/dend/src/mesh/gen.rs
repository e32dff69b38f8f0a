//! Procedural generators of the paper's test shapes, with the paper's vertex
//! counts as defaults. Every shape is oriented counter-clockwise seen from
//! outside (closed shapes have positive signed volume; open ones face +z or
//! away from their axis). Quads are split along the diagonal from their
//! first to their third corner.
//!
//! | shape | default | vertices | topology |
//! |---|---|---|---|
//! | `bar` | 7 segments across each side, 27 along z; 1 × 1 × 6 | 856 = 28·28 + 2·6² | **capped** box (genus 0, closed), quad-grid sides and caps; z ∈ [0, 6] |
//! | `cylinder` | 32 around, 34 rings; radius 1, length 6 | 1088 = 32·34 | **open** tube, 2 boundary loops (z = 0 and z = 6) |
//! | `flag` | 17 × 17 grid; 1 × 1 | 289 | flat square in z = 0, 1 boundary loop |
//! | `plane` | 47 × 45 grid; 1 × 44/46 (square cells) | 2115 | flat in z = 0, 1 boundary loop |
//! | `bumpy-plane` | as `plane`, plus 9 Gaussian bumps of height 0.1 | 2115 | height field, 1 boundary loop |
//! | `torus` | 24 × 24; radii 1 and 0.4 | 576 | closed, genus 1, axis z |
//! | `creature` | 2 Catmull–Clark levels of a 146-vertex quadruped cage | 2306 | closed, genus 0, +y up, head at +x, 4 legs, neck + head, tail (`gen/creature.rs`) |
//! | `saddle` | 45 × 45 jittered grid over `[-1, 1]²`, `z = ½(x² − y²)`, random diagonals | 2025 | **open**, 1 boundary loop; obtuse and skinny triangles (`gen/patch.rs`) |
//! | `wavy-sheet` | as `saddle`, `z = 0.15 sin(2.5πx) cos(1.5πy)` | 2025 | **open**, 1 boundary loop; obtuse and skinny triangles |
//! | `limb` | 3 bones of length 1, 8 rings of 12 per bone, 2 poles | 302 | closed, genus 0, along +y; **rigged**: a skinned glTF asset (`crate::rig::sample`, [`generate_asset`]) |
//!
//! The bar and the cylinder have their long axis along z with the end that is
//! usually fixed at z = 0, so constraints can be picked by a z range, as in
//! the survey meshes. The bar's count 856 is only reachable as a *capped* box
//! with square cross-section (`4a(m+1) + 2(a-1)² = 856` has the solution
//! `a = 7, m = 27`; the open tube `4a(m+1) = 856` has no reasonable one), and
//! the cylinder's 1088 only as an *open* tube (`n·rings = 1088 = 32·34`).

use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::asset::Asset;
use super::io::gltf::{Container, Sidecars};
use super::io::Format;
use super::{Mesh, MeshError, Real};
use crate::rig::sample::{limb, LimbOptions};

mod creature;
mod lattice;
mod patch;
pub use creature::{creature_constraints, BELLY_HEIGHT, FOOT_HEIGHT, HEAD_DEPTH};
pub use patch::{irregular_patch, PatchSurface};

use lattice::{lattice_box, quad, Raw};

/// The generated shapes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "kebab-case")]
pub enum Shape {
    /// Capped rectangular box bar along z (default 856 vertices).
    Bar,
    /// Open cylindrical tube along z (default 1088 vertices).
    Cylinder,
    /// Flat square grid (default 17 × 17 = 289 vertices).
    Flag,
    /// Flat rectangular grid (default 47 × 45 = 2115 vertices).
    Plane,
    /// The plane with smooth Gaussian bumps (default 2115 vertices).
    BumpyPlane,
    /// Torus about the z axis (default 24 × 24 = 576 vertices).
    Torus,
    /// A posable quadruped, +y up, head towards +x: smooth legs, neck,
    /// head and tail (default 2 subdivision levels); its default edit is
    /// [`creature_constraints`].
    Creature,
    /// An irregular open saddle patch (default 45 × 45 = 2025 vertices):
    /// obtuse and skinny triangles, a free boundary ([`irregular_patch`]).
    Saddle,
    /// An irregular open wavy sheet (default 2025 vertices), as `saddle`.
    WavySheet,
    /// A rigged limb: a capped tube along +y skinned to a chain of bones
    /// (`crate::rig::sample::limb`; default 3 bones, 302 vertices), a
    /// skinned glTF asset ([`generate_asset`]) whose skeleton the server
    /// lists; its default edit is `crate::rig::sample::limb_constraints`.
    Limb,
}

/// Optional size parameters; `None` takes the shape's default (module table).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize, clap::Args)]
#[serde(default, deny_unknown_fields)]
pub struct ShapeParams {
    /// First resolution. bar: segments across each side [7]; cylinder:
    /// vertices around [32]; flag/plane: vertices along x [17/47]; torus:
    /// vertices around the z axis [24]; creature: Catmull–Clark levels
    /// (0..=4) [2]; saddle/wavy-sheet: vertices per side [45].
    #[arg(long)]
    pub nu: Option<u32>,
    /// Second resolution. bar: segments along z [27]; cylinder: rings along z
    /// [34]; flag/plane: vertices along y [17/45]; torus: vertices around the tube [24].
    #[arg(long)]
    pub nv: Option<u32>,
    /// First size. bar: side of the square cross-section [1]; cylinder:
    /// radius [1]; flag/plane: extent along x [1]; torus: major radius [1];
    /// creature, saddle, wavy-sheet: scale [1].
    #[arg(long)]
    pub size: Option<Real>,
    /// Second size. bar/cylinder: length along z [6]; flag/plane: extent
    /// along y [square cells]; torus: minor radius [0.4].
    #[arg(long)]
    pub size2: Option<Real>,
    /// bumpy-plane: bump height as a fraction of the x extent [0.1].
    #[arg(long)]
    pub amplitude: Option<Real>,
}

/// A shape and its parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeSpec {
    /// Which shape.
    pub shape: Shape,
    /// Its sizes (defaults where `None`).
    #[serde(default)]
    pub params: ShapeParams,
}

impl ShapeSpec {
    /// The shape with all-default parameters.
    pub fn default_for(shape: Shape) -> Self {
        ShapeSpec {
            shape,
            params: ShapeParams::default(),
        }
    }
}

/// Why a shape could not be generated.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum GenError {
    /// A resolution is too small or too large. Fix: use a value in range.
    #[error("{what} = {value} is out of range ({min}..={max})")]
    Resolution {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: u32,
        /// Smallest allowed.
        min: u32,
        /// Largest allowed.
        max: u32,
    },
    /// A size is not finite and positive (or the torus tube is too thick).
    #[error("{what} = {value} is invalid: {why}")]
    Size {
        /// Which parameter.
        what: &'static str,
        /// The value given.
        value: Real,
        /// The requirement.
        why: &'static str,
    },
    /// The generated mesh failed validation (should not happen). (The
    /// validation's message is in this one, not a `source`.)
    #[error("generated mesh is invalid: {0}")]
    Mesh(MeshError),
    /// A generated asset could not be read back (should not happen).
    #[error("generated asset is unreadable: {0}")]
    Asset(String),
}

impl From<MeshError> for GenError {
    fn from(e: MeshError) -> Self {
        GenError::Mesh(e)
    }
}

const MAX_RES: u32 = 4096;

fn res(v: Option<u32>, default: u32, what: &'static str, min: u32) -> Result<u32, GenError> {
    let value = v.unwrap_or(default);
    if (min..=MAX_RES).contains(&value) {
        Ok(value)
    } else {
        Err(GenError::Resolution {
            what,
            value,
            min,
            max: MAX_RES,
        })
    }
}

fn size(v: Option<Real>, default: Real, what: &'static str) -> Result<Real, GenError> {
    let value = v.unwrap_or(default);
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(GenError::Size {
            what,
            value,
            why: "must be finite and positive",
        })
    }
}

/// The rigged limb's options for `spec`'s parameters: `nu` bones [3]
/// (1..=64), `nv` rings per bone [8] (2..=64), `size` the bone length [1].
fn limb_options(p: &ShapeParams, container: Container) -> Result<LimbOptions, GenError> {
    let bones = res(p.nu, 3, "nu", 1)?;
    let rings = res(p.nv, 8, "nv", 2)?;
    for (what, value) in [("nu", bones), ("nv", rings)] {
        if value > 64 {
            return Err(GenError::Resolution {
                what,
                value,
                min: if what == "nu" { 1 } else { 2 },
                max: 64,
            });
        }
    }
    Ok(LimbOptions {
        bones: bones as usize,
        rings_per_bone: rings as usize,
        bone: size(p.size, 1.0, "size")? as f32,
        container,
        ..LimbOptions::default()
    })
}

/// The file of a shape that is an asset rather than a bare mesh (the rigged
/// `limb`: a skinned glTF, GLB or `.gltf` as `container` says); `None` for
/// the others.
pub fn generate_asset(spec: &ShapeSpec, container: Container) -> Result<Option<Vec<u8>>, GenError> {
    match spec.shape {
        Shape::Limb => Ok(Some(limb(limb_options(&spec.params, container)?))),
        _ => Ok(None),
    }
}

/// Generates `spec`'s mesh (validated).
pub fn generate(spec: &ShapeSpec) -> Result<Mesh, GenError> {
    let p = &spec.params;
    let (positions, triangles) = match spec.shape {
        Shape::Limb => {
            let bytes = limb(limb_options(p, Container::Glb)?);
            let asset = Asset::read_bytes(&bytes, Format::Glb, Sidecars::Refuse)
                .map_err(|e| GenError::Asset(e.to_string()))?;
            let m = asset.mesh();
            (m.positions().to_vec(), m.triangles().to_vec())
        }
        Shape::Bar => bar(
            res(p.nu, 7, "nu", 1)?,
            res(p.nv, 27, "nv", 1)?,
            size(p.size, 1.0, "size")?,
            size(p.size2, 6.0, "size2")?,
        ),
        Shape::Cylinder => cylinder(
            res(p.nu, 32, "nu", 3)?,
            res(p.nv, 34, "nv", 2)?,
            size(p.size, 1.0, "size")?,
            size(p.size2, 6.0, "size2")?,
        ),
        Shape::Flag | Shape::Plane | Shape::BumpyPlane => {
            let (dx, dy) = if spec.shape == Shape::Flag {
                (17, 17)
            } else {
                (47, 45)
            };
            let nx = res(p.nu, dx, "nu", 2)?;
            let ny = res(p.nv, dy, "nv", 2)?;
            let sx = size(p.size, 1.0, "size")?;
            let sy = size(p.size2, sx * (ny - 1) as Real / (nx - 1) as Real, "size2")?;
            let amp = if spec.shape == Shape::BumpyPlane {
                let a = p.amplitude.unwrap_or(0.1);
                if !a.is_finite() {
                    return Err(GenError::Size {
                        what: "amplitude",
                        value: a,
                        why: "must be finite",
                    });
                }
                a * sx
            } else {
                0.0
            };
            grid(nx, ny, sx, sy, |x, y| bumps(x / sx, y / sy, sx) * amp)
        }
        Shape::Torus => {
            let big = size(p.size, 1.0, "size")?;
            let small = size(p.size2, 0.4, "size2")?;
            if small >= big {
                return Err(GenError::Size {
                    what: "size2",
                    value: small,
                    why: "the minor radius must be smaller than the major radius",
                });
            }
            torus(res(p.nu, 24, "nu", 3)?, res(p.nv, 24, "nv", 3)?, big, small)
        }
        Shape::Creature => {
            let levels = p.nu.unwrap_or(2);
            if levels > 4 {
                return Err(GenError::Resolution {
                    what: "nu",
                    value: levels,
                    min: 0,
                    max: 4,
                });
            }
            creature::creature(levels, size(p.size, 1.0, "size")?)
        }
        Shape::Saddle | Shape::WavySheet => {
            let surface = if spec.shape == Shape::Saddle {
                PatchSurface::Saddle
            } else {
                PatchSurface::Wavy
            };
            let n = res(p.nu, 45, "nu", 3)?;
            let s = size(p.size, 1.0, "size")?;
            let m = irregular_patch(surface, n as usize, PATCH_JITTER, PATCH_SEED);
            let pos = m.positions().iter().map(|q| q.map(|c| s * c)).collect();
            (pos, m.triangles().to_vec())
        }
    };
    Ok(Mesh::new(positions, triangles)?)
}

/// The `saddle` and `wavy-sheet` shapes' jitter, in cells, and seed.
const PATCH_JITTER: Real = 0.4;
const PATCH_SEED: u64 = 1;

/// The surface of the lattice box `[0,a]×[0,a]×[0,m]`, mapped to a
/// `w × w × len` bar centred on the z axis with z ∈ [0, len].
fn bar(a: u32, m: u32, w: Real, len: Real) -> Raw {
    // faces normal to z first (bottom, top), then x, then y
    let (corners, quads) = lattice_box([a, a, m], [2, 0, 1]);
    let pos = corners
        .iter()
        .map(|c| {
            [
                (c[0] as Real / a as Real - 0.5) * w,
                (c[1] as Real / a as Real - 0.5) * w,
                c[2] as Real / m as Real * len,
            ]
        })
        .collect();
    let mut tris = Vec::with_capacity(2 * quads.len());
    for q in quads {
        quad(&mut tris, q);
    }
    (pos, tris)
}

/// Open tube: `n` vertices around, `rings` rings, z ∈ [0, len].
fn cylinder(n: u32, rings: u32, r: Real, len: Real) -> Raw {
    let mut pos = Vec::with_capacity((n * rings) as usize);
    for k in 0..rings {
        let z = k as Real / (rings - 1) as Real * len;
        for j in 0..n {
            let t = 2.0 * std::f64::consts::PI * j as Real / n as Real;
            pos.push([r * t.cos(), r * t.sin(), z]);
        }
    }
    let mut tris = Vec::new();
    for k in 0..rings - 1 {
        for j in 0..n {
            let j1 = (j + 1) % n;
            quad(
                &mut tris,
                [k * n + j, k * n + j1, (k + 1) * n + j1, (k + 1) * n + j],
            );
        }
    }
    (pos, tris)
}

/// Height-field grid of `nx × ny` vertices over `[0,sx]×[0,sy]`, facing +z.
fn grid(nx: u32, ny: u32, sx: Real, sy: Real, h: impl Fn(Real, Real) -> Real) -> Raw {
    let mut pos = Vec::with_capacity((nx * ny) as usize);
    for j in 0..ny {
        for i in 0..nx {
            let x = i as Real / (nx - 1) as Real * sx;
            let y = j as Real / (ny - 1) as Real * sy;
            pos.push([x, y, h(x, y)]);
        }
    }
    let mut tris = Vec::new();
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let v = j * nx + i;
            quad(&mut tris, [v, v + 1, v + 1 + nx, v + nx]);
        }
    }
    (pos, tris)
}

/// Sum of 9 Gaussian bumps (peak 1, σ = 0.07 of the extent) centred on the
/// 3×3 grid at 1/4, 1/2, 3/4 of the unit square; `(u, v)` in `[0,1]²`.
fn bumps(u: Real, v: Real, _sx: Real) -> Real {
    let s2 = 2.0 * 0.07f64.powi(2);
    let mut z = 0.0;
    for cu in [0.25, 0.5, 0.75] {
        for cv in [0.25, 0.5, 0.75] {
            z += (-((u - cu).powi(2) + (v - cv).powi(2)) / s2).exp();
        }
    }
    z
}

/// Torus about z: `nu` vertices around the axis, `nv` around the tube.
fn torus(nu: u32, nv: u32, big: Real, small: Real) -> Raw {
    let tau = 2.0 * std::f64::consts::PI;
    let mut pos = Vec::with_capacity((nu * nv) as usize);
    for i in 0..nu {
        let t = tau * i as Real / nu as Real;
        for j in 0..nv {
            let f = tau * j as Real / nv as Real;
            let rr = big + small * f.cos();
            pos.push([rr * t.cos(), rr * t.sin(), small * f.sin()]);
        }
    }
    let mut tris = Vec::new();
    for i in 0..nu {
        let i1 = (i + 1) % nu;
        for j in 0..nv {
            let j1 = (j + 1) % nv;
            quad(
                &mut tris,
                [i * nv + j, i1 * nv + j, i1 * nv + j1, i * nv + j1],
            );
        }
    }
    (pos, tris)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_have_the_paper_counts() {
        for (shape, nv) in [
            (Shape::Bar, 856),
            (Shape::Cylinder, 1088),
            (Shape::Flag, 289),
            (Shape::Plane, 2115),
            (Shape::BumpyPlane, 2115),
            (Shape::Torus, 576),
            (Shape::Creature, 2306),
        ] {
            let m = generate(&ShapeSpec::default_for(shape)).unwrap();
            assert_eq!(m.num_vertices(), nv, "{shape:?}");
        }
    }

    #[test]
    fn bad_parameters_are_errors() {
        let mut s = ShapeSpec::default_for(Shape::Cylinder);
        s.params.nu = Some(2);
        assert!(matches!(
            generate(&s),
            Err(GenError::Resolution { what: "nu", .. })
        ));
        let mut s = ShapeSpec::default_for(Shape::Torus);
        s.params.size2 = Some(2.0);
        assert!(matches!(
            generate(&s),
            Err(GenError::Size { what: "size2", .. })
        ));
        s.params.size2 = Some(Real::NAN);
        assert!(generate(&s).is_err());
    }
}
