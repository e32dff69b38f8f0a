//! The solver's vertex order ([`Rest::with_ordering`]) is invisible at
//! the API: constraints and poses keep the mesh's order, and the solution
//! does not depend on it.

use std::sync::Arc;

use super::test_util::{creature_moved, max_dist};
use crate::deform::{Deformer, Levels, Params, Rest, VertexOrdering};
use crate::mesh::gen::{generate, Shape, ShapeSpec};
use crate::mesh::{Mesh, Point, Real};

/// `mesh` with vertex `old` renumbered `perm[old]`.
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

/// A fixed shuffle of `0..n`.
fn shuffle(n: usize) -> Vec<u32> {
    let mut v: Vec<u32> = (0..n as u32).collect();
    let mut s = 0x2545_f491_4f6c_dd1du64;
    for i in (1..n).rev() {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1);
        v.swap(i, (s >> 33) as usize % (i + 1));
    }
    v
}

/// Solves the creature's edit on its shuffled copy with `ordering` and
/// `levels`; returns (iterations, objective, pose in the shuffled order).
fn solve(mesh: &Mesh, ordering: VertexOrdering, levels: Levels) -> (usize, Real, Vec<Point>) {
    let c = creature_moved(mesh);
    let params = Params {
        tol: 1e-6,
        ..Params::default()
    };
    let rest = Arc::new(Rest::with_ordering(mesh.clone(), ordering).unwrap());
    assert_eq!(
        rest.vertex_order().is_some(),
        ordering == VertexOrdering::BreadthFirst
    );
    // the API's mesh is the mesh as given
    assert_eq!(rest.mesh().positions(), mesh.positions());
    assert_eq!(rest.mesh().triangles(), mesh.triangles());
    let mut d = Deformer::new(rest, params);
    d.set_levels(levels);
    let f = d.build_factor(&c).unwrap();
    let r = d.step(&f, &c, 1000).unwrap();
    assert!(r.converged, "{ordering:?} {levels:?}: {r:?}");
    // the constrained vertices sit exactly on their targets, in the
    // mesh's order
    for (&v, &at) in c.fixed.iter().zip(&c.fixed_at) {
        assert_eq!(d.pose()[v as usize], at);
    }
    for (v, at) in c.handles[0].target_positions() {
        assert_eq!(d.pose()[v as usize], at);
    }
    (r.iterations, r.objective, d.pose().to_vec())
}

/// Renumbering changes nothing but the order of sums. On one level: the
/// same iterations, and poses and objectives equal to rounding. On two
/// (the coarse mesh is simplified in the mesh's own order): the same
/// minimum, objectives to 1e-9 and poses to 1e-6 of the diagonal, at most
/// a few iterations apart. The coarse corrections' solves decide where to
/// stop from their iterates (converged, stalled, drifting:
/// `multilevel::CORRECTION_DRIFT`), and a solve cut while its update grows
/// hands on a state whose last bits the growing mode has amplified: at
/// this tolerance (1e-6) one correction then takes 84 coarse iterations
/// in one order and 81 in the other, and the fine counts end 53 and 52.
#[test]
fn the_solvers_vertex_order_does_not_change_the_solution() {
    let mesh = generate(&ShapeSpec::default_for(Shape::Creature)).unwrap();
    let shuffled = permuted(&mesh, &shuffle(mesh.num_vertices()));
    let diag = shuffled.diagonal();
    for levels in [Levels::One, Levels::Two] {
        let (i0, e0, p0) = solve(&shuffled, VertexOrdering::AsGiven, levels);
        let (i1, e1, p1) = solve(&shuffled, VertexOrdering::BreadthFirst, levels);
        let gap = max_dist(&p0, &p1) / diag;
        eprintln!("{levels:?}: {i0} and {i1} iterations, objectives {e0} and {e1}, poses {gap:.1e} of the diagonal apart");
        assert!((e0 - e1).abs() <= 1e-9 * e0, "{levels:?}: {e0} vs {e1}");
        if levels == Levels::One {
            assert_eq!(i0, i1, "{levels:?}: iterations");
            assert!(
                gap <= 1e-9,
                "{levels:?}: poses {gap:.1e} of the diagonal apart"
            );
        } else {
            assert!(
                i0.abs_diff(i1) <= 3,
                "{levels:?}: {i0} against {i1} iterations"
            );
            assert!(
                gap <= 1e-6,
                "{levels:?}: poses {gap:.1e} of the diagonal apart"
            );
        }
    }
}

/// The coarse level of a renumbered mesh is the coarse level of the mesh
/// as given (the same mesh, the same fine vertices), its maps in the
/// solver's order.
#[test]
fn a_renumbered_mesh_has_the_coarse_level_of_the_mesh_as_given() {
    let mesh = generate(&ShapeSpec::default_for(Shape::Creature)).unwrap();
    let shuffled = permuted(&mesh, &shuffle(mesh.num_vertices()));
    let given = Rest::with_ordering(shuffled.clone(), VertexOrdering::AsGiven).unwrap();
    let renumbered = Rest::with_ordering(shuffled, VertexOrdering::BreadthFirst).unwrap();
    let (a, b) = (given.coarse().unwrap(), renumbered.coarse().unwrap());
    assert_eq!(a.rest.mesh().positions(), b.rest.mesh().positions());
    assert_eq!(a.rest.mesh().triangles(), b.rest.mesh().triangles());
    let order = renumbered.vertex_order().unwrap();
    for (c, (&fa, &fb)) in a.fine_of.iter().zip(&b.fine_of).enumerate() {
        assert_eq!(order.internal(fa), fb, "coarse vertex {c}");
    }
    for v in 0..given.mesh().num_vertices() as u32 {
        let i = order.internal(v) as usize;
        assert_eq!(a.coarse_of[v as usize], b.coarse_of[i]);
        assert_eq!(a.near[v as usize], b.near[i], "vertex {v}");
    }
}
