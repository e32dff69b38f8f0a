//! The coarse mesh of the two-level start: a simplification whose vertices
//! are a subset of the fine mesh's ([`coarse_mesh`]).

use meshopt::SimplifyOptions;

use crate::mesh::{Mesh, Point, Real};

/// A coarse mesh with about `#V / ratio` vertices whose vertices are fine
/// vertices: `fine_of[c]` is the fine index of coarse vertex `c`, strictly
/// increasing. `None` when the simplification fails or its result is not a
/// valid [`Mesh`] (non-manifold, zero area, …).
///
/// Edge collapses with quadric error (Garland & Heckbert 1997) by
/// meshoptimizer's `meshopt_simplify`, which collapses a vertex onto a
/// neighbour without moving it and returns an index buffer into the
/// original vertices; `Regularize` trades a little geometric error for
/// rounder triangles (the coarse energy is a finite-element energy).
/// Topology is kept: only collapses that keep the mesh manifold are taken
/// (meshoptimizer classifies vertices as manifold/border/seam/locked), and
/// the result is validated again by [`Mesh::new`]. Where two sheets come
/// close (a camel's ear) a collapse can still make an edge of 4 triangles;
/// the regularised simplification is then retried without `Regularize`
/// (measured: camel_9770 non-manifold with it, valid without; dino_6013,
/// eth_hand_14k valid with both).
///
/// meshoptimizer sees `normalised`, the mesh's positions centred and in
/// mean edge lengths (the rest operators' copy), as f32: the collapses
/// then do not depend on the mesh's unit of length or placement. Given
/// the raw coordinates, their f32 rounding (and meshoptimizer's own float
/// arithmetic) changed with the unit: a 1600-vertex patch scaled by 37
/// got another coarse mesh, and its solve another path (issue #33).
pub fn coarse_mesh(mesh: &Mesh, normalised: &[Point], ratio: usize) -> Option<(Mesh, Vec<u32>)> {
    [SimplifyOptions::Regularize, SimplifyOptions::None]
        .into_iter()
        .find_map(|options| simplify_with(mesh, normalised, ratio, options))
}

/// One attempt of [`coarse_mesh`] with meshoptimizer's `options`.
fn simplify_with(
    mesh: &Mesh,
    normalised: &[Point],
    ratio: usize,
    options: SimplifyOptions,
) -> Option<(Mesh, Vec<u32>)> {
    let fine = mesh.positions();
    let positions: Vec<[f32; 3]> = normalised
        .iter()
        .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
        .collect();
    let indices: Vec<u32> = mesh.triangles().iter().flatten().copied().collect();
    let target = 3 * (mesh.num_triangles() / ratio.max(1)).max(1);
    // error bound 1 (relative to the mesh extent): stop at the target count
    let simplified = meshopt::simplify_decoder(&indices, &positions, target, 1.0, options, None);
    if simplified.is_empty() || simplified.len() % 3 != 0 {
        return None;
    }
    let mut coarse_of = vec![u32::MAX; fine.len()];
    for &v in &simplified {
        coarse_of[v as usize] = 0;
    }
    let mut fine_of = Vec::new();
    for (v, c) in coarse_of.iter_mut().enumerate() {
        if *c == 0 {
            *c = fine_of.len() as u32;
            fine_of.push(v as u32);
        }
    }
    let triangles: Vec<[u32; 3]> = simplified
        .chunks_exact(3)
        .map(|t| {
            [
                coarse_of[t[0] as usize],
                coarse_of[t[1] as usize],
                coarse_of[t[2] as usize],
            ]
        })
        .collect();
    let positions = fine_of.iter().map(|&v| fine[v as usize]).collect();
    let coarse = Mesh::new(positions, triangles).ok()?;
    // every triangle of a usable energy has a non-negligible area
    let h = coarse.mean_edge_length();
    let tiny = 1e-8 * h * h;
    let degenerate = coarse.triangles().iter().any(|t| {
        let p = |k: usize| coarse.positions()[t[k] as usize];
        let (a, b, c) = (p(0), p(1), p(2));
        let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = crate::mesh::cross(e1, e2);
        0.5 * crate::mesh::norm(n) < tiny as Real
    });
    if degenerate {
        return None;
    }
    Some((coarse, fine_of))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::gen;

    #[test]
    fn coarse_vertices_are_fine_vertices() {
        let spec = gen::ShapeSpec {
            shape: gen::Shape::Torus,
            params: gen::ShapeParams {
                nu: Some(80),
                nv: Some(50),
                ..Default::default()
            },
        };
        let mesh = gen::generate(&spec).expect("torus");
        let ops = crate::operators::Operators::new(&mesh);
        let (coarse, fine_of) = coarse_mesh(&mesh, &ops.positions, 8).expect("simplifies");
        let n = mesh.num_vertices();
        let nc = coarse.num_vertices();
        assert!(nc * 5 < n && nc * 16 > n, "{nc} of {n}");
        assert!(fine_of.windows(2).all(|w| w[0] < w[1]));
        for (c, &v) in fine_of.iter().enumerate() {
            assert_eq!(coarse.positions()[c], mesh.positions()[v as usize]);
        }
        // the surface keeps its topology (a torus: χ = 0)
        assert_eq!(coarse.euler_characteristic(), 0);
    }
}
