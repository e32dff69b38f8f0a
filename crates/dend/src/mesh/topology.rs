//! Adjacency of a manifold, consistently oriented triangle mesh.
//!
//! Built once by [`Topology::build`] (which also performs the combinatorial
//! part of validation): the ordered 1-ring of every vertex, the undirected
//! edge list, boundary loops and connected components.

use super::error::MeshError;

/// The adjacency of a validated mesh.
///
/// **Ring order.** For a vertex `i`, [`Topology::ring`] lists its neighbours
/// `j_1, …, j_m` so that every consecutive pair `(j_t, j_{t+1})` spans a face
/// `(i, j_t, j_{t+1})` in the mesh's own (counter-clockwise) orientation. An
/// interior vertex's ring is cyclic (`(j_m, j_1)` is a face too, and `m` equals
/// the number of incident faces); a boundary vertex's ring is open, starts and
/// ends on boundary edges, and has one more neighbour than incident faces.
#[derive(Debug, Clone)]
pub struct Topology {
    ring_offsets: Vec<u32>,
    ring: Vec<u32>,
    boundary: Vec<bool>,
    edges: Vec<[u32; 2]>,
    boundary_loops: Vec<Vec<u32>>,
    component: Vec<u32>,
    num_components: usize,
}

impl Topology {
    /// Builds the adjacency, rejecting non-manifold edges, inconsistent
    /// orientation and non-manifold vertices (in that order). Indices must
    /// already be in range and distinct within each face.
    pub fn build(nv: usize, triangles: &[[u32; 3]]) -> Result<Self, MeshError> {
        // Sorted keys instead of hash maps: O(F log F), cache friendly, and
        // the first offending element (in face order) is still reported.
        let key = |a: u32, b: u32| ((a.min(b) as u64) << 32) | a.max(b) as u64;
        let dkey = |a: u32, b: u32| ((a as u64) << 32) | b as u64;
        let mut ukeys: Vec<u64> = Vec::with_capacity(triangles.len() * 3);
        for t in triangles {
            for k in 0..3 {
                ukeys.push(key(t[k], t[(k + 1) % 3]));
            }
        }
        ukeys.sort_unstable();
        // Undirected edges shared by 3+ faces.
        let mut bad: Vec<(u64, usize)> = Vec::new();
        let mut edges: Vec<[u32; 2]> = Vec::with_capacity(ukeys.len() / 2 + 1);
        let mut i = 0;
        while i < ukeys.len() {
            let mut j = i + 1;
            while j < ukeys.len() && ukeys[j] == ukeys[i] {
                j += 1;
            }
            if j - i > 2 {
                bad.push((ukeys[i], j - i));
            }
            edges.push([(ukeys[i] >> 32) as u32, ukeys[i] as u32]);
            i = j;
        }
        drop(ukeys);
        if !bad.is_empty() {
            for t in triangles {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    if let Ok(p) = bad.binary_search_by_key(&key(a, b), |&(k, _)| k) {
                        return Err(MeshError::NonManifoldEdge {
                            a: a.min(b),
                            b: a.max(b),
                            faces: bad[p].1,
                        });
                    }
                }
            }
        }
        // Directed half-edges: each may appear once.
        let mut half: Vec<(u64, u32)> = Vec::with_capacity(triangles.len() * 3);
        for (f, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                half.push((dkey(t[k], t[(k + 1) % 3]), f as u32));
            }
        }
        half.sort_unstable();
        if let Some(w) = half
            .windows(2)
            .filter(|w| w[0].0 == w[1].0)
            .min_by_key(|w| w[1].1)
        {
            return Err(MeshError::InconsistentOrientation {
                face_a: w[0].1 as usize,
                face_b: w[1].1 as usize,
                a: (w[0].0 >> 32) as u32,
                b: w[0].0 as u32,
            });
        }
        let has_half = |a: u32, b: u32| half.binary_search_by_key(&dkey(a, b), |&(k, _)| k).is_ok();

        // Corners per vertex (CSR): for vertex i in face (i, j, k): j -> k.
        let corner_off = corner_offsets(nv, triangles);
        let mut fill = corner_off.clone();
        let mut corners = vec![(0u32, 0u32); triangles.len() * 3];
        for t in triangles {
            for k in 0..3 {
                let (i, j, l) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                corners[fill[i as usize]] = (j, l);
                fill[i as usize] += 1;
            }
        }

        let mut ring_offsets = Vec::with_capacity(nv + 1);
        let mut ring = Vec::with_capacity(triangles.len() * 3 + nv);
        let mut boundary = vec![false; nv];
        ring_offsets.push(0u32);
        for i in 0..nv {
            let cs = &corners[corner_off[i]..corner_off[i + 1]];
            if !cs.is_empty() {
                // A fan starts at a `j` that is no corner's `l` (boundary vertex).
                let start = cs
                    .iter()
                    .position(|&(j, _)| !cs.iter().any(|&(_, l)| l == j));
                let open = start.is_some();
                let mut cur = start.unwrap_or(0);
                let mut visited = 0usize;
                let first = cs[cur].0;
                ring.push(first);
                loop {
                    visited += 1;
                    let next = cs[cur].1;
                    if !open && next == first {
                        break;
                    }
                    ring.push(next);
                    match cs.iter().position(|&(j, _)| j == next) {
                        Some(p) if visited < cs.len() => cur = p,
                        _ => break,
                    }
                }
                if visited != cs.len() {
                    return Err(MeshError::NonManifoldVertex {
                        vertex: i as u32,
                        fans: count_fans(cs),
                    });
                }
                boundary[i] = open;
            }
            ring_offsets.push(ring.len() as u32);
        }

        // Boundary loops: half-edges a -> b without twin b -> a. Manifold
        // vertices have at most one outgoing boundary half-edge.
        let mut bnext = vec![u32::MAX; nv];
        let mut starts = Vec::new();
        for &(k, _) in &half {
            let (a, b) = ((k >> 32) as u32, k as u32);
            if !has_half(b, a) {
                bnext[a as usize] = b;
                starts.push(a);
            }
        }
        starts.sort_unstable();
        let mut seen = vec![false; nv];
        let mut boundary_loops = Vec::new();
        for s in starts {
            if seen[s as usize] {
                continue;
            }
            let mut lp = vec![s];
            seen[s as usize] = true;
            let mut v = bnext[s as usize];
            while v != s && v != u32::MAX && !seen[v as usize] {
                lp.push(v);
                seen[v as usize] = true;
                v = bnext[v as usize];
            }
            boundary_loops.push(lp);
        }

        // Components by union-find over edges; unreferenced vertices get none.
        let mut parent: Vec<u32> = (0..nv as u32).collect();
        fn find(p: &mut [u32], mut x: u32) -> u32 {
            while p[x as usize] != x {
                p[x as usize] = p[p[x as usize] as usize];
                x = p[x as usize];
            }
            x
        }
        for &[a, b] in &edges {
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            if ra != rb {
                parent[ra.max(rb) as usize] = ra.min(rb);
            }
        }
        let mut label = vec![u32::MAX; nv];
        let mut root_label = vec![u32::MAX; nv];
        let mut num_components = 0u32;
        for v in 0..nv {
            if ring_offsets[v] == ring_offsets[v + 1] {
                continue;
            }
            let r = find(&mut parent, v as u32) as usize;
            if root_label[r] == u32::MAX {
                root_label[r] = num_components;
                num_components += 1;
            }
            label[v] = root_label[r];
        }
        Ok(Topology {
            ring_offsets,
            ring,
            boundary,
            edges,
            boundary_loops,
            component: label,
            num_components: num_components as usize,
        })
    }

    /// The ordered 1-ring of vertex `i` (see the type's doc for the order).
    pub fn ring(&self, i: usize) -> &[u32] {
        &self.ring[self.ring_offsets[i] as usize..self.ring_offsets[i + 1] as usize]
    }

    /// Whether vertex `i` lies on the boundary (its ring is open).
    pub fn is_boundary(&self, i: usize) -> bool {
        self.boundary[i]
    }

    /// The undirected edges `[a, b]` with `a < b`, sorted.
    pub fn edges(&self) -> &[[u32; 2]] {
        &self.edges
    }

    /// Boundary loops, each a closed vertex cycle following the boundary
    /// half-edges' direction.
    pub fn boundary_loops(&self) -> &[Vec<u32>] {
        &self.boundary_loops
    }

    /// Number of connected components (over referenced vertices).
    pub fn num_components(&self) -> usize {
        self.num_components
    }

    /// The component label of vertex `i` (`None` for an unreferenced vertex).
    pub fn component(&self, i: usize) -> Option<u32> {
        match self.component[i] {
            u32::MAX => None,
            c => Some(c),
        }
    }
}

/// Number of fans the corners `(j, l)` of one vertex form (connected groups
/// of faces sharing an edge at that vertex).
/// The CSR offsets of the triangle corners at each vertex: vertex `v`'s
/// corners are `offsets[v]..offsets[v + 1]` in any list that stores them
/// grouped by vertex in triangle order (`#V + 1` entries).
pub(crate) fn corner_offsets(num_vertices: usize, triangles: &[[u32; 3]]) -> Vec<usize> {
    let mut offsets = vec![0usize; num_vertices + 1];
    for t in triangles {
        for &v in t {
            offsets[v as usize + 1] += 1;
        }
    }
    for i in 0..num_vertices {
        offsets[i + 1] += offsets[i];
    }
    offsets
}

fn count_fans(cs: &[(u32, u32)]) -> usize {
    let n = cs.len();
    let mut group: Vec<usize> = (0..n).collect();
    fn find(g: &mut [usize], mut x: usize) -> usize {
        while g[x] != x {
            g[x] = g[g[x]];
            x = g[x];
        }
        x
    }
    for a in 0..n {
        for b in 0..n {
            if cs[a].1 == cs[b].0 {
                let (ra, rb) = (find(&mut group, a), find(&mut group, b));
                group[ra] = rb;
            }
        }
    }
    (0..n).filter(|&a| find(&mut group, a) == a).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3x3-vertex grid (2x2 quads, 8 triangles), CCW seen from +z.
    fn grid() -> Vec<[u32; 3]> {
        let mut t = Vec::new();
        for r in 0..2u32 {
            for c in 0..2u32 {
                let v = r * 3 + c;
                t.push([v, v + 1, v + 4]);
                t.push([v, v + 4, v + 3]);
            }
        }
        t
    }

    #[test]
    fn grid_rings_are_ordered_and_open_on_the_boundary() {
        let t = grid();
        let topo = Topology::build(9, &t).unwrap();
        // centre vertex 4: closed ring of 6
        assert!(!topo.is_boundary(4));
        let r = topo.ring(4);
        assert_eq!(r.len(), 6);
        // consecutive pairs (cyclic) are faces (4, a, b) in CCW order
        for k in 0..r.len() {
            let (a, b) = (r[k], r[(k + 1) % r.len()]);
            assert!(
                t.iter().any(
                    |f| (0..3).any(|s| f[s] == 4 && f[(s + 1) % 3] == a && f[(s + 2) % 3] == b)
                ),
                "({a},{b}) is not a face around 4"
            );
        }
        // corner vertex 0 has faces [0,1,4] and [0,4,3]: open ring 1,4,3
        assert!(topo.is_boundary(0));
        assert_eq!(topo.ring(0), &[1, 4, 3]);
        assert_eq!(topo.boundary_loops().len(), 1);
        assert_eq!(topo.boundary_loops()[0].len(), 8);
        assert_eq!(topo.edges().len(), 16);
        assert_eq!(topo.num_components(), 1);
    }

    #[test]
    fn two_components_are_labelled_apart() {
        let t = vec![[0, 1, 2], [3, 4, 5]];
        let topo = Topology::build(7, &t).unwrap();
        assert_eq!(topo.num_components(), 2);
        assert_ne!(topo.component(0), topo.component(3));
        assert_eq!(topo.component(6), None);
        assert_eq!(topo.boundary_loops().len(), 2);
    }
}
