//! The triangle mesh: validated positions and faces, plus the adjacency DEND
//! needs (ordered 1-rings, boundary loops, connected components).
//!
//! A [`Mesh`] can only be built through [`Mesh::new`], which validates the input
//! and rejects, with a [`MeshError`] naming the *first* offending element:
//! non-finite coordinates, out-of-range or repeated indices in a face,
//! zero-area triangles, non-manifold edges and vertices, and inconsistent
//! orientation.
//!
//! **Unreferenced vertices are kept** (so that vertex indices in `.sel` files
//! and constraint files stay valid) and reported by
//! [`Mesh::unreferenced_vertices`]; the CLI prints a warning for them. They have
//! an empty 1-ring, zero area, and the solver leaves them where they are.

pub mod asset;
mod error;
pub mod gen;
pub mod io;
pub mod order;
mod point;
pub mod selection;
mod topology;
pub mod weld;

pub use error::MeshError;
pub use point::{Point, Real};

pub(crate) use topology::corner_offsets;
pub use topology::Topology;

/// A validated triangle mesh: `#V×3` positions (f64) and `#F×3` triangles (u32),
/// counter-clockwise seen from outside for closed meshes, with its adjacency.
#[derive(Debug, Clone)]
pub struct Mesh {
    positions: Vec<Point>,
    triangles: Vec<[u32; 3]>,
    topology: Topology,
}

impl Mesh {
    /// Validates `positions` and `triangles` and builds the adjacency.
    ///
    /// Checks, in this order, and reports the first failure: emptiness, size
    /// limits, finite coordinates, index range, repeated indices, zero area,
    /// non-manifold edges, orientation, non-manifold vertices.
    pub fn new(positions: Vec<Point>, triangles: Vec<[u32; 3]>) -> Result<Self, MeshError> {
        if triangles.is_empty() {
            return Err(MeshError::Empty {
                vertices: positions.len(),
            });
        }
        let max = u32::MAX as usize - 1;
        if positions.len() > max {
            return Err(MeshError::TooLarge {
                what: "vertices",
                count: positions.len(),
                max,
            });
        }
        if triangles.len() > max / 3 {
            return Err(MeshError::TooLarge {
                what: "triangles",
                count: triangles.len(),
                max: max / 3,
            });
        }
        if let Some((vertex, p)) = positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(MeshError::NonFinite { vertex, value: *p });
        }
        let nv = positions.len();
        for (face, t) in triangles.iter().enumerate() {
            if let Some(&index) = t.iter().find(|&&i| i as usize >= nv) {
                return Err(MeshError::IndexOutOfRange {
                    face,
                    index: index as u64,
                    vertices: nv,
                });
            }
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                return Err(MeshError::RepeatedIndex { face, tri: *t });
            }
        }
        for (face, t) in triangles.iter().enumerate() {
            if is_zero_area(&positions, t) {
                return Err(MeshError::ZeroArea { face, tri: *t });
            }
        }
        let topology = Topology::build(nv, &triangles)?;
        Ok(Mesh {
            positions,
            triangles,
            topology,
        })
    }

    /// Vertex positions, `#V×3`.
    pub fn positions(&self) -> &[Point] {
        &self.positions
    }

    /// Triangles, `#F×3`, indices into [`Mesh::positions`].
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Number of vertices (including unreferenced ones).
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn num_triangles(&self) -> usize {
        self.triangles.len()
    }

    /// The adjacency: 1-rings, boundary loops, components.
    pub fn topology(&self) -> &Topology {
        &self.topology
    }

    /// Vertices that no triangle uses, in increasing order.
    pub fn unreferenced_vertices(&self) -> Vec<u32> {
        (0..self.num_vertices() as u32)
            .filter(|&v| self.topology.ring(v as usize).is_empty())
            .collect()
    }

    /// The same connectivity with other positions (e.g. a deformed pose).
    ///
    /// Validates the new positions (finite, no zero-area triangle).
    pub fn with_positions(&self, positions: Vec<Point>) -> Result<Self, MeshError> {
        if positions.len() != self.positions.len() {
            return Err(MeshError::VertexCountMismatch {
                expected: self.positions.len(),
                got: positions.len(),
            });
        }
        if let Some((vertex, p)) = positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.iter().all(|c| c.is_finite()))
        {
            return Err(MeshError::NonFinite { vertex, value: *p });
        }
        for (face, t) in self.triangles.iter().enumerate() {
            if is_zero_area(&positions, t) {
                return Err(MeshError::ZeroArea { face, tri: *t });
            }
        }
        Ok(Mesh {
            positions,
            triangles: self.triangles.clone(),
            topology: self.topology.clone(),
        })
    }

    /// Axis-aligned bounding box `(min, max)`.
    pub fn bounding_box(&self) -> (Point, Point) {
        bounding_box(&self.positions)
    }

    /// Length of the bounding-box diagonal.
    pub fn diagonal(&self) -> Real {
        let (lo, hi) = self.bounding_box();
        norm(sub(hi, lo))
    }

    /// Mean length of the (undirected) edges.
    pub fn mean_edge_length(&self) -> Real {
        mean_edge_length(&self.positions, self.topology.edges())
    }

    /// Euler characteristic `V - E + F`, counting referenced vertices only.
    pub fn euler_characteristic(&self) -> i64 {
        let v = self.num_vertices() - self.unreferenced_vertices().len();
        v as i64 - self.topology.edges().len() as i64 + self.num_triangles() as i64
    }

    /// Total genus from `χ = 2c - 2g - b` (components `c`, boundary loops `b`).
    pub fn genus(&self) -> i64 {
        let c = self.topology.num_components() as i64;
        let b = self.topology.boundary_loops().len() as i64;
        (2 * c - b - self.euler_characteristic()) / 2
    }
}

/// Whether a triangle is numerically degenerate: `|e1 × e2| ≤ 4ε · ℓ_max²`.
pub(crate) fn is_zero_area(positions: &[Point], t: &[u32; 3]) -> bool {
    let [a, b, c] = t.map(|i| positions[i as usize]);
    let (e0, e1, e2) = (sub(b, a), sub(c, a), sub(c, b));
    let lmax = dot(e0, e0).max(dot(e1, e1)).max(dot(e2, e2));
    let cr = norm(cross(e0, e1));
    // NaN compares as degenerate too
    cr.partial_cmp(&(4.0 * Real::EPSILON * lmax)) != Some(std::cmp::Ordering::Greater)
}

/// Axis-aligned bounding box of a point set.
pub fn bounding_box(points: &[Point]) -> (Point, Point) {
    let mut lo = [Real::INFINITY; 3];
    let mut hi = [Real::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

/// Mean length over the undirected `edges` (each listed once).
pub fn mean_edge_length(positions: &[Point], edges: &[[u32; 2]]) -> Real {
    if edges.is_empty() {
        return 0.0;
    }
    let sum: Real = edges
        .iter()
        .map(|&[a, b]| norm(sub(positions[b as usize], positions[a as usize])))
        .sum();
    sum / edges.len() as Real
}

// --- small vector helpers used across the crate --------------------------------

/// `a - b`.
#[inline]
pub fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
/// `a + b`.
#[inline]
pub fn add(a: Point, b: Point) -> Point {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
/// `s a`.
#[inline]
pub fn scale(a: Point, s: Real) -> Point {
    [a[0] * s, a[1] * s, a[2] * s]
}
/// `a · b`.
#[inline]
pub fn dot(a: Point, b: Point) -> Real {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
/// `a × b`.
#[inline]
pub fn cross(a: Point, b: Point) -> Point {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
/// `|a|`.
#[inline]
pub fn norm(a: Point) -> Real {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> (Vec<Point>, Vec<[u32; 3]>) {
        (
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
            ],
            vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
        )
    }

    #[test]
    fn tetrahedron_is_closed_genus_zero() {
        let (p, t) = tetra();
        let m = Mesh::new(p, t).unwrap();
        assert_eq!(m.euler_characteristic(), 2);
        assert_eq!(m.genus(), 0);
        assert!(m.topology().boundary_loops().is_empty());
        assert_eq!(m.topology().num_components(), 1);
        for v in 0..4 {
            assert_eq!(m.topology().ring(v).len(), 3);
            assert!(!m.topology().is_boundary(v));
        }
    }

    #[test]
    fn rejects_each_kind_of_bad_input() {
        let (p, t) = tetra();
        let mut bad = p.clone();
        bad[2][1] = Real::NAN;
        assert!(matches!(
            Mesh::new(bad, t.clone()),
            Err(MeshError::NonFinite { vertex: 2, .. })
        ));
        let mut bt = t.clone();
        bt[1][2] = 9;
        assert!(matches!(
            Mesh::new(p.clone(), bt),
            Err(MeshError::IndexOutOfRange {
                face: 1,
                index: 9,
                ..
            })
        ));
        let mut bt = t.clone();
        bt[3] = [1, 1, 3];
        assert!(matches!(
            Mesh::new(p.clone(), bt),
            Err(MeshError::RepeatedIndex { face: 3, .. })
        ));
        let mut bt = t.clone();
        bt[3] = [2, 1, 3];
        assert!(matches!(
            Mesh::new(p.clone(), bt),
            Err(MeshError::InconsistentOrientation { .. })
        ));
        let mut bp = p.clone();
        bp[3] = [0.5, 0.5, 0.0]; // on the hypotenuse of face 0's plane: face 3 collinear? no: check below
        bp[2] = [2.0, 0.0, 0.0]; // 0,1,2 collinear
        assert!(matches!(
            Mesh::new(bp, t.clone()),
            Err(MeshError::ZeroArea { face: 0, .. })
        ));
        assert!(matches!(
            Mesh::new(p.clone(), vec![]),
            Err(MeshError::Empty { vertices: 4 })
        ));
    }

    #[test]
    fn rejects_non_manifold_edge_and_vertex() {
        // three triangles on edge (0,1)
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let t = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        assert!(matches!(
            Mesh::new(p, t),
            Err(MeshError::NonManifoldEdge {
                a: 0,
                b: 1,
                faces: 3
            })
        ));
        // bow tie: two triangles sharing only vertex 0
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [-1.0, 0.0, 0.0],
            [-1.0, -1.0, 0.0],
        ];
        let t = vec![[0, 1, 2], [0, 3, 4]];
        assert!(matches!(
            Mesh::new(p, t),
            Err(MeshError::NonManifoldVertex { vertex: 0, fans: 2 })
        ));
    }

    #[test]
    fn unreferenced_vertices_are_kept_and_reported() {
        let (mut p, t) = tetra();
        p.push([5.0, 5.0, 5.0]);
        let m = Mesh::new(p, t).unwrap();
        assert_eq!(m.num_vertices(), 5);
        assert_eq!(m.unreferenced_vertices(), vec![4]);
        assert_eq!(m.euler_characteristic(), 2);
    }
}
