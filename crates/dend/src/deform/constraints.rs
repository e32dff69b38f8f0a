//! Constraint sets: fixed vertices and handle groups with rigid targets
//! (dend.md §1), and the constraints JSON format (`api/constraints.schema.json`).

use nalgebra::{Matrix3, Rotation3, Unit, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::DeformError;
use crate::mesh::asset::groups::GroupSel;
use crate::mesh::{Mesh, Point};

/// A rigid handle target `p' = pivot + R (p - pivot) + translation`
/// (mesh units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidTransform {
    /// The rotation `R`.
    pub rotation: UnitQuaternion<f64>,
    /// The translation, applied after the rotation.
    pub translation: Point,
    /// The rotation centre (a handle's rest centroid unless given).
    pub pivot: Point,
}

impl RigidTransform {
    /// The identity about `pivot`.
    pub fn identity(pivot: Point) -> Self {
        RigidTransform {
            rotation: UnitQuaternion::identity(),
            translation: [0.0; 3],
            pivot,
        }
    }

    /// `pivot + R (p - pivot) + translation`.
    pub fn apply(&self, p: Point) -> Point {
        let v = Vector3::new(
            p[0] - self.pivot[0],
            p[1] - self.pivot[1],
            p[2] - self.pivot[2],
        );
        let r = self.rotation * v;
        [
            self.pivot[0] + r.x + self.translation[0],
            self.pivot[1] + r.y + self.translation[1],
            self.pivot[2] + r.z + self.translation[2],
        ]
    }

    /// Composes a drag delta: rotate by `d_rotation` about the handle's
    /// *current* pivot (`pivot + translation`), then translate by
    /// `d_translation`. In closed form `R ← dR·R`, `t ← t + dt`, so applying
    /// deltas one by one equals applying their composition.
    pub fn then(&self, d_rotation: UnitQuaternion<f64>, d_translation: Point) -> Self {
        RigidTransform {
            rotation: d_rotation * self.rotation,
            translation: [
                self.translation[0] + d_translation[0],
                self.translation[1] + d_translation[1],
                self.translation[2] + d_translation[2],
            ],
            pivot: self.pivot,
        }
    }

    /// The fraction `s ∈ [0, 1]` of this transform: rotation angle and
    /// translation scaled by `s` about the same pivot (for `--steps`).
    /// The angle is read from the quaternion as stored, in `[0°, 360°]`
    /// (`2 atan2(|v|, w)`), so a 300° rotation is split into 300° / N steps;
    /// `slerp` would take the short way (−60° in total).
    pub fn fraction(&self, s: f64) -> Self {
        let q = self.rotation.quaternion();
        let angle = 2.0 * q.vector().norm().atan2(q.w);
        let rotation = match Unit::try_new(q.vector().into_owned(), 1e-300) {
            Some(axis) => UnitQuaternion::from_axis_angle(&axis, s * angle),
            None => UnitQuaternion::identity(),
        };
        RigidTransform {
            rotation,
            translation: [
                self.translation[0] * s,
                self.translation[1] * s,
                self.translation[2] * s,
            ],
            pivot: self.pivot,
        }
    }

    /// From a 4×4 affine matrix (row-major, column vectors: `p' = M p`) whose
    /// 3×3 block is a rotation (orthonormalised by polar decomposition),
    /// re-expressed about `pivot`.
    pub fn from_matrix(m: &[[f64; 4]; 4], pivot: Point) -> Result<Self, DeformError> {
        if m.iter().flatten().any(|v| !v.is_finite()) {
            return Err(DeformError::NonFinite {
                what: "handle transform",
            });
        }
        let a = Matrix3::new(
            m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
        );
        let svd = a.svd(true, true);
        let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
        let mut r = u * vt;
        if r.determinant() < 0.0 {
            return Err(DeformError::InvalidTransform {
                reason: "the 3x3 block is a reflection",
            });
        }
        r = Rotation3::from_matrix_unchecked(r).into_inner();
        let q = UnitQuaternion::from_matrix(&r);
        // canonical sign (w ≥ 0): the angle `fraction` reads is then ≤ 180°
        let rotation = if q.w < 0.0 {
            UnitQuaternion::new_unchecked(-q.into_inner())
        } else {
            q
        };
        // p' = R p + t = pivot + R (p - pivot) + (R pivot + t - pivot)
        let c = Vector3::from(pivot);
        let t = Vector3::new(m[0][3], m[1][3], m[2][3]);
        let tr = rotation * c + t - c;
        Ok(RigidTransform {
            rotation,
            translation: [tr.x, tr.y, tr.z],
            pivot,
        })
    }
}

/// A set of vertices, as written in the constraints JSON: an index list, a box
/// or a sphere (selected on the rest mesh, in the mesh's own units), or a
/// named part of the asset file (resolved by
/// [`Asset::resolve_groups`](crate::mesh::asset::Asset::resolve_groups)).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum VertexSet {
    /// Explicit indices `[0, 5, 9]`.
    Indices(Vec<u64>),
    /// `{"box": {"min": [x,y,z], "max": [x,y,z]}}` (inclusive).
    Box {
        /// The box.
        #[serde(rename = "box")]
        bbox: BoxSel,
    },
    /// `{"sphere": {"center": [x,y,z], "radius": r}}` (inclusive).
    Sphere {
        /// The sphere.
        sphere: SphereSel,
    },
    /// `{"group": "LeftArm"}`, `{"group": {"node": "Arm"}}`, … : a named
    /// part of the asset (see [`crate::mesh::asset::groups`]).
    Group(GroupSel),
}

/// An axis-aligned box selector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSel {
    /// Lower corner.
    pub min: Point,
    /// Upper corner.
    pub max: Point,
}

/// A ball selector.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSel {
    /// Centre.
    pub center: Point,
    /// Radius (≥ 0).
    pub radius: f64,
}

/// A rotation in the constraints JSON: axis–angle in degrees, or a unit
/// quaternion. Quaternions are `[x, y, z, w]` across the whole API (as in
/// drags, WebSocket messages, the store and glTF); `[w, x, y, z]` is
/// accepted only under its explicit name `quaternion_wxyz`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum RotationSpec {
    /// `{"axis": [x,y,z], "degrees": a}`.
    AxisAngle {
        /// Rotation axis (any non-zero length).
        axis: Point,
        /// Angle in degrees (right-hand rule).
        degrees: f64,
    },
    /// `{"quaternion": [x, y, z, w]}` (normalised on use).
    Quaternion {
        /// `[x, y, z, w]`.
        quaternion: [f64; 4],
    },
    /// `{"quaternion_wxyz": [w, x, y, z]}` (normalised on use).
    QuaternionWxyz {
        /// `[w, x, y, z]`.
        quaternion_wxyz: [f64; 4],
    },
}

impl RotationSpec {
    /// The rotation as a unit quaternion; rejects NaN and zero axes.
    pub fn to_quaternion(&self) -> Result<UnitQuaternion<f64>, DeformError> {
        match self {
            RotationSpec::AxisAngle { axis, degrees } => {
                if !axis.iter().chain([degrees]).all(|v| v.is_finite()) {
                    return Err(DeformError::NonFinite { what: "rotation" });
                }
                if *degrees == 0.0 {
                    return Ok(UnitQuaternion::identity());
                }
                let a = Vector3::from(*axis);
                if a.norm() == 0.0 {
                    return Err(DeformError::InvalidTransform {
                        reason: "rotation axis is zero",
                    });
                }
                Ok(UnitQuaternion::from_axis_angle(
                    &Unit::new_normalize(a),
                    degrees.to_radians(),
                ))
            }
            RotationSpec::Quaternion { quaternion: q }
            | RotationSpec::QuaternionWxyz { quaternion_wxyz: q } => {
                if !q.iter().all(|v| v.is_finite()) {
                    return Err(DeformError::NonFinite { what: "rotation" });
                }
                // nalgebra's constructor takes (w, x, y, z)
                let quat = match self {
                    RotationSpec::Quaternion { .. } => {
                        nalgebra::Quaternion::new(q[3], q[0], q[1], q[2])
                    }
                    _ => nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]),
                };
                if quat.norm() == 0.0 {
                    return Err(DeformError::InvalidTransform {
                        reason: "quaternion is zero",
                    });
                }
                Ok(UnitQuaternion::from_quaternion(quat))
            }
        }
    }
}

/// One handle in the constraints JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandleSpec {
    /// Name (defaults to `handle<k>`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The handle's vertices.
    pub vertices: VertexSet,
    /// Translation (default zero).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translate: Option<Point>,
    /// Rotation (default identity).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate: Option<RotationSpec>,
    /// Rotation centre (default: the handle's rest centroid).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pivot: Option<Point>,
    /// Explicit target positions, one per handle vertex in increasing index
    /// order; the rigid transform then applies to these instead of the rest
    /// positions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub positions: Option<Vec<Point>>,
}

/// The constraints JSON: `{"fixed": VERTEX_SET, "handles": [HANDLE...]}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintsSpec {
    /// Vertices that stay where they are: at their rest positions, or at
    /// `fixed_positions`.
    #[serde(default = "empty_set")]
    pub fixed: VertexSet,
    /// Explicit positions of the fixed vertices, one per fixed vertex in
    /// increasing index order (default: their rest positions). A constraint
    /// edit on a posed session pins the new set where the pose has it
    /// ([`ConstraintsSpec::resolve_at`], [`ConstraintsSpec::anchored`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fixed_positions: Option<Vec<Point>>,
    /// Handle groups.
    #[serde(default)]
    pub handles: Vec<HandleSpec>,
}

fn empty_set() -> VertexSet {
    VertexSet::Indices(Vec::new())
}

/// A handle group, resolved against a mesh.
#[derive(Debug, Clone, PartialEq)]
pub struct HandleGroup {
    /// Name (unique within the set).
    pub name: String,
    /// Vertex indices, sorted, non-empty.
    pub vertices: Vec<u32>,
    /// Base positions the transform acts on (the rest positions unless the
    /// spec gave explicit ones), one per vertex, mesh units.
    pub base: Vec<Point>,
    /// Centroid of `base`.
    pub rest_centroid: Point,
    /// The current target transform.
    pub target: RigidTransform,
}

impl HandleGroup {
    /// Target positions of the handle's vertices (mesh units).
    pub fn target_positions(&self) -> impl Iterator<Item = (u32, Point)> + '_ {
        self.vertices
            .iter()
            .zip(&self.base)
            .map(|(&v, &p)| (v, self.target.apply(p)))
    }
}

/// A validated constraint set: fixed vertices and handle groups, pairwise
/// disjoint, every index in range.
#[derive(Debug, Clone, PartialEq)]
pub struct Constraints {
    /// Fixed vertices, sorted.
    pub fixed: Vec<u32>,
    /// Where each fixed vertex is held (mesh units; its rest position
    /// unless the spec or an anchoring pose said otherwise).
    pub fixed_at: Vec<Point>,
    /// Handle groups.
    pub handles: Vec<HandleGroup>,
}

impl Constraints {
    /// Builds and validates a constraint set from resolved index lists.
    /// `handles` are `(name, vertices, target)`; targets default to identity
    /// about the handle's rest centroid when `None`.
    pub fn new(
        mesh: &Mesh,
        fixed: Vec<u32>,
        handles: Vec<(String, Vec<u32>, Option<RigidTransform>)>,
    ) -> Result<Self, DeformError> {
        let n = mesh.num_vertices();
        let mut owner = vec![u32::MAX; n];
        let mut fixed = fixed;
        fixed.sort_unstable();
        fixed.dedup();
        for &v in &fixed {
            if v as usize >= n {
                return Err(DeformError::UnknownVertex {
                    index: v as u64,
                    vertices: n,
                });
            }
            owner[v as usize] = 0;
        }
        let mut groups = Vec::with_capacity(handles.len());
        for (k, (name, mut vs, target)) in handles.into_iter().enumerate() {
            vs.sort_unstable();
            vs.dedup();
            if vs.is_empty() {
                return Err(DeformError::EmptyHandle { name });
            }
            if groups.iter().any(|g: &HandleGroup| g.name == name) {
                return Err(DeformError::DuplicateHandle { name });
            }
            for &v in &vs {
                if v as usize >= n {
                    return Err(DeformError::UnknownVertex {
                        index: v as u64,
                        vertices: n,
                    });
                }
                if owner[v as usize] != u32::MAX {
                    return Err(DeformError::OverlappingSets {
                        vertex: v,
                        handle: name,
                    });
                }
                owner[v as usize] = k as u32 + 1;
            }
            let base: Vec<Point> = vs.iter().map(|&v| mesh.positions()[v as usize]).collect();
            let c = centroid(&base);
            groups.push(HandleGroup {
                name,
                vertices: vs,
                base,
                rest_centroid: c,
                target: target.unwrap_or_else(|| RigidTransform::identity(c)),
            });
        }
        if fixed.is_empty() && groups.is_empty() {
            return Err(DeformError::NoConstraints);
        }
        let fixed_at = fixed
            .iter()
            .map(|&v| mesh.positions()[v as usize])
            .collect();
        Ok(Constraints {
            fixed,
            fixed_at,
            handles: groups,
        })
    }

    /// Every constrained vertex (fixed and handles), sorted.
    pub fn constrained(&self) -> Vec<u32> {
        let mut all: Vec<u32> = self.fixed.clone();
        for h in &self.handles {
            all.extend_from_slice(&h.vertices);
        }
        all.sort_unstable();
        all
    }

    /// Index of the handle named `name`.
    pub fn handle_index(&self, name: &str) -> Option<usize> {
        self.handles.iter().position(|h| h.name == name)
    }
}

impl ConstraintsSpec {
    /// Selects the vertex sets on the rest mesh and validates the result.
    pub fn resolve(&self, mesh: &Mesh) -> Result<Constraints, DeformError> {
        self.resolve_at(mesh, None)
    }

    /// [`resolve`](Self::resolve), with the constrained vertices held where
    /// `pose` has them instead of at rest: fixed vertices stay at their
    /// posed positions, and handle transforms act on the posed positions
    /// (default pivot: their posed centroid). Explicit `fixed_positions`
    /// and handle `positions` still win. Vertex sets (boxes, spheres) are
    /// always selected on the rest mesh. This is how a constraint edit keeps
    /// the pose.
    pub fn resolve_at(
        &self,
        mesh: &Mesh,
        pose: Option<&[Point]>,
    ) -> Result<Constraints, DeformError> {
        if let Some(p) = pose {
            if p.len() != mesh.num_vertices() {
                return Err(DeformError::PositionsMismatch {
                    handle: "(anchoring pose)".into(),
                    expected: mesh.num_vertices(),
                    got: p.len(),
                });
            }
            if p.iter().flatten().any(|v| !v.is_finite()) {
                return Err(DeformError::NonFinite {
                    what: "anchoring pose",
                });
            }
        }
        let fixed = select(&self.fixed, mesh)?;
        let mut handles = Vec::with_capacity(self.handles.len());
        for (k, h) in self.handles.iter().enumerate() {
            let name = h.name.clone().unwrap_or_else(|| format!("handle{k}"));
            let vs = select(&h.vertices, mesh)?;
            handles.push((name, vs, h));
        }
        let plain = handles
            .iter()
            .map(|(name, vs, _)| (name.clone(), vs.clone(), None))
            .collect();
        let mut c = Constraints::new(mesh, fixed, plain)?;
        if let Some(pos) = &self.fixed_positions {
            if pos.len() != c.fixed.len() {
                return Err(DeformError::PositionsMismatch {
                    handle: "(fixed)".into(),
                    expected: c.fixed.len(),
                    got: pos.len(),
                });
            }
            if pos.iter().flatten().any(|v| !v.is_finite()) {
                return Err(DeformError::NonFinite {
                    what: "fixed positions",
                });
            }
            c.fixed_at = pos.clone();
        } else if let Some(p) = pose {
            c.fixed_at = c.fixed.iter().map(|&v| p[v as usize]).collect();
        }
        for (g, (_, _, spec)) in c.handles.iter_mut().zip(&handles) {
            if let (None, Some(p)) = (&spec.positions, pose) {
                g.base = g.vertices.iter().map(|&v| p[v as usize]).collect();
                g.rest_centroid = centroid(&g.base);
            }
            if let Some(pos) = &spec.positions {
                if pos.len() != g.vertices.len() {
                    return Err(DeformError::PositionsMismatch {
                        handle: g.name.clone(),
                        expected: g.vertices.len(),
                        got: pos.len(),
                    });
                }
                if pos.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(DeformError::NonFinite {
                        what: "handle positions",
                    });
                }
                g.base = pos.clone();
                g.rest_centroid = centroid(&g.base);
            }
            let pivot = spec.pivot.unwrap_or(g.rest_centroid);
            let translation = spec.translate.unwrap_or([0.0; 3]);
            if pivot.iter().chain(&translation).any(|v| !v.is_finite()) {
                return Err(DeformError::NonFinite {
                    what: "handle transform",
                });
            }
            let rotation = match &spec.rotate {
                Some(r) => r.to_quaternion()?,
                None => UnitQuaternion::identity(),
            };
            g.target = RigidTransform {
                rotation,
                translation,
                pivot,
            };
        }
        Ok(c)
    }
}

impl ConstraintsSpec {
    /// This spec with the positions `c` holds its vertices at written out
    /// wherever they differ from the rest mesh's (`fixed_positions`, each
    /// handle's `positions`), so that [`resolve`](Self::resolve) on the rest
    /// mesh gives `c`'s vertex sets and bases again: what a session stores
    /// after a constraint edit that kept the pose. `c` must be this spec
    /// resolved on `mesh` (same vertex sets, same handle order).
    pub fn anchored(&self, mesh: &Mesh, c: &Constraints) -> ConstraintsSpec {
        let rest = mesh.positions();
        let differs =
            |vs: &[u32], at: &[Point]| vs.iter().zip(at).any(|(&v, p)| rest[v as usize] != *p);
        let mut out = self.clone();
        out.fixed_positions = differs(&c.fixed, &c.fixed_at).then(|| c.fixed_at.clone());
        for (h, g) in out.handles.iter_mut().zip(&c.handles) {
            if differs(&g.vertices, &g.base) {
                h.positions = Some(g.base.clone());
                // the pivot the resolution chose, kept explicit: a default
                // pivot is the centroid of the positions it acts on
                h.pivot.get_or_insert(g.target.pivot);
            }
        }
        out
    }
}

/// The vertices a [`VertexSet`] selects on the rest mesh, sorted; errors on
/// indices out of range and on NaN in selectors. Unreferenced vertices are
/// never selected by a box or a sphere.
pub fn select(set: &VertexSet, mesh: &Mesh) -> Result<Vec<u32>, DeformError> {
    let n = mesh.num_vertices();
    let referenced = |v: usize| !mesh.topology().ring(v).is_empty();
    let mut out: Vec<u32> = match set {
        VertexSet::Indices(ix) => {
            let mut out = Vec::with_capacity(ix.len().min(n));
            for &i in ix {
                if i >= n as u64 {
                    return Err(DeformError::UnknownVertex {
                        index: i,
                        vertices: n,
                    });
                }
                out.push(i as u32);
            }
            out
        }
        VertexSet::Box { bbox } => {
            if bbox.min.iter().chain(&bbox.max).any(|v| !v.is_finite()) {
                return Err(DeformError::NonFinite {
                    what: "box selector",
                });
            }
            (0..n)
                .filter(|&v| {
                    let p = mesh.positions()[v];
                    referenced(v) && (0..3).all(|k| p[k] >= bbox.min[k] && p[k] <= bbox.max[k])
                })
                .map(|v| v as u32)
                .collect()
        }
        VertexSet::Sphere { sphere } => {
            if !sphere
                .center
                .iter()
                .chain([&sphere.radius])
                .all(|v| v.is_finite())
                || sphere.radius < 0.0
            {
                return Err(DeformError::NonFinite {
                    what: "sphere selector",
                });
            }
            let r2 = sphere.radius * sphere.radius;
            (0..n)
                .filter(|&v| {
                    let p = mesh.positions()[v];
                    let d2: f64 = (0..3).map(|k| (p[k] - sphere.center[k]).powi(2)).sum();
                    referenced(v) && d2 <= r2
                })
                .map(|v| v as u32)
                .collect()
        }
        // a group needs the asset: resolved before, by Asset::resolve_groups
        VertexSet::Group(GroupSel { group }) => {
            return Err(DeformError::UnknownGroup {
                group: group.to_string(),
                available: Vec::new(),
            })
        }
    };
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

fn centroid(points: &[Point]) -> Point {
    let mut c = [0.0; 3];
    for p in points {
        for k in 0..3 {
            c[k] += p[k];
        }
    }
    let n = points.len().max(1) as f64;
    [c[0] / n, c[1] / n, c[2] / n]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn composing_deltas_equals_applying_them_in_turn() {
        let t0 = RigidTransform::identity([1.0, 2.0, 3.0]);
        let d1 = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3);
        let d2 = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), -0.7);
        let t = t0.then(d1, [0.5, 0.0, 0.0]).then(d2, [0.0, 1.0, -1.0]);
        // apply step by step: each delta rotates about the current pivot
        let p = [4.0, -1.0, 2.0];
        let step = |q: Point, d: UnitQuaternion<f64>, c: Point, dt: Point| {
            let v = d * Vector3::new(q[0] - c[0], q[1] - c[1], q[2] - c[2]);
            [c[0] + v.x + dt[0], c[1] + v.y + dt[1], c[2] + v.z + dt[2]]
        };
        let q1 = step(p, d1, [1.0, 2.0, 3.0], [0.5, 0.0, 0.0]);
        let q2 = step(q1, d2, [1.5, 2.0, 3.0], [0.0, 1.0, -1.0]);
        let got = t.apply(p);
        for k in 0..3 {
            assert!((got[k] - q2[k]).abs() < 1e-12, "{got:?} vs {q2:?}");
        }
    }

    #[test]
    fn from_matrix_reexpresses_about_the_pivot() {
        let r = Rotation3::from_axis_angle(&Vector3::y_axis(), 2.0);
        let m = r.matrix();
        let mat = [
            [m[(0, 0)], m[(0, 1)], m[(0, 2)], 1.0],
            [m[(1, 0)], m[(1, 1)], m[(1, 2)], -2.0],
            [m[(2, 0)], m[(2, 1)], m[(2, 2)], 0.5],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let t = RigidTransform::from_matrix(&mat, [3.0, 1.0, -1.0]).unwrap();
        let p = [0.2, 0.7, 9.0];
        let want = r * Vector3::from(p) + Vector3::new(1.0, -2.0, 0.5);
        let got = t.apply(p);
        for k in 0..3 {
            assert!((got[k] - want[k]).abs() < 1e-12);
        }
        // half the transform, twice, is the whole (same pivot, linear translation)
        let h = t.fraction(0.5);
        assert!((h.rotation.angle() - 1.0).abs() < 1e-12);
        // a 300° rotation is split the long way: a fifth is +60° about +z
        let q = RotationSpec::AxisAngle {
            axis: [0.0, 0.0, 1.0],
            degrees: 300.0,
        }
        .to_quaternion()
        .unwrap();
        let fifth = RigidTransform {
            rotation: q,
            translation: [0.0; 3],
            pivot: [0.0; 3],
        }
        .fraction(0.2);
        let a = fifth.rotation.scaled_axis();
        assert!((a.z - 60f64.to_radians()).abs() < 1e-12, "{a:?}");
    }

    #[test]
    fn constraints_json_parses_all_selector_forms() {
        let j = r#"{"fixed": {"box": {"min": [0,0,0], "max": [1,1,1]}},
                    "handles": [{"name": "top", "vertices": [3, 4],
                                 "translate": [0,0,1], "rotate": {"axis": [0,0,1], "degrees": 90}},
                                {"vertices": {"sphere": {"center": [0,0,0], "radius": 2}},
                                 "rotate": {"quaternion": [1,0,0,0]}}]}"#;
        let s: ConstraintsSpec = serde_json::from_str(j).unwrap();
        assert!(matches!(s.fixed, VertexSet::Box { .. }));
        assert_eq!(s.handles.len(), 2);
        assert!(matches!(s.handles[1].vertices, VertexSet::Sphere { .. }));
        let bad = r#"{"fixed": [0], "handles": [], "oops": 1}"#;
        assert!(serde_json::from_str::<ConstraintsSpec>(bad).is_err());
    }

    /// A posed grid (sheared, bent) to anchor on.
    fn posed_grid() -> (Mesh, Vec<Point>) {
        let mesh = crate::deform::factor::tests::grid(8);
        let pose = mesh
            .positions()
            .iter()
            .map(|p| [p[0] + 0.1 * p[1], p[1], p[2] + 0.05 * p[0] * p[0]])
            .collect();
        (mesh, pose)
    }

    fn spec(j: &str) -> ConstraintsSpec {
        serde_json::from_str(j).unwrap()
    }

    #[test]
    fn resolving_at_a_pose_holds_the_sets_where_the_pose_has_them() {
        let (mesh, pose) = posed_grid();
        let s = spec(
            r#"{"fixed": [0, 1, 2], "handles": [{"name": "h", "vertices": [40, 41],
                         "translate": [0, 0, 1]}]}"#,
        );
        let c = s.resolve_at(&mesh, Some(&pose)).unwrap();
        for (&v, p) in c.fixed.iter().zip(&c.fixed_at) {
            assert_eq!(*p, pose[v as usize]);
        }
        for (v, p) in c.handles[0].target_positions() {
            let q = pose[v as usize];
            assert_eq!(p, [q[0], q[1], q[2] + 1.0]);
        }
        // the default pivot is the posed centroid
        let b = &c.handles[0].base;
        let mid = [
            (b[0][0] + b[1][0]) / 2.0,
            (b[0][1] + b[1][1]) / 2.0,
            (b[0][2] + b[1][2]) / 2.0,
        ];
        assert_eq!(c.handles[0].target.pivot, mid);
        // resolved at rest, the same spec holds them at rest
        let r = s.resolve(&mesh).unwrap();
        assert_eq!(r.fixed_at[2], mesh.positions()[2]);
        assert_ne!(r.fixed_at[2], c.fixed_at[2]);
    }

    #[test]
    fn an_anchored_spec_resolves_to_the_same_constraints_on_the_rest_mesh() {
        let (mesh, pose) = posed_grid();
        let s = spec(
            r#"{"fixed": [0, 1, 2, 3], "handles": [{"name": "h", "vertices": [40, 41, 47],
                         "rotate": {"axis": [0, 0, 1], "degrees": 30}},
                         {"name": "g", "vertices": [20], "pivot": [1, 2, 3]}]}"#,
        );
        let c = s.resolve_at(&mesh, Some(&pose)).unwrap();
        let stored = s.anchored(&mesh, &c);
        assert!(stored.fixed_positions.is_some());
        assert_eq!(stored.handles[1].pivot, Some([1.0, 2.0, 3.0]));
        // through JSON, as a store keeps it
        let json = serde_json::to_string(&stored).unwrap();
        let back: ConstraintsSpec = serde_json::from_str(&json).unwrap();
        assert_eq!(back.resolve(&mesh).unwrap(), c);
        // anchored at rest, nothing is written out
        let r = s.resolve(&mesh).unwrap();
        assert_eq!(s.anchored(&mesh, &r), s);
    }

    #[test]
    fn bad_anchors_are_typed_errors() {
        let (mesh, mut pose) = posed_grid();
        let s = spec(r#"{"fixed": [0, 1], "fixed_positions": [[0, 0, 0]]}"#);
        assert!(matches!(
            s.resolve(&mesh),
            Err(DeformError::PositionsMismatch { .. })
        ));
        let s = spec(r#"{"fixed": [0, 1]}"#);
        assert!(matches!(
            s.resolve_at(&mesh, Some(&pose[1..])),
            Err(DeformError::PositionsMismatch { .. })
        ));
        pose[3][1] = f64::NAN;
        assert!(matches!(
            s.resolve_at(&mesh, Some(&pose)),
            Err(DeformError::NonFinite { .. })
        ));
    }

    #[test]
    fn quaternions_are_xyzw_unless_named_wxyz() {
        let axis_angle = RotationSpec::AxisAngle {
            axis: [0.0, 0.0, 1.0],
            degrees: 90.0,
        }
        .to_quaternion()
        .unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let xyzw: RotationSpec =
            serde_json::from_str(&format!("{{\"quaternion\": [0, 0, {h}, {h}]}}")).unwrap();
        let wxyz: RotationSpec =
            serde_json::from_str(&format!("{{\"quaternion_wxyz\": [{h}, 0, 0, {h}]}}")).unwrap();
        for r in [xyzw, wxyz] {
            assert!(
                r.to_quaternion().unwrap().angle_to(&axis_angle) < 1e-12,
                "{r:?}"
            );
        }
        // [w, x, y, z] under the plain name is another rotation
        let wrong: RotationSpec =
            serde_json::from_str(&format!("{{\"quaternion\": [{h}, 0, 0, {h}]}}")).unwrap();
        assert!(wrong.to_quaternion().unwrap().angle_to(&axis_angle) > 0.5);
    }
}
