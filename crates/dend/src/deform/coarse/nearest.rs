//! The nearest coarse vertex of every fine vertex ([`nearest_sources`]).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::mesh::{norm, sub, Point, Real, Topology};

/// For each vertex, the source (index into `sources`) nearest to it along
/// the mesh's edges, by multi-source Dijkstra with edge lengths
/// `|x_i − x_j|` of `positions`; `u32::MAX` for vertices no source reaches
/// (unreferenced vertices, components without a source); between sources
/// at the same distance (to a relative [`TIE`]) the one listed first.
/// O(E log V).
pub fn nearest_sources(topo: &Topology, positions: &[Point], sources: &[u32]) -> Vec<u32> {
    let n = positions.len();
    let mut dist = vec![Real::INFINITY; n];
    let mut near = vec![u32::MAX; n];
    let mut heap = BinaryHeap::new();
    for (s, &v) in sources.iter().enumerate() {
        dist[v as usize] = 0.0;
        near[v as usize] = s as u32;
        heap.push(Entry(0.0, v));
    }
    while let Some(Entry(d, v)) = heap.pop() {
        let v = v as usize;
        if d > dist[v] {
            continue;
        }
        for &w in topo.ring(v) {
            let w = w as usize;
            let dw = d + norm(sub(positions[w], positions[v]));
            // distances within TIE of each other are equal: the smaller
            // source index wins, so rounding (which differs with the
            // unit of length) does not pick between equidistant sources
            let tie = TIE * dw;
            let closer = dw < dist[w] - tie;
            if closer || (dw <= dist[w] + tie && near[v] < near[w]) {
                near[w] = near[v];
                if dw < dist[w] {
                    dist[w] = dw;
                    heap.push(Entry(dw, w as u32));
                }
            }
        }
    }
    near
}

/// Relative difference under which two path lengths count as equal in
/// [`nearest_sources`] (symmetric meshes have many equidistant sources,
/// whose computed lengths differ by rounding).
const TIE: Real = 1e-9;

/// A heap entry, smallest distance first.
struct Entry(Real, u32);

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;

    #[test]
    fn a_strip_splits_at_the_midpoint() {
        // a strip of 2 × 6 vertices, unit squares; sources at both ends
        let mut p = Vec::new();
        for x in 0..6 {
            p.push([x as Real, 0.0, 0.0]);
            p.push([x as Real, 1.0, 0.0]);
        }
        let mut t = Vec::new();
        for x in 0..5u32 {
            let (a, b, c, d) = (2 * x, 2 * x + 1, 2 * x + 2, 2 * x + 3);
            t.push([a, c, d]);
            t.push([a, d, b]);
        }
        let mesh = Mesh::new(p, t).unwrap();
        let near = nearest_sources(mesh.topology(), mesh.positions(), &[0, 11]);
        for (v, (&n, p)) in near.iter().zip(mesh.positions()).enumerate() {
            if p[0] < 2.5 {
                assert_eq!(n, 0, "vertex {v}");
            } else if p[0] > 2.5 {
                assert_eq!(n, 1, "vertex {v}");
            }
        }
    }
}
