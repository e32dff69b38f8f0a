//! Properties of the DEND solver (design.md §10) on generated meshes.

use std::sync::Arc;

use dend::deform::*;

use dend_testkit::*;
use nalgebra::{UnitQuaternion, Vector3};

#[test]
fn identity_edit_keeps_the_rest_pose_on_irregular_meshes() {
    for seed in 0..3 {
        let m = irregular_saddle(12, seed);
        let spec = ConstraintsSpec {
            fixed_positions: None,
            fixed: VertexSet::Indices((0..12).collect()),
            handles: vec![HandleSpec {
                vertices: VertexSet::Indices((132..144).collect()),
                ..handle(None, None)
            }],
        };
        for energy in [Energy::TotalCurvature, Energy::ThinPlate, Energy::Membrane] {
            let params = Params { energy, ..ls() };
            let (pose, rep) = solve(&m, params, &spec, 20);
            let err = max_dist(&pose, m.positions()) / m.diagonal();
            assert!(
                err < 1e-8,
                "seed {seed} {energy:?}: identity error {err:e} ({rep:?})"
            );
        }
    }
}

#[test]
fn translating_every_constraint_translates_the_mesh() {
    let m = square_tube(1.0, 6.0, 5, 25);
    let t = [0.7, -1.3, 2.1];
    let mut spec = tube_spec(&m, handle(Some(t), None));
    // move the fixed set as a second handle with the same translation
    let fixed = std::mem::replace(&mut spec.fixed, VertexSet::Indices(vec![]));
    spec.handles.push(HandleSpec {
        name: Some("bottom".into()),
        vertices: fixed,
        ..handle(Some(t), None)
    });
    for energy in [
        Energy::TotalCurvature,
        Energy::ThinPlate,
        Energy::Membrane,
        Energy::Combined { ks: 1.0, kb: 1.0 },
    ] {
        for detail in [DetailTerm::Linear, DetailTerm::Nonlinear] {
            let params = Params {
                energy,
                detail,
                tol: 1e-12,
                ..ls()
            };
            let (pose, _) = solve(&m, params, &spec, 500);
            let want: Vec<[f64; 3]> = m
                .positions()
                .iter()
                .map(|p| [p[0] + t[0], p[1] + t[1], p[2] + t[2]])
                .collect();
            let err = max_dist(&pose, &want) / m.diagonal();
            assert!(
                err < 1e-8,
                "{energy:?} {detail:?}: translation error {err:e}"
            );
        }
    }
    // the literal paper's L² - 2LG is not translation invariant (design.md §3)
    let params = Params {
        energy: Energy::TotalCurvaturePaper,
        detail: DetailTerm::Linear,
        formulation: FormulationParams::LeastSquares(PaperParams { mode: Mode::Paper }),
        ..ls()
    };
    let (pose, _) = solve(&m, params, &spec, 5);
    let want: Vec<[f64; 3]> = m
        .positions()
        .iter()
        .map(|p| [p[0] + t[0], p[1] + t[1], p[2] + t[2]])
        .collect();
    let err = max_dist(&pose, &want) / m.diagonal();
    assert!(
        err > 1e-6,
        "L² - 2LG unexpectedly translation invariant: {err:e}"
    );
}

/// design.md §10–11 on a 1×1×6 open tube twisted 135°: the default mode keeps
/// the cross-sections and twists evenly; the literal paper barely twists
/// the middle; thin plate with the linear term collapses (paper Fig. 1c).
#[test]
fn twisted_tube_default_keeps_sections_paper_and_linear_fail() {
    let m = square_tube(1.0, 6.0, 5, 25);
    let spec = tube_spec(
        &m,
        handle(
            None,
            Some(RotationSpec::AxisAngle {
                axis: [0.0, 0.0, 1.0],
                degrees: 135.0,
            }),
        ),
    );
    let c = spec.resolve(&m).unwrap();
    let zf = c
        .fixed
        .iter()
        .map(|&v| m.positions()[v as usize][2])
        .fold(f64::MIN, f64::max);
    let zh = c.handles[0]
        .vertices
        .iter()
        .map(|&v| m.positions()[v as usize][2])
        .fold(f64::MAX, f64::min);
    let run = |params: Params| {
        let (pose, rep) = solve(&m, params, &spec, 200);
        let f = dend::measure::bar_slabs(m.positions(), &pose, zf, zh, 8);
        let (area, dev) = (f.min_area(), f.twist_deviation(zf, zh, 135.0));
        eprintln!(
            "{:?}/{:?}/{:?}: {} iterations, min area {area:.3}, twist dev {dev:.2}",
            params.energy,
            params.mode(),
            params.detail,
            rep.iterations
        );
        (area, dev, rep)
    };
    let (area, dev, rep) = run(ls());
    assert!(
        rep.converged && area >= 0.85 && dev <= 8.0,
        "default: {area} {dev} {rep:?}"
    );
    let (area, dev, _) = run(Params {
        energy: Energy::Membrane,
        ..ls()
    });
    assert!(area >= 0.85 && dev <= 8.0, "membrane: {area} {dev}");
    let (_, dev, _) = run(Params::paper());
    assert!(
        dev > 45.0,
        "the literal paper should fail to twist evenly: {dev}"
    );
    let (area, _, _) = run(Params {
        energy: Energy::ThinPlate,
        detail: DetailTerm::Linear,
        ..ls()
    });
    assert!(area < 0.6, "thin plate + linear should collapse: {area}");
}

fn rotate_about(p: [f64; 3], q: &UnitQuaternion<f64>, c: [f64; 3], t: [f64; 3]) -> [f64; 3] {
    let v = q * Vector3::new(p[0] - c[0], p[1] - c[1], p[2] - c[2]);
    [c[0] + v.x + t[0], c[1] + v.y + t[1], c[2] + v.z + t[2]]
}

/// Rotating every constraint by one R: the nonlinear detail term brings the
/// result much closer to the rigidly rotated mesh than the linear one
/// (design.md §10), and in the paper mode closer as λ2 grows.
#[test]
fn rigid_rotation_of_all_constraints() {
    let m = square_tube(1.0, 4.0, 4, 17);
    let axis = [0.3, 1.0, 0.2];
    let deg = 40.0;
    let pivot = [0.0, 0.0, 2.0];
    let t = [0.5, 0.0, -0.2];
    let mut spec = tube_spec(
        &m,
        HandleSpec {
            pivot: Some(pivot),
            ..handle(
                Some(t),
                Some(RotationSpec::AxisAngle { axis, degrees: deg }),
            )
        },
    );
    let fixed = std::mem::replace(&mut spec.fixed, VertexSet::Indices(vec![]));
    spec.handles.push(HandleSpec {
        name: Some("bottom".into()),
        vertices: fixed,
        pivot: Some(pivot),
        ..handle(
            Some(t),
            Some(RotationSpec::AxisAngle { axis, degrees: deg }),
        )
    });
    let q = UnitQuaternion::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::from(axis)),
        deg.to_radians(),
    );
    let want: Vec<[f64; 3]> = m
        .positions()
        .iter()
        .map(|&p| rotate_about(p, &q, pivot, t))
        .collect();
    let err = |params: Params| {
        let (pose, _) = solve(&m, params, &spec, 300);
        max_dist(&pose, &want) / m.diagonal()
    };
    let linear = err(Params {
        detail: DetailTerm::Linear,
        ..ls()
    });
    let nonlinear = err(Params { tol: 1e-8, ..ls() });
    eprintln!("rigid rotation error / diagonal: linear {linear:.3e}, nonlinear {nonlinear:.3e}");
    assert!(
        linear > 1e-3,
        "the linear term should resist rotation: {linear:e}"
    );
    assert!(
        nonlinear < 1e-6,
        "default mode should reproduce a rigid motion: {nonlinear:e}"
    );
    // paper mode: the unrotated internal term fights the rotation; λ2 helps
    let errs: Vec<f64> = [1.0, 10.0, 100.0]
        .iter()
        .map(|&lambda2| {
            err(Params {
                lambda2,
                ..Params::paper()
            })
        })
        .collect();
    eprintln!("paper mode error vs lambda2 = 1, 10, 100: {errs:?}");
    assert!(errs[0] > errs[1] && errs[1] > errs[2], "{errs:?}");
    let paper_linear = err(Params {
        lambda2: 100.0,
        detail: DetailTerm::Linear,
        ..Params::paper()
    });
    eprintln!("paper mode, lambda2 = 100, linear term: {paper_linear:.3e}");
    assert!(errs[2] < paper_linear, "{} !< {paper_linear}", errs[2]);
}

#[test]
fn scaling_mesh_and_targets_scales_the_result() {
    let m = square_tube(1.0, 6.0, 4, 19);
    let spec = tube_spec(
        &m,
        handle(
            Some([0.5, 0.2, 0.3]),
            Some(RotationSpec::AxisAngle {
                axis: [0.0, 0.0, 1.0],
                degrees: 60.0,
            }),
        ),
    );
    let params = ls();
    let (pose, _) = solve(&m, params, &spec, 40);
    for s in [1e-3, 1e4] {
        let ms = m
            .with_positions(
                m.positions()
                    .iter()
                    .map(|p| [p[0] * s, p[1] * s, p[2] * s])
                    .collect(),
            )
            .unwrap();
        let c = spec.resolve(&m).unwrap();
        let mut c_s = ConstraintsSpec {
            fixed_positions: None,
            fixed: VertexSet::Indices(c.fixed.iter().map(|&v| v as u64).collect()),
            handles: vec![HandleSpec {
                vertices: VertexSet::Indices(
                    c.handles[0].vertices.iter().map(|&v| v as u64).collect(),
                ),
                ..handle(
                    Some([0.5 * s, 0.2 * s, 0.3 * s]),
                    Some(RotationSpec::AxisAngle {
                        axis: [0.0, 0.0, 1.0],
                        degrees: 60.0,
                    }),
                )
            }],
        };
        c_s.handles[0].name = Some("top".into());
        let (pose_s, _) = solve(&ms, params, &c_s, 40);
        let back: Vec<[f64; 3]> = pose_s
            .iter()
            .map(|p| [p[0] / s, p[1] / s, p[2] / s])
            .collect();
        let err = max_dist(&back, &pose) / m.diagonal();
        assert!(err < 1e-9, "scale {s}: {err:e}");
    }
}

#[test]
fn hard_constraints_are_met_exactly_and_soft_ones_approach_them() {
    // off the origin by amounts whose normalisation does not round-trip
    // bit for bit (the fixed vertices came back 2.2e-16 off before the pose
    // took hard targets as given)
    let t = square_tube(1.0, 5.0, 4, 16);
    let shifted = t
        .positions()
        .iter()
        .map(|p| [p[0] + 0.1, p[1] + 1.0 / 3.0, p[2] - 0.7])
        .collect();
    let m = t.with_positions(shifted).unwrap();
    let spec = tube_spec(
        &m,
        handle(
            Some([1.0, 0.0, 0.5]),
            Some(RotationSpec::AxisAngle {
                axis: [1.0, 0.0, 0.0],
                degrees: 30.0,
            }),
        ),
    );
    let c = spec.resolve(&m).unwrap();
    let targets: Vec<(u32, [f64; 3])> = c.handles[0]
        .target_positions()
        .chain(c.fixed.iter().map(|&v| (v, m.positions()[v as usize])))
        .collect();
    let miss = |pose: &[[f64; 3]]| {
        targets
            .iter()
            .map(|&(v, p)| max_dist(&[pose[v as usize]], &[p]))
            .fold(0.0, f64::max)
    };
    for params in [ls(), Params::default()] {
        let (hard, _) = solve(&m, params, &spec, 50);
        assert_eq!(miss(&hard), 0.0, "{:?}", params.formulation.kind());
        for &v in &c.fixed {
            assert_eq!(
                hard[v as usize],
                m.positions()[v as usize],
                "fixed {v} keeps its bits"
            );
        }
    }
    let mut last = f64::INFINITY;
    for lambda1 in [0.1, 1.0, 10.0, 100.0, 1000.0] {
        let (soft, _) = solve(&m, Params { lambda1, ..ls() }, &spec, 50);
        let e = miss(&soft);
        eprintln!("soft lambda1 = {lambda1}: constraint miss {e:.3e}");
        assert!(e < last, "miss must shrink as lambda1 grows: {e} !< {last}");
        last = e;
    }
    assert!(last < 2e-2 * m.diagonal());
}

/// design.md §4.5: one solve of the 8th-order normal equations missed the
/// identity by 3e-4 of the diagonal on a random Delaunay saddle, and the
/// iteration then diverged. Solving for the update from the unsquared
/// residual keeps the identity exact, for every energy and both modes.
#[test]
fn identity_edit_on_random_delaunay_patches() {
    for seed in 1..4 {
        let m = random_delaunay_patch(300, seed);
        // fix the left rim, handle on the right rim, at rest
        let fixed: Vec<u64> = (0..m.num_vertices() as u64)
            .filter(|&v| m.positions()[v as usize][0] < -0.8)
            .collect();
        let hv: Vec<u64> = (0..m.num_vertices() as u64)
            .filter(|&v| m.positions()[v as usize][0] > 0.8)
            .collect();
        let spec = ConstraintsSpec {
            fixed_positions: None,
            fixed: VertexSet::Indices(fixed),
            handles: vec![HandleSpec {
                vertices: VertexSet::Indices(hv),
                ..handle(None, None)
            }],
        };
        for params in [
            ls(),
            Params {
                energy: Energy::ThinPlate,
                ..ls()
            },
            Params {
                lambda1: 10.0,
                ..ls()
            },
            Params {
                detail: DetailTerm::Linear,
                ..ls()
            },
        ] {
            let (pose, rep) = solve(&m, params, &spec, 50);
            let err = max_dist(&pose, m.positions()) / m.diagonal();
            assert!(err < 1e-8, "seed {seed} {params:?}: identity error {err:e}");
            assert!(!rep.diverged);
        }
        // A real edit on this sliver-ridden mesh: the nonlinear iteration may
        // not converge (it oscillates; see README "Known limitations"), but it
        // never returns NaN, never ends more than 5 % worse than it started, and
        // says so.
        let spec2 = ConstraintsSpec {
            fixed_positions: None,
            handles: vec![HandleSpec {
                translate: Some([0.0, 0.0, 0.5]),
                ..spec.handles[0].clone()
            }],
            ..spec.clone()
        };
        for params in [
            ls(),
            Params::paper(),
            Params {
                energy: Energy::Membrane,
                ..ls()
            },
        ] {
            let (pose, rep) = solve(&m, params, &spec2, 60);
            assert!(pose.iter().flatten().all(|v| v.is_finite()));
            assert!(
                rep.objective <= 1.05 * rep.initial_objective,
                "seed {seed}: {rep:?}"
            );
            assert!(
                rep.converged || rep.diverged || rep.iterations == 60,
                "{rep:?}"
            );
        }
    }
}

/// The same edit on a moderately irregular mesh (jittered grid saddle)
/// converges in every default energy.
#[test]
fn real_edit_converges_on_an_irregular_grid() {
    for seed in 1..3 {
        let m = irregular_saddle(16, seed);
        let fixed: Vec<u64> = (0..m.num_vertices() as u64)
            .filter(|&v| m.positions()[v as usize][0] < 0.5)
            .collect();
        let hv: Vec<u64> = (0..m.num_vertices() as u64)
            .filter(|&v| m.positions()[v as usize][0] > 14.5)
            .collect();
        let spec = ConstraintsSpec {
            fixed_positions: None,
            fixed: VertexSet::Indices(fixed),
            handles: vec![HandleSpec {
                vertices: VertexSet::Indices(hv),
                ..handle(Some([0.0, 0.0, 4.0]), None)
            }],
        };
        for energy in [Energy::TotalCurvature, Energy::ThinPlate, Energy::Membrane] {
            let (pose, rep) = solve(&m, Params { energy, ..ls() }, &spec, 100);
            assert!(
                rep.converged && !rep.diverged,
                "seed {seed} {energy:?}: {rep:?}"
            );
            assert!(pose.iter().flatten().all(|v| v.is_finite()));
        }
    }
}

/// A chain of one-iteration steps on unchanged targets (the server's settle
/// frames) follows the same iterates as one long step: the safeguard state,
/// the best pose and the Anderson history carry over between the calls.
#[test]
fn chained_one_iteration_steps_equal_one_long_step() {
    let m = square_tube(1.0, 6.0, 5, 25);
    let spec = tube_spec(
        &m,
        handle(
            Some([0.3, 0.0, 0.0]),
            Some(RotationSpec::AxisAngle {
                axis: [0.0, 0.0, 1.0],
                degrees: 90.0,
            }),
        ),
    );
    let c = spec.resolve(&m).unwrap();
    for params in [
        ls(),
        Params {
            anderson: 0,
            ..ls()
        },
    ] {
        let rest = Arc::new(Rest::new(m.clone()).unwrap());
        let f = Factor::build(&rest, &params, &c).unwrap();
        let mut long = Deformer::new(rest.clone(), params);
        let rep = long.step(&f, &c, 200).unwrap();
        assert!(rep.converged, "{rep:?}");
        let mut chained = Deformer::new(rest, params);
        let mut calls = 0;
        loop {
            let r = chained.step(&f, &c, 1).unwrap();
            calls += 1;
            if r.converged || calls == 400 {
                break;
            }
        }
        assert_eq!(calls, rep.iterations, "anderson {}", params.anderson);
        let diff = max_dist(long.pose(), chained.pose());
        assert!(diff < 1e-9 * m.diagonal(), "poses differ by {diff:e}");
    }
}
