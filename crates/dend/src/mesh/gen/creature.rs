//! The posable creature: a quadruped built the way an artist box-models
//! one. A coarse quad cage (a body box; four legs, a neck with a head and
//! a tail extruded from its faces) is smoothed by Catmull–Clark
//! subdivision, so the result is closed, manifold, consistently oriented
//! and smooth, with every limb a round tube that blends into the body.
//!
//! Axes as in glTF and the web editor: +y up (the feet stand on y = 0),
//! the head towards +x, the width along z. At `size` 1 the creature is
//! about 3.2 long and 2.4 high.
//!
//! [`creature_constraints`] gives the default edit: the four feet fixed,
//! the head one handle.

use std::collections::HashMap;

use super::lattice::{lattice_box, quad, Raw};
use crate::mesh::selection::{ConstraintsSpec, HandleSpec, VertexSet};
use crate::mesh::{Mesh, Point, Real};

/// Height (at `size` 1) below which a vertex belongs to a foot: the fixed
/// region of [`creature_constraints`].
pub const FOOT_HEIGHT: Real = 0.12;
/// Distance (at `size` 1) behind the tip of the snout within which a
/// vertex belongs to the head: the handle of [`creature_constraints`].
pub const HEAD_DEPTH: Real = 0.55;
/// Height (at `size` 1) of the underside of the body: everything below it
/// is leg.
pub const BELLY_HEIGHT: Real = 0.85;

/// A quad cage: positions and counter-clockwise (seen from outside) quads.
struct Cage {
    pos: Vec<Point>,
    quads: Vec<[u32; 4]>,
}

impl Cage {
    /// The surface of the box `lo..hi` cut into `n[a]` cells along axis `a`.
    fn boxed(n: [u32; 3], lo: Point, hi: Point) -> Cage {
        let (corners, quads) = lattice_box(n, [0, 1, 2]);
        let pos = corners
            .iter()
            .map(|c| [0, 1, 2].map(|a| lo[a] + (hi[a] - lo[a]) * c[a] as Real / n[a] as Real))
            .collect();
        Cage { pos, quads }
    }

    fn centroid(&self, f: usize) -> Point {
        let q = self.quads[f];
        [0, 1, 2].map(|a| q.iter().map(|&i| self.pos[i as usize][a]).sum::<Real>() / 4.0)
    }

    /// The quad whose centroid is nearest `p`.
    fn face_at(&self, p: Point) -> usize {
        let d2 = |c: Point| (0..3).map(|a| (c[a] - p[a]).powi(2)).sum::<Real>();
        (0..self.quads.len())
            .min_by(|&a, &b| d2(self.centroid(a)).total_cmp(&d2(self.centroid(b))))
            .expect("a non-empty cage")
    }

    /// Extrudes quad `f`: its corners are copied, moved by `offset` and
    /// scaled per axis by `scale` about their centroid; four side quads
    /// join the old ring to the new one. The quad keeps its index.
    fn extrude(&mut self, f: usize, offset: Point, scale: Point) {
        let c = self.centroid(f);
        let old = self.quads[f];
        let new = old.map(|i| {
            let p = self.pos[i as usize];
            self.pos
                .push([0, 1, 2].map(|a| c[a] + offset[a] + (p[a] - c[a]) * scale[a]));
            (self.pos.len() - 1) as u32
        });
        for k in 0..4 {
            let k1 = (k + 1) % 4;
            self.quads.push([old[k], old[k1], new[k1], new[k]]);
        }
        self.quads[f] = new;
    }

    /// Extrudes the quad nearest `at` once per step `(offset, scale)`.
    fn limb(&mut self, at: Point, steps: &[(Point, Point)]) {
        let f = self.face_at(at);
        for &(offset, scale) in steps {
            self.extrude(f, offset, scale);
        }
    }

    /// One Catmull–Clark step on a closed quad mesh: new vertices are the
    /// moved old vertices, then the face points, then the edge points.
    fn subdivide(&self) -> Cage {
        let nv = self.pos.len();
        let nf = self.quads.len();
        let avg = |ps: &[Point]| {
            [0, 1, 2].map(|a| ps.iter().map(|p| p[a]).sum::<Real>() / ps.len() as Real)
        };
        let face: Vec<Point> = (0..nf).map(|f| self.centroid(f)).collect();
        // edges in order of first use: (low, high) → index, and each
        // edge's ends and adjacent faces (visited in that order, so that
        // the sums below, and the mesh, are the same on every run)
        let mut edge_index: HashMap<(u32, u32), usize> = HashMap::new();
        let mut edges: Vec<((u32, u32), Vec<usize>)> = Vec::new();
        for (f, q) in self.quads.iter().enumerate() {
            for k in 0..4 {
                let (a, b) = (q[k], q[(k + 1) % 4]);
                let key = (a.min(b), a.max(b));
                let e = *edge_index.entry(key).or_insert_with(|| {
                    edges.push((key, Vec::new()));
                    edges.len() - 1
                });
                edges[e].1.push(f);
            }
        }
        let mut edge_pt = Vec::with_capacity(edges.len());
        let mut faces_of: Vec<Vec<usize>> = vec![Vec::new(); nv];
        let mut mids_of: Vec<Vec<Point>> = vec![Vec::new(); nv];
        for ((a, b), fs) in &edges {
            let (pa, pb) = (self.pos[*a as usize], self.pos[*b as usize]);
            let mut ps = vec![pa, pb];
            ps.extend(fs.iter().map(|&f| face[f]));
            edge_pt.push(avg(&ps));
            let mid = avg(&[pa, pb]);
            mids_of[*a as usize].push(mid);
            mids_of[*b as usize].push(mid);
        }
        for (f, q) in self.quads.iter().enumerate() {
            for &i in q {
                faces_of[i as usize].push(f);
            }
        }
        let mut pos: Vec<Point> = (0..nv)
            .map(|i| {
                let n = mids_of[i].len() as Real;
                let q = avg(&faces_of[i].iter().map(|&f| face[f]).collect::<Vec<_>>());
                let r = avg(&mids_of[i]);
                let p = self.pos[i];
                [0, 1, 2].map(|a| (q[a] + 2.0 * r[a] + (n - 3.0) * p[a]) / n)
            })
            .collect();
        pos.extend(&face);
        pos.extend(&edge_pt);
        let e = |a: u32, b: u32| (nv + nf + edge_index[&(a.min(b), a.max(b))]) as u32;
        let mut quads = Vec::with_capacity(4 * nf);
        for (f, q) in self.quads.iter().enumerate() {
            let c = (nv + f) as u32;
            for k in 0..4 {
                let (prev, v, next) = (q[(k + 3) % 4], q[k], q[(k + 1) % 4]);
                quads.push([v, e(v, next), c, e(prev, v)]);
            }
        }
        Cage { pos, quads }
    }
}

/// The quadruped's cage at `size` 1 (see the module doc).
fn cage() -> Cage {
    // body: 2 long (x), 0.8 wide (z), 0.6 high (y), bottom at 0.9
    let mut c = Cage::boxed([4, 2, 3], [-1.0, 0.9, -0.4], [1.0, 1.5, 0.4]);
    let leg = [
        ([0.0, -0.3, 0.0], [0.6, 1.0, 0.95]),
        ([0.0, -0.3, 0.0], [0.9, 1.0, 0.9]),
        ([0.0, -0.25, 0.0], [0.9, 1.0, 0.9]),
        ([0.04, -0.12, 0.0], [1.05, 1.0, 1.05]),
    ];
    for x in [-0.75, 0.75] {
        for z in [-0.267, 0.267] {
            c.limb([x, 0.9, z], &leg);
        }
    }
    // neck, head and snout from the front face's upper middle quad
    c.limb(
        [1.0, 1.35, 0.0],
        &[
            ([0.25, 0.3, 0.0], [1.0, 0.85, 0.85]),
            ([0.15, 0.3, 0.0], [1.0, 0.9, 0.9]),
            ([0.25, 0.1, 0.0], [1.0, 1.6, 1.7]),
            ([0.3, -0.1, 0.0], [1.0, 0.55, 0.6]),
        ],
    );
    // a short tail from the back face's upper middle quad
    c.limb(
        [-1.0, 1.35, 0.0],
        &[
            ([-0.3, 0.15, 0.0], [1.0, 0.7, 0.7]),
            ([-0.25, 0.2, 0.0], [1.0, 0.8, 0.8]),
            // a short last step rounds the tip off
            ([-0.08, 0.04, 0.0], [1.0, 0.9, 0.9]),
        ],
    );
    c
}

/// The creature's surface: the cage after `levels` Catmull–Clark steps,
/// scaled by `size`, standing on y = 0.
pub(super) fn creature(levels: u32, size: Real) -> Raw {
    let mut c = cage();
    for _ in 0..levels {
        c = c.subdivide();
    }
    let floor = c.pos.iter().map(|p| p[1]).fold(Real::INFINITY, Real::min);
    let pos = c
        .pos
        .iter()
        .map(|p| [p[0] * size, (p[1] - floor) * size, p[2] * size])
        .collect();
    let mut tris = Vec::with_capacity(2 * c.quads.len());
    for q in c.quads {
        quad(&mut tris, q);
    }
    (pos, tris)
}

/// The creature's default edit: the four feet (vertices within
/// [`FOOT_HEIGHT`] of the floor) fixed, and the head (within
/// [`HEAD_DEPTH`] of the snout's tip) the handle `head`, both as index
/// lists (the editor shows them as painted regions). Sizes scale with the
/// mesh (its height over the unit creature's).
pub fn creature_constraints(mesh: &Mesh) -> ConstraintsSpec {
    let (lo, hi) = mesh.bounding_box();
    let unit = generated_height();
    let s = (hi[1] - lo[1]) / unit;
    let pick = |keep: &dyn Fn(&Point) -> bool| -> Vec<u64> {
        (0..mesh.num_vertices() as u64)
            .filter(|&i| keep(&mesh.positions()[i as usize]))
            .collect()
    };
    let fixed = pick(&|p| p[1] <= lo[1] + FOOT_HEIGHT * s);
    let head = pick(&|p| p[0] >= hi[0] - HEAD_DEPTH * s);
    ConstraintsSpec {
        fixed: VertexSet::Indices(fixed),
        fixed_positions: None,
        handles: vec![HandleSpec {
            name: Some("head".into()),
            vertices: VertexSet::Indices(head),
            translate: None,
            rotate: None,
            pivot: None,
            positions: None,
        }],
    }
}

/// The height of the creature at `size` 1 and one subdivision level
/// (subdivision changes it by well under 1 %).
fn generated_height() -> Real {
    let (p, _) = creature(1, 1.0);
    p.iter().map(|q| q[1]).fold(0.0, Real::max)
}

#[cfg(test)]
#[path = "creature_tests.rs"]
mod tests;
