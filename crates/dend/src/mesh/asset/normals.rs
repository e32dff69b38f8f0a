//! Normals and tangents for a deformed asset.
//!
//! **Groups.** Asset vertices are grouped into *normal groups*: the asset
//! vertices at one welded vertex that had the same normal in the file (glTF:
//! bit-identical NORMAL; OBJ: the same `vn` index). A group sees only the
//! triangles incident to its own asset vertices, so a split made only for UVs
//! (same file normal on both sides) is one group, smooth across the seam, and
//! a hard edge (different file normals) stays hard: each side follows only its
//! own faces.
//!
//! **Rotation.** For each group, the rotation `R` that best maps its rest
//! neighbourhood onto the posed one (orthogonal Procrustes, by SVD, of the
//! edges from the group's corners to the other corners of its triangles, plus
//! the area-weighted normal so that a flat neighbourhood has a unique
//! answer).
//!
//! **What is written.** The file's own normal turned by `R`, and a tangent's
//! direction turned by `R` with its handedness `w` kept. Authored normals
//! (custom smoothing, weighted normals) are carried along with the surface
//! instead of being replaced; a rigid motion turns every normal exactly; a
//! group whose neighbourhood did not change shape or turn (every edge
//! vector from its corners is bit-identical; a translation is no change)
//! keeps the file's values exactly, so an identity
//! deformation changes nothing.

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

/// The turn of each group from `rest` to `pose` (both in the asset layout).
/// `corner_group[t][k]` is the group of corner `k` of triangle `t`.
pub fn group_turns(
    rest: &[Point],
    pose: &[Point],
    triangles: &[[u32; 3]],
    corner_group: &[[u32; 3]],
    groups: usize,
) -> Vec<Turn> {
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
        for k in 0..3 {
            let gi = g[k] as usize;
            n_rest[gi] += nr;
            n_pose[gi] += np;
            for j in [(k + 1) % 3, (k + 2) % 3] {
                let a = v3(sub(r[j], r[k]));
                let b = v3(sub(p[j], p[k]));
                cov[gi] += b * a.transpose();
                moved[gi] |= a != b;
                scale[gi] += a.norm_squared();
            }
        }
    }
    (0..groups)
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
        .collect()
}

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
}
