//! The elastic formulation on shapes (design.md §7): a pulled limb, a
//! twist in steps and the characters' standard edit keep their form
//! (no spike, the twist's direction, the proportions). The exactness and
//! invariance properties are in `tests/it/elastic.rs`.

use std::sync::Arc;

use dend::deform::{Constraints, Deformer, Factor, Params, Rest, RigidTransform};
use dend::mesh::{Mesh, Point};
use dend_testkit::{max_dist, standard_edit};
use nalgebra::{UnitQuaternion, Vector3};

use super::elastic::{assert_monotone, objectives};

/// A cylinder with a thin tube on its side ("a limb"), body fixed, the
/// tip pulled up and out and turned: the stretch that clamping both ends
/// makes unavoidable is spread as ARAP's spokes spread it, not gathered
/// into a spike.
#[test]
fn a_pulled_limb_grows_no_spike() {
    // body: a 24-gon cylinder of radius 1, z in [0, 4]; limb: a 8-gon tube
    // of radius 0.2 along +x from the body's side at z = 2, length 3
    let mut p: Vec<Point> = Vec::new();
    let mut t: Vec<[u32; 3]> = Vec::new();
    let ring = |p: &mut Vec<Point>, n: usize, f: &dyn Fn(f64) -> Point| -> u32 {
        let start = p.len() as u32;
        for k in 0..n {
            p.push(f(2.0 * std::f64::consts::PI * k as f64 / n as f64));
        }
        start
    };
    let strip = |t: &mut Vec<[u32; 3]>, a: u32, b: u32, n: u32| {
        for k in 0..n {
            let (a0, a1, b0, b1) = (a + k, a + (k + 1) % n, b + k, b + (k + 1) % n);
            t.push([a0, a1, b1]);
            t.push([a0, b1, b0]);
        }
    };
    let mut prev = None;
    for r in 0..=16 {
        let z = 4.0 * r as f64 / 16.0;
        let s = ring(&mut p, 24, &|a| [a.cos(), a.sin(), z]);
        if let Some(q) = prev {
            strip(&mut t, q, s, 24);
        }
        prev = Some(s);
    }
    // the limb: its own surface (a second component) whose root ring sits
    // on the body's side and is fixed with the body, as a limb is held by
    // the body it grows from
    let mut prev = None;
    for r in 0..=20 {
        let x = 1.0 + 3.0 * r as f64 / 20.0;
        let s = ring(&mut p, 8, &|a| [x, 0.2 * a.cos(), 2.0 + 0.2 * a.sin()]);
        if let Some(q) = prev {
            strip(&mut t, q, s, 8);
        }
        prev = Some(s);
    }
    let mesh = Mesh::new(p, t).unwrap();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let pos = mesh.positions();
    let fixed: Vec<u32> = (0..pos.len() as u32)
        .filter(|&v| {
            let q = pos[v as usize];
            q[0] < 1.05 // the body and the limb's root ring
        })
        .collect();
    let tip: Vec<u32> = (0..pos.len() as u32)
        .filter(|&v| pos[v as usize][0] > 3.9)
        .collect();
    let mut c = Constraints::new(&mesh, fixed, vec![("tip".into(), tip, None)]).unwrap();
    // the tip swung 60° sideways about the limb's root: reachable by a
    // bend without any stretch
    c.handles[0].target = RigidTransform {
        rotation: UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 30f64.to_radians()),
        translation: [0.5, 0.0, 1.2],
        pivot: [4.0, 0.0, 2.0],
    };
    // edge stretch |l'/l − 1|: (mean, max)
    let stretch = |params: Params| {
        let (obj, converged, pose) = objectives(&rest, params, &c, 300);
        assert!(converged, "{params:?}");
        assert_monotone(&obj);
        let (mut sum, mut worst, edges) = (0.0, 0.0f64, mesh.topology().edges());
        for e in edges {
            let (a, b) = (e[0] as usize, e[1] as usize);
            let s = (max_dist(&[pose[a]], &[pose[b]]) / max_dist(&[pos[a]], &[pos[b]]) - 1.0).abs();
            sum += s;
            worst = worst.max(s);
        }
        (sum / edges.len() as f64, worst)
    };
    let (mean, worst) = stretch(Params::default());
    // ARAP's spokes alone (no bending, no area term): the stretch
    // resistance the default must keep
    let (arap_mean, arap_worst) = stretch(Params::default().with_elastic(|e| {
        e.bending = 0.0;
        e.area = 0.0;
    }));
    let (el_mean, el_worst) = stretch(Params::elastica());
    eprintln!("limb stretch mean/max: default {mean:.3}/{worst:.3}, elastica {el_mean:.3}/{el_worst:.3}, spokes only {arap_mean:.3}/{arap_worst:.3}");
    assert!(
        worst <= arap_worst,
        "a spike: largest stretch {worst} > {arap_worst}"
    );
    assert!(
        mean <= 1.5 * arap_mean,
        "mean stretch {mean} > 1.5 × {arap_mean}"
    );
    // the elastica preset (softer spokes, the whole Laplacian part) is
    // held to the same: no spike, stretch near the spokes'
    assert!(
        el_worst <= arap_worst,
        "elastica: a spike: largest stretch {el_worst} > {arap_worst}"
    );
    assert!(
        el_mean <= 1.5 * arap_mean,
        "elastica: mean stretch {el_mean} > 1.5 × {arap_mean}"
    );
}

/// A bar twisted 300° about its axis in five steps of 60° (the paper's
/// interactive large edit): each step starts from the last pose turned by
/// the handle's change of rotation, so the twist keeps its direction (the
/// slab twist follows the 0 → 300° ramp within 15°, where starting each
/// step from the old rotations untwisted it by 137°), the cross-sections
/// keep 80 % of their area, and every step converges in 20 iterations
/// (40–57 before), with the `elastica` preset (docs/posing.md: the default
/// keeps 0.60). The objective never grows within a step.
#[test]
fn a_twist_in_steps_keeps_its_direction() {
    use dend::mesh::gen::{generate, Shape, ShapeSpec};
    let mesh = generate(&ShapeSpec::default_for(Shape::Bar)).unwrap();
    let p = mesh.positions();
    let (zmin, zmax) = p
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), q| (a.min(q[2]), b.max(q[2])));
    let h = zmax - zmin;
    let fixed: Vec<u32> = (0..p.len() as u32)
        .filter(|&v| p[v as usize][2] < zmin + 0.08 * h)
        .collect();
    let handle: Vec<u32> = (0..p.len() as u32)
        .filter(|&v| p[v as usize][2] > zmax - 0.08 * h)
        .collect();
    let z0 = fixed
        .iter()
        .map(|&v| p[v as usize][2])
        .fold(f64::MIN, f64::max);
    let z1 = handle
        .iter()
        .map(|&v| p[v as usize][2])
        .fold(f64::MAX, f64::min);
    let mut c = Constraints::new(&mesh, fixed, vec![("top".into(), handle, None)]).unwrap();
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let params = Params::elastica();
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest.clone(), params);
    let pivot = c.handles[0].rest_centroid;
    for step in 1..=5 {
        c.handles[0].target = RigidTransform {
            rotation: UnitQuaternion::from_axis_angle(
                &Vector3::z_axis(),
                (60.0 * step as f64).to_radians(),
            ),
            translation: [0.0; 3],
            pivot,
        };
        let mut obj = Vec::new();
        let mut its = 0;
        loop {
            let r = d.step(&f, &c, 1).unwrap();
            if obj.is_empty() {
                obj.push(r.initial_objective);
            }
            obj.push(r.objective);
            its += r.iterations;
            if r.converged || its >= 100 {
                break;
            }
        }
        assert_monotone(&obj);
        assert!(its <= 20, "step {step}: {its} iterations");
    }
    let fig = dend::measure::bar_slabs(p, d.pose(), z0, z1, 20);
    let dev = fig.twist_deviation(z0, z1, 300.0);
    assert!(dev <= 15.0, "twist deviation {dev}° ({:?})", fig.twist_deg);
    assert!(fig.min_area() >= 0.8, "min area {}", fig.min_area());
}

/// The benches' standard edit on the shared character meshes (lowest
/// 10 % in z fixed, highest 10 % moved 0.15 × diagonal along x and turned
/// 30° about y): edge distortion within 1.5× (mean) and 2× (max) of libigl
/// ARAP run to convergence on the same sets (ARAP's figures measured by
/// scripts/posing_suite.py: camel 0.00307 / 0.0937, dino 0.00281 / 0.0374).
/// The least-squares default before this one stretched the camel's neck
/// 42× (design.md §7.1). Needs `../shared/meshes`: skipped (and listed by
/// `scripts/test.sh`) without it.
#[test]
fn characters_keep_their_proportions_under_the_standard_edit() {
    let Some(dir) = dend_testkit::shared_meshes() else {
        return;
    };
    for (file, arap_mean, arap_max) in [
        ("camel_9770.off", 0.00307, 0.0937),
        ("dino_6013.obj", 0.00281, 0.0374),
    ] {
        let mesh = dend::mesh::io::read_path(&dir.join(file)).unwrap();
        let pos = mesh.positions();
        let c = standard_edit(&mesh);
        let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
        let (obj, converged, pose) = objectives(&rest, Params::default(), &c, 200);
        assert!(converged, "{file}");
        assert_monotone(&obj);
        let edges = mesh.topology().edges();
        let (mut sum, mut worst) = (0.0, 0.0f64);
        for e in edges {
            let (a, b) = (e[0] as usize, e[1] as usize);
            let s = (max_dist(&[pose[a]], &[pose[b]]) / max_dist(&[pos[a]], &[pos[b]]) - 1.0).abs();
            sum += s;
            worst = worst.max(s);
        }
        let mean = sum / edges.len() as f64;
        eprintln!(
            "{file}: distortion {mean:.5} / {worst:.4}, {} iterations",
            obj.len() - 1
        );
        assert!(mean <= 1.5 * arap_mean, "{file}: mean distortion {mean}");
        assert!(worst <= 2.0 * arap_max, "{file}: max distortion {worst}");
    }
}
