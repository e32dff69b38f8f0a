//! The factor cache and the solver's typed errors: targets never
//! refactor, one build per constraint set, degenerate input gives finite
//! poses or typed errors.

use std::sync::Arc;

use dend::deform::*;
use dend::mesh::Mesh;
use dend_testkit::*;
use nalgebra::{UnitQuaternion, Vector3};

#[test]
fn changing_only_targets_never_refactors() {
    let m = square_tube(1.0, 5.0, 4, 16);
    let rest = Arc::new(Rest::new(m.clone()).unwrap());
    let cache = FactorCache::new(1 << 30);
    let spec = tube_spec(&m, handle(None, None));
    let mut c = spec.resolve(&m).unwrap();
    let params = ls();
    let mut d = Deformer::new(rest.clone(), params);
    for k in 0..10 {
        c.handles[0].target = c.handles[0].target.then(
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.1),
            [0.05 * k as f64, 0.0, 0.0],
        );
        let f = cache.get_or_build(&rest, &params, &c).unwrap();
        let rep = d.step(&f, &c, 5).unwrap();
        assert!(rep.iterations >= 1);
    }
    assert_eq!(cache.builds(), 1);
    assert_eq!(cache.hits(), 9);
    // a different constrained set does build a new factor
    let mut c2 = c.clone();
    c2.fixed.pop();
    cache.get_or_build(&rest, &params, &c2).unwrap();
    assert_eq!(cache.builds(), 2);
    // a factor built for another set is refused
    let f = cache.get_or_build(&rest, &params, &c2).unwrap();
    assert_eq!(d.step(&f, &c, 1), Err(DeformError::FactorMismatch));
}

#[test]
fn a_cache_builds_its_factors_with_its_options() {
    use dend::deform::{FactorPrecision, SolveOptions};
    let m = square_tube(1.0, 5.0, 40, 40);
    let rest = Arc::new(Rest::new(m.clone()).unwrap());
    let c = tube_spec(&m, handle(None, None)).resolve(&m).unwrap();
    let params = ls();
    let single = FactorCache::with_options(
        1 << 30,
        SolveOptions {
            precision: FactorPrecision::Single,
            ..SolveOptions::default()
        },
    );
    let (fd, fs) = (
        FactorCache::new(1 << 30)
            .get_or_build(&rest, &params, &c)
            .unwrap(),
        single.get_or_build(&rest, &params, &c).unwrap(),
    );
    assert_eq!(fd.factor_nnz(), fs.factor_nnz());
    // f32 values: 4 bytes less per nonzero
    assert_eq!(fd.factor_bytes() - fs.factor_bytes(), 4 * fd.factor_nnz());
    let mut d = Deformer::new(rest, params);
    assert!(d.step(&fs, &c, 50).unwrap().iterations >= 1);
}

/// Sessions opened together on one mesh and constraint set share one build:
/// concurrent requests wait for the first factorisation.
#[test]
fn concurrent_requests_for_one_set_build_one_factor() {
    let m = square_tube(1.0, 5.0, 6, 30);
    let rest = Arc::new(Rest::new(m.clone()).unwrap());
    let cache = Arc::new(FactorCache::new(1 << 30));
    let c = tube_spec(&m, handle(None, None)).resolve(&m).unwrap();
    let params = ls();
    let ids: Vec<u64> = std::thread::scope(|scope| {
        let hs: Vec<_> = (0..6)
            .map(|_| scope.spawn(|| cache.get_or_build(&rest, &params, &c).unwrap().id()))
            .collect();
        hs.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(cache.builds(), 1, "{ids:?}");
    assert_eq!(cache.hits(), 5);
    assert!(ids.iter().all(|&i| i == ids[0]), "{ids:?}");
}

#[test]
fn near_degenerate_triangles_give_finite_poses() {
    // a sliver: one vertex pushed almost onto the opposite edge
    let mut m = irregular_saddle(8, 7);
    let mut p = m.positions().to_vec();
    p[27] = [
        0.5 * (p[26][0] + p[28][0]),
        0.5 * (p[26][1] + p[28][1]) + 1e-7,
        0.5 * (p[26][2] + p[28][2]),
    ];
    m = m.with_positions(p).unwrap();
    let spec = ConstraintsSpec {
        fixed_positions: None,
        fixed: VertexSet::Indices((0..8).collect()),
        handles: vec![HandleSpec {
            vertices: VertexSet::Indices((56..64).collect()),
            ..handle(Some([0.0, 1.0, 2.0]), None)
        }],
    };
    for params in [
        ls(),
        Params::paper(),
        Params {
            energy: Energy::ThinPlate,
            ..ls()
        },
    ] {
        let (pose, rep) = solve(&m, params, &spec, 30);
        assert!(
            pose.iter().flatten().all(|v| v.is_finite()),
            "{params:?}: {rep:?}"
        );
    }
}

#[test]
fn bad_constraint_sets_are_typed_errors() {
    let m = irregular_saddle(6, 1);
    let r = |j: &str| {
        serde_json::from_str::<ConstraintsSpec>(j)
            .unwrap()
            .resolve(&m)
    };
    assert!(matches!(
        r(r#"{"fixed": [0, 99]}"#),
        Err(DeformError::UnknownVertex { index: 99, .. })
    ));
    assert!(matches!(
        r(r#"{"fixed": [0, 1], "handles": [{"vertices": [1, 2]}]}"#),
        Err(DeformError::OverlappingSets { vertex: 1, .. })
    ));
    assert!(matches!(
        r(
            r#"{"fixed": [0], "handles": [{"name": "h", "vertices": {"box": {"min": [90,90,90], "max": [91,91,91]}}}]}"#
        ),
        Err(DeformError::EmptyHandle { .. })
    ));
    assert!(matches!(
        r(r#"{"fixed": []}"#),
        Err(DeformError::NoConstraints)
    ));
    assert!(matches!(
        r(
            r#"{"fixed": [0], "handles": [{"vertices": [3], "rotate": {"axis": [0,0,0], "degrees": 5}}]}"#
        ),
        Err(DeformError::InvalidTransform { .. })
    ));
    let bad = Params {
        lambda2: f64::NAN,
        ..ls()
    };
    assert!(matches!(
        bad.validate(),
        Err(DeformError::InvalidParam {
            name: "lambda2",
            ..
        })
    ));
    // a second component without constraints is rank-deficient
    let mut p = m.positions().to_vec();
    let mut t = m.triangles().to_vec();
    let base = p.len() as u32;
    p.extend([[50.0, 0.0, 0.0], [51.0, 0.0, 0.0], [50.0, 1.0, 0.0]]);
    t.push([base, base + 1, base + 2]);
    let m2 = Mesh::new(p, t).unwrap();
    let rest = Rest::new(m2.clone()).unwrap();
    let c = Constraints::new(&m2, vec![0, 1], vec![]).unwrap();
    assert!(matches!(
        Factor::build(&rest, &ls(), &c),
        Err(DeformError::Unconstrained { component: 1, .. })
    ));
}
