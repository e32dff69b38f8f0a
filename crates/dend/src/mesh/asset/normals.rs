//! Normals and tangents for a deformed asset: **normals are recomputed**
//! on the deformed surface, **tangents are turned** with it and made
//! orthogonal to the new normal.
//!
//! **Groups.** Asset vertices are grouped into *normal groups*: the asset
//! vertices at one welded vertex that had the same normal in the file (glTF:
//! bit-identical NORMAL; PLY: bit-identical `nx ny nz`; OBJ: the same `vn`
//! index, wherever it is used). A group sees only the triangles incident to
//! its own asset vertices, so a split made only for UVs (same file normal on
//! both sides) is one group, smooth across the seam, and a hard edge
//! (different file normals) stays hard: each side averages only its own
//! faces.
//!
//! **Normal.** Where the neighbourhood changed shape, the angle-weighted
//! vertex normal (Thürmer and Wüthrich 1998)
//! of the group's corners on the deformed surface:
//!
//! ```text
//!   n_g = normalise( Σ_{corners c of g} θ_c · n̂_t(c) )
//! ```
//!
//! where `t(c)` is the corner's triangle, `n̂_t = (p1 − p0) × (p2 − p0) / |…|`
//! its unit normal (counter-clockwise winding) and `θ_c = atan2(|e1 × e2|,
//! e1 · e2)` the triangle's interior angle at the corner (`e1`, `e2` the
//! edges leaving it). Angle weights make the normal independent of how a
//! face is split into triangles. Degenerate triangles (a zero edge or zero
//! area) add nothing; a group whose sum is zero falls back to its file normal
//! turned by the rotation below.
//!
//! **Rotation.** For each group, the rotation `R` that best maps its rest
//! neighbourhood onto the posed one (orthogonal Procrustes, by SVD, of the
//! edges from the group's corners to the other corners of its triangles, plus
//! the area-weighted normal so that a flat neighbourhood has a unique
//! answer).
//!
//! **Tangent.** The file's tangent direction turned by `R`, then made
//! orthogonal to the new normal `n` by one Gram–Schmidt step, `t' =
//! normalise(R t − (R t · n) n)`; the handedness `w` is kept. (Recomputing
//! tangents from the UVs, MikkTSpace-style, would change them even at rest.)
//!
//! **Unchanged and rigidly moved neighbourhoods.** A group whose
//! neighbourhood did not change shape or turn (every edge vector from its
//! corners is bit-identical; a translation is no change) keeps the file's
//! normal and tangent exactly, so an identity deformation changes nothing.
//! A group whose neighbourhood only turned (its rotation `R` maps every rest
//! edge `a` onto the posed `b` with `Σ |R a − b|² ≤ RIGID² Σ |a|²`, `RIGID =
//! 1e-6`: the fixed parts and the handles of a pose) gets the file's normal
//! turned by `R`: authored normals (analytic, custom-weighted, of a
//! non-uniformly scaled node) are kept wherever the shape did not change,
//! and recomputed only where it did. Where the file's normals are
//! angle-weighted, both rules give the same normals (to rounding), so there
//! is no seam between turned and recomputed ones.

use nalgebra::{Matrix3, Vector3};

use crate::mesh::{cross, sub, Point};

/// How a group's normals and tangents change.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Turn {
    /// The neighbourhood did not move: keep the file's vectors.
    Keep,
    /// Rotate by this rotation matrix.
    Rotate(Matrix3<f64>),
}

impl Turn {
    /// Applies the turn to a direction (a normal or a tangent).
    pub fn apply(&self, v: Point) -> Point {
        match self {
            Turn::Keep => v,
            Turn::Rotate(r) => {
                let w = r * Vector3::from(v);
                [w.x, w.y, w.z]
            }
        }
    }
}

fn v3(p: Point) -> Vector3<f64> {
    Vector3::from(p)
}

/// The best rotation `R` (det +1) minimising `Σ |R a_i - b_i|²` for the
/// cross-covariance `cov = Σ b_i a_iᵀ`.
fn procrustes(cov: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = cov.svd(true, true);
    let (Some(u), Some(vt)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    u * d * vt
}

/// What export writes for one normal group (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shade {
    /// How the group's neighbourhood turned ([`Turn::Keep`]: it did not move).
    pub turn: Turn,
    /// The angle-weighted normal on the deformed surface (None: the group's
    /// triangles are all degenerate).
    pub weighted: Option<Point>,
    /// Whether the neighbourhood moved rigidly (to within [`RIGID`]): then
    /// the file's normal is turned, not recomputed.
    pub rigid: bool,
}

impl Shade {
    /// The normal to write in place of the file's unit normal `file`; None
    /// keeps the file's value (the neighbourhood did not move).
    pub fn normal(&self, file: Point) -> Option<Point> {
        match self.turn {
            Turn::Keep => None,
            t if self.rigid => Some(t.apply(file)),
            t => Some(self.weighted.unwrap_or_else(|| t.apply(file))),
        }
    }

    /// The tangent direction to write in place of the file's unit tangent
    /// `file` (at a vertex whose file normal is `file_normal`, if any): turned
    /// by the group's rotation and made orthogonal to the new normal; None
    /// keeps the file's value.
    pub fn tangent(&self, file: Point, file_normal: Option<Point>) -> Option<Point> {
        if self.turn == Turn::Keep {
            return None;
        }
        let t = v3(self.turn.apply(file));
        let n = file_normal
            .and_then(|f| self.normal(f))
            .or(self.weighted)
            .map(v3);
        let ortho = match n {
            Some(n) => t - t.dot(&n) * n,
            None => t,
        };
        let u = ortho.try_normalize(1e-12).unwrap_or(t);
        Some([u.x, u.y, u.z])
    }
}

/// The interior angle of a triangle at `p`, between the edges to `a` and to
/// `b`: `atan2(|e1 × e2|, e1 · e2)` (0 when an edge has zero length).
fn corner_angle(p: Point, a: Point, b: Point) -> f64 {
    let (e1, e2) = (v3(sub(a, p)), v3(sub(b, p)));
    e1.cross(&e2).norm().atan2(e1.dot(&e2))
}

/// The angle-weighted normal of each group on `pose`: `Σ θ_c n̂_t(c)`
/// normalised (module documentation); None where the sum is zero.
pub fn weighted_normals(
    pose: &[Point],
    triangles: &[[u32; 3]],
    corner_group: &[[u32; 3]],
    groups: usize,
) -> Vec<Option<Point>> {
    let mut sum = vec![Vector3::zeros(); groups];
    for (t, g) in triangles.iter().zip(corner_group) {
        let p = t.map(|i| pose[i as usize]);
        let Some(n) = v3(cross(sub(p[1], p[0]), sub(p[2], p[0]))).try_normalize(0.0) else {
            continue;
        };
        for k in 0..3 {
            let theta = corner_angle(p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
            if theta.is_finite() {
                sum[g[k] as usize] += theta * n;
            }
        }
    }
    sum.into_iter()
        .map(|s| s.try_normalize(0.0).map(|u| [u.x, u.y, u.z]))
        .collect()
}

/// The [`Shade`] of each group from `rest` to `pose` (both in the asset
/// layout). `corner_group[t][k]` is the group of corner `k` of triangle `t`.
pub fn group_shading(
    rest: &[Point],
    pose: &[Point],
    triangles: &[[u32; 3]],
    corner_group: &[[u32; 3]],
    groups: usize,
) -> Vec<Shade> {
    let turns = fit_turns(rest, pose, triangles, corner_group, groups);
    let normals = weighted_normals(pose, triangles, corner_group, groups);
    turns
        .into_iter()
        .zip(normals)
        .map(|((turn, rigid), weighted)| Shade {
            turn,
            weighted,
            rigid,
        })
        .collect()
}

/// The turn of each group from `rest` to `pose` (both in the asset layout).
/// `corner_group[t][k]` is the group of corner `k` of triangle `t`.
pub fn group_turns(
    rest: &[Point],
    pose: &[Point],
    triangles: &[[u32; 3]],
    corner_group: &[[u32; 3]],
    groups: usize,
) -> Vec<Turn> {
    fit_turns(rest, pose, triangles, corner_group, groups)
        .into_iter()
        .map(|(t, _)| t)
        .collect()
}

/// The edges `(a, b)` (rest, posed) from each corner to the other two
/// corners of its triangle, with the corner's group.
fn corner_edges<'a>(
    rest: &'a [Point],
    pose: &'a [Point],
    triangles: &'a [[u32; 3]],
    corner_group: &'a [[u32; 3]],
) -> impl Iterator<Item = (usize, Vector3<f64>, Vector3<f64>)> + 'a {
    triangles.iter().zip(corner_group).flat_map(move |(t, g)| {
        let r = t.map(|i| rest[i as usize]);
        let p = t.map(|i| pose[i as usize]);
        (0..3).flat_map(move |k| {
            [(k + 1) % 3, (k + 2) % 3]
                .map(|j| (g[k] as usize, v3(sub(r[j], r[k])), v3(sub(p[j], p[k]))))
        })
    })
}

/// [`group_turns`], with whether each group moved rigidly: its rotation
/// maps every rest edge onto the posed one to within `RIGID` of the edges'
/// size, `Σ |R a − b|² ≤ RIGID² Σ |a|²`.
fn fit_turns(
    rest: &[Point],
    pose: &[Point],
    triangles: &[[u32; 3]],
    corner_group: &[[u32; 3]],
    groups: usize,
) -> Vec<(Turn, bool)> {
    let mut cov = vec![Matrix3::zeros(); groups];
    let mut n_rest = vec![Vector3::zeros(); groups];
    let mut n_pose = vec![Vector3::zeros(); groups];
    let mut scale = vec![0.0f64; groups];
    let mut moved = vec![false; groups];
    for (t, g) in triangles.iter().zip(corner_group) {
        let r = t.map(|i| rest[i as usize]);
        let p = t.map(|i| pose[i as usize]);
        let nr = v3(cross(sub(r[1], r[0]), sub(r[2], r[0])));
        let np = v3(cross(sub(p[1], p[0]), sub(p[2], p[0])));
        for &gi in g {
            n_rest[gi as usize] += nr;
            n_pose[gi as usize] += np;
        }
    }
    for (gi, a, b) in corner_edges(rest, pose, triangles, corner_group) {
        cov[gi] += b * a.transpose();
        moved[gi] |= a != b;
        scale[gi] += a.norm_squared();
    }
    let turns: Vec<Turn> = (0..groups)
        .map(|g| {
            if !moved[g] {
                return Turn::Keep;
            }
            let mut c = cov[g];
            if let (Some(a), Some(b)) = (n_rest[g].try_normalize(0.0), n_pose[g].try_normalize(0.0))
            {
                c += scale[g] * b * a.transpose();
            }
            Turn::Rotate(procrustes(&c))
        })
        .collect();
    let mut residual = vec![0.0f64; groups];
    for (gi, a, b) in corner_edges(rest, pose, triangles, corner_group) {
        if let Turn::Rotate(r) = turns[gi] {
            residual[gi] += (r * a - b).norm_squared();
        }
    }
    turns
        .into_iter()
        .enumerate()
        .map(|(g, t)| (t, residual[g] <= RIGID * RIGID * scale[g]))
        .collect()
}

/// The relative edge error under which a group counts as moved rigidly.
pub const RIGID: f64 = 1e-6;

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Two triangles folded at 90° along the x axis.
    fn fold() -> (Vec<Point>, Vec<[u32; 3]>) {
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        (p, vec![[0, 1, 2], [1, 0, 3]])
    }

    #[test]
    fn a_rigid_motion_gives_its_rotation_to_every_group() {
        let (p, t) = fold();
        // a quarter turn about z plus a shift
        let pose: Vec<Point> = p.iter().map(|q| [1.0 - q[1], q[0], q[2] + 2.0]).collect();
        let split = vec![[0, 1, 2], [4, 3, 5]];
        for turn in group_turns(&p, &pose, &t, &split, 6) {
            let x = turn.apply([1.0, 0.0, 0.0]);
            let z = turn.apply([0.0, 0.0, 1.0]);
            for (got, want) in [(x, [0.0, 1.0, 0.0]), (z, [0.0, 0.0, 1.0])] {
                for k in 0..3 {
                    assert_relative_eq!(got[k], want[k], epsilon = 1e-12);
                }
            }
        }
    }

    #[test]
    fn hard_edge_groups_follow_only_their_own_faces() {
        let (p, t) = fold();
        // open the fold: vertex 3 moves from +z to -y (flat), face 0 stays
        let mut pose = p.clone();
        pose[3] = [0.0, -1.0, 0.0];
        let split = vec![[0, 1, 2], [4, 3, 5]];
        let turns = group_turns(&p, &pose, &t, &split, 6);
        // face 0's groups did not move
        assert_eq!(turns[2], Turn::Keep);
        // face 1's normal (+y at rest) now faces +z
        let n = turns[5].apply([0.0, 1.0, 0.0]);
        assert_relative_eq!(n[2], 1.0, epsilon = 1e-12);
        assert_eq!(group_turns(&p, &p, &t, &split, 6), vec![Turn::Keep; 6]);
    }

    #[test]
    fn angle_weights_do_not_depend_on_how_faces_are_split() {
        // a cube corner at the origin: faces x = 0, y = 0, z = 0 (outward
        // normals -x, -y, -z); the origin is in two 45° triangles of the
        // first, one 90° triangle of the second and two 45° triangles of a
        // fan about the third's centre
        let p = vec![
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 1.0, 1.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 0.0],
            [0.5, 0.5, 0.0],
        ];
        let mut t: Vec<([u32; 3], Point)> = vec![
            ([0, 1, 2], [-1.0, 0.0, 0.0]),
            ([0, 2, 3], [-1.0, 0.0, 0.0]),
            ([0, 4, 3], [0.0, -1.0, 0.0]),
            ([4, 5, 3], [0.0, -1.0, 0.0]),
            ([7, 0, 4], [0.0, 0.0, -1.0]),
            ([7, 4, 6], [0.0, 0.0, -1.0]),
            ([7, 6, 1], [0.0, 0.0, -1.0]),
            ([7, 1, 0], [0.0, 0.0, -1.0]),
        ];
        for (tri, want) in &mut t {
            let n = cross(
                sub(p[tri[1] as usize], p[tri[0] as usize]),
                sub(p[tri[2] as usize], p[tri[0] as usize]),
            );
            if v3(n).dot(&v3(*want)) < 0.0 {
                tri.swap(1, 2);
            }
        }
        let tris: Vec<[u32; 3]> = t.iter().map(|(tri, _)| *tri).collect();
        let corner: Vec<[u32; 3]> = tris
            .iter()
            .map(|tri| tri.map(|v| u32::from(v != 0)))
            .collect();
        let n = weighted_normals(&p, &tris, &corner, 2)[0].unwrap();
        let s = -1.0 / 3f64.sqrt();
        for c in n {
            assert_relative_eq!(c, s, epsilon = 1e-12);
        }
        // a group whose triangles are all degenerate has no normal
        let flat = [[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]];
        assert_eq!(
            weighted_normals(&flat, &[[0, 1, 2]], &[[0, 0, 0]], 1),
            vec![None]
        );
    }

    #[test]
    fn a_shade_recomputes_the_normal_and_squares_the_tangent_to_it() {
        let (p, t) = fold();
        // open the fold flat: vertex 3 from +z to -y; one group per vertex
        let mut pose = p.clone();
        pose[3] = [0.0, -1.0, 0.0];
        let shades = group_shading(&p, &pose, &t, &t, 4);
        // vertex 0 touches both faces, now coplanar (normal +z)
        let n = shades[0].normal([0.0, 0.0, 1.0]).unwrap();
        assert_relative_eq!(n[2], 1.0, epsilon = 1e-12);
        // a tangent: turned, then orthogonal to that normal, unit
        let tan = shades[0]
            .tangent([1.0, 0.0, 0.0], Some([0.0, 0.0, 1.0]))
            .unwrap();
        assert!((v3(tan).dot(&v3(n))).abs() < 1e-12);
        assert_relative_eq!(v3(tan).norm(), 1.0, epsilon = 1e-12);
        // an unmoved group keeps the file's vectors
        assert_eq!(
            group_shading(&p, &p, &t, &t, 4)[0].normal([0.0, 0.0, 1.0]),
            None
        );
    }
}
