//! Tests of the generated creature and its default edit (`creature.rs`).

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
