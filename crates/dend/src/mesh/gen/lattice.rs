//! The pieces the generated shapes are built of: a shape as positions
//! and triangles, quads split into triangles, and the surface of a
//! lattice box.

use std::collections::HashMap;

use crate::mesh::Point;

/// A generated shape before it is checked as a [`crate::mesh::Mesh`].
pub(super) type Raw = (Vec<Point>, Vec<[u32; 3]>);

/// Splits quad `q` (counter-clockwise) into two triangles.
pub(super) fn quad(out: &mut Vec<[u32; 3]>, q: [u32; 4]) {
    out.push([q[0], q[1], q[2]]);
    out.push([q[0], q[2], q[3]]);
}

/// The surface of the lattice box `[0,n₀]×[0,n₁]×[0,n₂]`: its corners
/// numbered in order of first use, and its cells as quads of those numbers,
/// counter-clockwise seen from outside; the faces normal to each axis of
/// `axes` in that order, the low side first.
pub(super) fn lattice_box(n: [u32; 3], axes: [usize; 3]) -> (Vec<[u32; 3]>, Vec<[u32; 4]>) {
    let mut index: HashMap<[u32; 3], u32> = HashMap::new();
    let mut corners = Vec::new();
    let mut quads = Vec::new();
    let mut vid = |c: [u32; 3]| -> u32 {
        *index.entry(c).or_insert_with(|| {
            corners.push(c);
            (corners.len() - 1) as u32
        })
    };
    for axis in axes {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3); // u × v = +axis
        for high in [false, true] {
            for i in 0..n[u] {
                for j in 0..n[v] {
                    let corner = |di: u32, dj: u32| {
                        let mut c = [0u32; 3];
                        c[axis] = if high { n[axis] } else { 0 };
                        c[u] = i + di;
                        c[v] = j + dj;
                        c
                    };
                    let mut q =
                        [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)].map(&mut vid);
                    if !high {
                        q.reverse();
                    }
                    quads.push(q);
                }
            }
        }
    }
    (corners, quads)
}
