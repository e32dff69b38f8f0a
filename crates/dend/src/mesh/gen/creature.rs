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

use super::{quad, Raw};
use crate::deform::{ConstraintsSpec, HandleSpec, VertexSet};
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
        let (corners, quads) = super::lattice_box(n, [0, 1, 2]);
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
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::deform::{Deformer, Factor, Params, Rest};
    use crate::mesh::gen::{generate, GenError, Shape, ShapeSpec};
    use crate::mesh::{cross, dot, norm, sub};

    fn default_creature() -> Mesh {
        generate(&ShapeSpec::default_for(Shape::Creature)).expect("a valid mesh")
    }

    /// Connected pieces of the triangles `keep` selects (shared vertices
    /// join them).
    fn pieces(mesh: &Mesh, keep: impl Fn(&[u32; 3]) -> bool) -> usize {
        let mut parent: Vec<usize> = (0..mesh.num_vertices()).collect();
        fn root(p: &mut [usize], mut i: usize) -> usize {
            while p[i] != i {
                p[i] = p[p[i]];
                i = p[i];
            }
            i
        }
        let mut used = vec![false; mesh.num_vertices()];
        for t in mesh.triangles().iter().filter(|t| keep(t)) {
            for k in 0..3 {
                used[t[k] as usize] = true;
                let (a, b) = (
                    root(&mut parent, t[k] as usize),
                    root(&mut parent, t[(k + 1) % 3] as usize),
                );
                parent[a] = b;
            }
        }
        (0..mesh.num_vertices())
            .filter(|&i| used[i] && root(&mut parent, i) == i)
            .count()
    }

    #[test]
    fn a_closed_oriented_genus_zero_surface() {
        for levels in 0..=3 {
            let mut spec = ShapeSpec::default_for(Shape::Creature);
            spec.params.nu = Some(levels);
            let m = generate(&spec).expect("Mesh::new accepts it");
            assert!(
                m.topology().boundary_loops().is_empty(),
                "level {levels}: closed"
            );
            assert_eq!(m.topology().num_components(), 1, "level {levels}");
            assert_eq!(m.genus(), 0, "level {levels}");
            assert!(m.unreferenced_vertices().is_empty(), "level {levels}");
            // outward: positive signed volume (Mesh::new already refused an
            // inconsistent orientation)
            let vol: f64 = m
                .triangles()
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| m.positions()[i as usize]);
                    dot(a, cross(b, c)) / 6.0
                })
                .sum();
            assert!(vol > 0.3, "level {levels}: volume {vol}");
        }
        let mut spec = ShapeSpec::default_for(Shape::Creature);
        spec.params.nu = Some(5);
        assert!(matches!(
            generate(&spec),
            Err(GenError::Resolution { what: "nu", .. })
        ));
    }

    #[test]
    fn four_legs_below_the_belly_and_smooth_limbs() {
        let m = default_creature();
        let (lo, hi) = m.bounding_box();
        assert!(lo[1].abs() < 1e-12, "stands on y = 0: {lo:?}");
        assert!(hi[0] - lo[0] > 2.5 && hi[1] > 1.8, "size {lo:?} {hi:?}");
        let p = m.positions();
        let below = |t: &[u32; 3]| t.iter().all(|&i| p[i as usize][1] < 0.75 * BELLY_HEIGHT);
        assert_eq!(pieces(&m, below), 4, "legs");
        // smooth: neighbouring faces turn by less than 45° everywhere (the
        // cage's box edges are 90°; at 2 levels the sharpest folds, ~42°,
        // are at the tips of the tail and the feet)
        let normal = |t: &[u32; 3]| {
            let [a, b, c] = t.map(|i| p[i as usize]);
            let n = cross(sub(b, a), sub(c, a));
            let l = norm(n);
            n.map(|x| x / l)
        };
        let mut by_edge = std::collections::HashMap::new();
        let (mut worst, mut at) = (0.0, [0.0; 3]);
        for t in m.triangles() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if let Some(n) = by_edge.insert((a.min(b), a.max(b)), normal(t)) {
                    let fold = dot(n, normal(t)).clamp(-1.0, 1.0).acos().to_degrees();
                    if fold > worst {
                        (worst, at) = (fold, p[a as usize]);
                    }
                }
            }
        }
        assert!(worst < 45.0, "sharpest fold {worst:.1}° at {at:?}");
    }

    #[test]
    fn the_default_edit_fixes_four_feet_and_moves_the_head() {
        let m = default_creature();
        let spec = creature_constraints(&m);
        let ids = |s: &VertexSet| match s {
            VertexSet::Indices(v) => v.clone(),
            other => panic!("index lists expected: {other:?}"),
        };
        let fixed = ids(&spec.fixed);
        let head = ids(&spec.handles[0].vertices);
        assert!(!fixed.is_empty() && !head.is_empty());
        assert!(fixed.iter().all(|i| !head.contains(i)), "disjoint");
        let set: std::collections::HashSet<u32> = fixed.iter().map(|&i| i as u32).collect();
        assert_eq!(
            pieces(&m, |t| t.iter().all(|i| set.contains(i))),
            4,
            "four feet"
        );
        // solvable: lift the head and turn it; the feet stay, the head follows
        let mut spec = spec;
        spec.handles[0].translate = Some([0.0, 0.3, 0.4]);
        let c = spec.resolve(&m).expect("a valid constraint set");
        let rest = Arc::new(Rest::new(m.clone()).expect("rest"));
        let params = Params::default();
        let f = Factor::build(&rest, &params, &c).expect("factor");
        let mut d = Deformer::new(rest, params);
        d.step(&f, &c, 60).expect("solve");
        let pose = d.pose();
        assert!(pose.iter().flatten().all(|x| x.is_finite()));
        for &i in &fixed {
            assert!(norm(sub(pose[i as usize], m.positions()[i as usize])) < 1e-9);
        }
        for &i in &head {
            let moved = sub(pose[i as usize], m.positions()[i as usize]);
            assert!(
                norm(sub(moved, [0.0, 0.3, 0.4])) < 1e-6,
                "head vertex {i}: {moved:?}"
            );
        }
        // the neck bent: a vertex between body and head moved part of the way
        let mid = (0..m.num_vertices())
            .filter(|&i| (1.0..1.3).contains(&m.positions()[i][0]))
            .map(|i| norm(sub(pose[i], m.positions()[i])))
            .fold(0.0, f64::max);
        assert!(mid > 0.05 && mid < 0.6, "neck moved {mid}");
    }
}
