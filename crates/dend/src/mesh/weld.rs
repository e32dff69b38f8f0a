//! Welding an asset's vertex layout into the surface the solver deforms.
//!
//! Game assets split a vertex where its UV, normal or colour differs on two
//! sides of a seam: the copies have the same position but separate indices,
//! so the file's triangles are cut along every seam. The solver needs the
//! connected surface, so copies are merged ("welded") by this rule:
//!
//! **Two asset vertices are one welded vertex when they have bit-identical
//! positions (with `-0.0 = 0.0`) and lie on a common geometric edge**: an
//! edge of one triangle whose two endpoint positions are bit-identical to
//! those of an edge of another triangle. Such edges are matched endpoint to
//! endpoint by position and their endpoints merged; merging is transitive
//! (union–find). Coincident vertices that share no edge, such as two parts
//! touching at a single point, stay apart, so welding never creates a
//! non-manifold vertex there. Near-equal positions are never merged.
//!
//! Welded vertices are numbered in order of their first asset vertex, and
//! take its position; welded triangles are the asset triangles renumbered
//! (same count, same order).

use std::collections::HashMap;

use crate::mesh::Point;

/// The asset → welded vertex map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Weld {
    /// Welded vertex of each asset vertex, `#A`.
    pub to_welded: Vec<u32>,
    /// Number of welded vertices.
    pub welded: usize,
}

fn key(p: Point) -> [u64; 3] {
    // -0.0 + 0.0 = 0.0: one key for both zeros
    p.map(|x| (x + 0.0).to_bits())
}

fn find(parent: &mut [u32], mut v: u32) -> u32 {
    while parent[v as usize] != v {
        let p = parent[v as usize];
        parent[v as usize] = parent[p as usize];
        v = p;
    }
    v
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    // the smaller index becomes the root: classes are named by their first vertex
    if ra < rb {
        parent[rb as usize] = ra;
    } else {
        parent[ra as usize] = rb;
    }
}

/// Welds `positions` (asset layout) along the geometric edges of `triangles`.
/// Indices past `positions` are ignored (validation reports them later).
pub fn weld(positions: &[Point], triangles: &[[u32; 3]]) -> Weld {
    let n = positions.len();
    let mut parent: Vec<u32> = (0..n as u32).collect();
    let mut first_edge: HashMap<([u64; 3], [u64; 3]), (u32, u32)> = HashMap::new();
    for t in triangles {
        if t.iter().any(|&i| i as usize >= n) {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let (ka, kb) = (key(positions[a as usize]), key(positions[b as usize]));
            if ka == kb {
                continue;
            }
            // orient the edge by its keys, so both sides of a seam agree
            let (lo, hi, klo, khi) = if ka < kb {
                (a, b, ka, kb)
            } else {
                (b, a, kb, ka)
            };
            match first_edge.entry((klo, khi)) {
                std::collections::hash_map::Entry::Occupied(e) => {
                    let (l0, h0) = *e.get();
                    union(&mut parent, lo, l0);
                    union(&mut parent, hi, h0);
                }
                std::collections::hash_map::Entry::Vacant(e) => {
                    e.insert((lo, hi));
                }
            }
        }
    }
    let mut id = vec![u32::MAX; n];
    let mut to_welded = Vec::with_capacity(n);
    let mut welded = 0u32;
    for v in 0..n as u32 {
        let r = find(&mut parent, v) as usize;
        if id[r] == u32::MAX {
            id[r] = welded;
            welded += 1;
        }
        to_welded.push(id[r]);
    }
    Weld {
        to_welded,
        welded: welded as usize,
    }
}

impl Weld {
    /// Welded positions: each welded vertex at its first asset vertex.
    pub fn positions(&self, asset: &[Point]) -> Vec<Point> {
        let mut out = vec![[0.0; 3]; self.welded];
        let mut seen = vec![false; self.welded];
        for (a, &w) in self.to_welded.iter().enumerate() {
            if !std::mem::replace(&mut seen[w as usize], true) {
                out[w as usize] = asset[a];
            }
        }
        out
    }

    /// Asset triangles renumbered to welded vertices (indices past the asset
    /// are kept as they are, for validation to report).
    pub fn triangles(&self, asset: &[[u32; 3]]) -> Vec<[u32; 3]> {
        asset
            .iter()
            .map(|t| t.map(|i| self.to_welded.get(i as usize).copied().unwrap_or(i)))
            .collect()
    }

    /// A welded pose spread onto the asset layout: asset vertex `a` takes
    /// `pose[to_welded[a]]`.
    pub fn spread(&self, pose: &[Point]) -> Vec<Point> {
        self.to_welded.iter().map(|&w| pose[w as usize]).collect()
    }
}

/// Leaves degenerate triangles (a repeated vertex, or zero area as
/// [`Mesh::new`] judges it) out of a welded surface: exported game assets
/// often hold some. Triangles with an index out of range stay, for
/// [`Mesh::new`] to report.
pub(crate) fn drop_degenerate(welded: &[Point], tris: &mut Vec<[u32; 3]>) {
    tris.retain(|t| {
        t.iter().any(|&i| i as usize >= welded.len())
            || !(t[0] == t[1]
                || t[1] == t[2]
                || t[0] == t[2]
                || crate::mesh::is_zero_area(welded, t))
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles forming a unit square, split along the diagonal seam
    /// (vertices 2, 3 duplicated as 4, 5).
    fn split_square() -> (Vec<Point>, Vec<[u32; 3]>) {
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [-0.0, 1.0, 0.0],
        ];
        (p, vec![[0, 1, 2], [0, 4, 5]])
    }

    #[test]
    fn seam_copies_are_merged_and_numbered_by_first_appearance() {
        let (p, t) = split_square();
        let w = weld(&p, &t);
        // vertex 0 is shared; 4 ~ 2 on the diagonal edge 0–2/0–4; 5 is not on
        // a shared edge with 3 (edge 0–5 vs 0–3: 3 is in no triangle)
        assert_eq!(w.to_welded, vec![0, 1, 2, 3, 2, 4]);
        assert_eq!(w.welded, 5);
        assert_eq!(w.triangles(&t), vec![[0, 1, 2], [0, 2, 4]]);
    }

    #[test]
    fn touching_at_a_point_is_not_welded() {
        // two triangles sharing only the position of one corner
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
        ];
        let w = weld(&p, &[[0, 1, 2], [3, 4, 5]]);
        assert_eq!(w.welded, 6);
    }

    #[test]
    fn near_equal_positions_are_not_welded() {
        let (mut p, t) = split_square();
        p[4][0] = 1.0 + f64::EPSILON;
        assert_eq!(weld(&p, &t).to_welded[4], 4);
    }

    #[test]
    fn spread_then_weld_positions_round_trip() {
        let (p, t) = split_square();
        let w = weld(&p, &t);
        let wp = w.positions(&p);
        let back = w.spread(&wp);
        for (a, b) in back.iter().zip(&p) {
            assert_eq!(key(*a), key(*b));
        }
    }
}
