//! A vertex order with locality for the solver's arrays ([`VertexOrder`]).
//!
//! Every kernel of the iteration reads each vertex's neighbours (rotations,
//! positions, area projections). When neighbours have nearby indices those
//! reads hit the cache; a mesh whose file numbers its vertices without
//! locality (a scan merged from parts, a decimation tool's output) makes
//! them miss it. `armadillo_43k` is such a mesh: over its edges the median
//! index gap is 1026 and 26 % of the gaps exceed 4096, against 300 and
//! none for `feline_50k`. The solver then works in a breadth-first order
//! (Cuthill & McKee 1969, without their degree sort) and maps constraints
//! and poses at its API (`deform::Rest`).

use super::{Mesh, Point};

/// A permutation of a mesh's vertices: `internal[v]` is the solver's index
/// of the mesh's vertex `v`, `user[i]` the mesh's index of solver vertex
/// `i` (inverse permutations).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VertexOrder {
    internal: Vec<u32>,
    user: Vec<u32>,
}

/// An edge whose endpoints' indices differ by more than this is
/// *scattered* ([`scattered_share`]): the rows of about 4096 vertices (a few
/// hundred bytes each over the iteration's arrays) no longer share a core's
/// cache.
pub const SCATTER_GAP: usize = 4096;

/// A mesh whose scattered share is at least this is renumbered
/// ([`VertexOrder::for_locality`]; armadillo_43k 0.26, igea_134k 0.12,
/// nefertiti_50k 0.075; feline_50k, eth_hand_14k, dino_14070 and the
/// survey bumpy plane 0.001 or less).
pub const SCATTER_SHARE: f64 = 0.05;

/// Meshes with fewer vertices keep their order: their arrays fit in the
/// cache whatever the order (camel_9770's scattered share is 0.33, and
/// its iteration is as fast per vertex as the feline's).
pub const REORDER_MIN_VERTICES: usize = 16384;

/// The share of `mesh`'s edges (each triangle's three, shared ones twice)
/// whose endpoints' indices are more than [`SCATTER_GAP`] apart.
pub fn scattered_share(mesh: &Mesh) -> f64 {
    let t = mesh.triangles();
    if t.is_empty() {
        return 0.0;
    }
    let far = t
        .iter()
        .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
        .filter(|&(a, b)| a.abs_diff(b) as usize > SCATTER_GAP)
        .count();
    far as f64 / (3 * t.len()) as f64
}

impl VertexOrder {
    /// The breadth-first order of `mesh` when it needs one: at least
    /// [`REORDER_MIN_VERTICES`] vertices and a [`scattered_share`] of at
    /// least [`SCATTER_SHARE`]; `None` otherwise (the mesh's own order).
    pub fn for_locality(mesh: &Mesh) -> Option<VertexOrder> {
        (mesh.num_vertices() >= REORDER_MIN_VERTICES && scattered_share(mesh) >= SCATTER_SHARE)
            .then(|| VertexOrder::breadth_first(mesh))
    }

    /// Breadth-first order over the edges, each connected component from
    /// its lowest unvisited index, neighbours in ring order; vertices on no
    /// triangle keep their relative order among the rest.
    pub fn breadth_first(mesh: &Mesh) -> VertexOrder {
        let n = mesh.num_vertices();
        let topo = mesh.topology();
        let mut user = Vec::with_capacity(n);
        let mut seen = vec![false; n];
        for s in 0..n {
            if seen[s] {
                continue;
            }
            seen[s] = true;
            let head = user.len();
            user.push(s as u32);
            let mut next = head;
            while next < user.len() {
                let v = user[next] as usize;
                next += 1;
                for &j in topo.ring(v) {
                    if !seen[j as usize] {
                        seen[j as usize] = true;
                        user.push(j);
                    }
                }
            }
        }
        let mut internal = vec![0u32; n];
        for (i, &v) in user.iter().enumerate() {
            internal[v as usize] = i as u32;
        }
        VertexOrder { internal, user }
    }

    /// The solver's index of the mesh's vertex `v`.
    #[inline]
    pub fn internal(&self, v: u32) -> u32 {
        self.internal[v as usize]
    }

    /// The mesh's index of solver vertex `i`.
    #[inline]
    pub fn user(&self, i: u32) -> u32 {
        self.user[i as usize]
    }

    /// `mesh` renumbered: vertex `i` is the mesh's `user(i)`; triangles
    /// keep their orientation and are sorted by their lowest new index
    /// (stably), so that per-triangle arrays (the area term's projections)
    /// follow the vertices too.
    pub fn renumber(&self, mesh: &Mesh) -> Mesh {
        let p = mesh.positions();
        let positions = self.user.iter().map(|&v| p[v as usize]).collect();
        let mut triangles: Vec<[u32; 3]> = mesh
            .triangles()
            .iter()
            .map(|t| t.map(|v| self.internal(v)))
            .collect();
        triangles.sort_by_key(|t| t[0].min(t[1]).min(t[2]));
        Mesh::new(positions, triangles).expect("a renumbered valid mesh is valid")
    }

    /// Per-vertex values in the mesh's order into the solver's (`out[i] =
    /// values[user(i)]`).
    pub fn to_internal(&self, values: &[Point], out: &mut Vec<Point>) {
        out.clear();
        out.extend(self.user.iter().map(|&v| values[v as usize]));
    }

    /// Per-vertex values in the solver's order into the mesh's (`out[v] =
    /// values[internal(v)]`).
    pub fn to_user(&self, values: &[Point], out: &mut Vec<Point>) {
        out.clear();
        out.extend(self.internal.iter().map(|&i| values[i as usize]));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::gen::{generate, Shape, ShapeParams, ShapeSpec};

    /// The generated creature at `levels` Catmull–Clark levels (3: 9,218
    /// vertices, 4: 36,866).
    fn creature(levels: u32) -> Mesh {
        generate(&ShapeSpec {
            shape: Shape::Creature,
            params: ShapeParams {
                nu: Some(levels),
                ..ShapeParams::default()
            },
        })
        .unwrap()
    }

    /// `mesh` with its vertices numbered by the permutation `perm`
    /// (`perm[old] = new`).
    fn permuted(mesh: &Mesh, perm: &[u32]) -> Mesh {
        let mut p = vec![[0.0; 3]; mesh.num_vertices()];
        for (old, &new) in perm.iter().enumerate() {
            p[new as usize] = mesh.positions()[old];
        }
        let t = mesh
            .triangles()
            .iter()
            .map(|t| t.map(|v| perm[v as usize]))
            .collect();
        Mesh::new(p, t).unwrap()
    }

    /// A shuffle of `0..n` (a fixed linear congruential sequence).
    fn shuffle(n: usize) -> Vec<u32> {
        let mut v: Vec<u32> = (0..n as u32).collect();
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        for i in (1..n).rev() {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
            v.swap(i, (s >> 33) as usize % (i + 1));
        }
        v
    }

    /// The order is a permutation and its inverse, renumbering keeps the
    /// geometry (the same triangles as point triples), and on a shuffled
    /// generated mesh it brings the scattered share from most edges to
    /// almost none.
    #[test]
    fn breadth_first_renumbers_a_shuffled_mesh_with_locality() {
        let mesh = creature(4);
        let n = mesh.num_vertices();
        let shuffled = permuted(&mesh, &shuffle(n));
        assert!(
            scattered_share(&shuffled) > 0.5,
            "{}",
            scattered_share(&shuffled)
        );
        let order = VertexOrder::breadth_first(&shuffled);
        let mut seen = vec![false; n];
        for v in 0..n as u32 {
            let i = order.internal(v);
            assert_eq!(order.user(i), v);
            assert!(!std::mem::replace(&mut seen[i as usize], true));
        }
        let renumbered = order.renumber(&shuffled);
        // the same triangles, as oriented point triples (bit patterns),
        // each starting at its lowest point
        let triples = |m: &Mesh| {
            let mut v: Vec<[[u64; 3]; 3]> = m
                .triangles()
                .iter()
                .map(|t| {
                    let mut tri: [[u64; 3]; 3] =
                        std::array::from_fn(|j| m.positions()[t[j] as usize].map(f64::to_bits));
                    let k = (0..3).min_by_key(|&k| tri[k]).unwrap();
                    tri.rotate_left(k);
                    tri
                })
                .collect();
            v.sort_unstable();
            v
        };
        assert_eq!(triples(&shuffled), triples(&renumbered));
        let share = scattered_share(&renumbered);
        assert!(share < 0.01, "scattered share after renumbering {share}");
        let (mut inner, mut back) = (vec![], vec![]);
        order.to_internal(shuffled.positions(), &mut inner);
        assert_eq!(inner, renumbered.positions());
        order.to_user(&inner, &mut back);
        assert_eq!(back, shuffled.positions());
    }

    /// Only large scattered meshes are renumbered: a shuffled creature of
    /// 36,866 vertices is, the same at 9,218 vertices is not, and a
    /// renumbered one is not renumbered again.
    #[test]
    fn only_large_scattered_meshes_get_an_order() {
        let large = creature(4);
        let shuffled = permuted(&large, &shuffle(large.num_vertices()));
        let order = VertexOrder::for_locality(&shuffled).expect("renumbered");
        assert_eq!(VertexOrder::for_locality(&order.renumber(&shuffled)), None);
        let small = creature(3);
        assert!(small.num_vertices() < REORDER_MIN_VERTICES);
        let shuffled = permuted(&small, &shuffle(small.num_vertices()));
        assert!(scattered_share(&shuffled) >= SCATTER_SHARE);
        assert_eq!(VertexOrder::for_locality(&shuffled), None);
    }
}
