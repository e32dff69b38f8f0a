//! Properties of the DEND solver (dend.md §7) on generated meshes.

mod support;

use std::sync::Arc;

use dend::deform::*;
use dend::mesh::Mesh;
use nalgebra::{UnitQuaternion, Vector3};
use support::*;

fn solve(
    mesh: &Mesh,
    params: Params,
    spec: &ConstraintsSpec,
    iters: usize,
) -> (Vec<[f64; 3]>, StepReport) {
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let c = spec.resolve(mesh).unwrap();
    let f = Factor::build(&rest, &params, &c).unwrap();
    let mut d = Deformer::new(rest, params);
    let rep = d.step(&f, &c, iters).unwrap();
    (d.pose().to_vec(), rep)
}

fn tube_spec(mesh: &Mesh, handle: HandleSpec) -> ConstraintsSpec {
    let (lo, hi) = mesh.bounding_box();
    let _ = lo;
    ConstraintsSpec {
        fixed: VertexSet::Box {
            bbox: BoxSel {
                min: [-9.0, -9.0, -0.01],
                max: [9.0, 9.0, 0.01 * hi[2] + 0.3],
            },
        },
        handles: vec![HandleSpec {
            vertices: VertexSet::Box {
                bbox: BoxSel {
                    min: [-9.0, -9.0, hi[2] * 0.99 - 0.3],
                    max: [9.0, 9.0, hi[2] + 1.0],
                },
            },
            ..handle
        }],
    }
}

fn handle(translate: Option<[f64; 3]>, rotate: Option<RotationSpec>) -> HandleSpec {
    HandleSpec {
        name: Some("top".into()),
        vertices: VertexSet::Indices(vec![]),
        translate,
        rotate,
        pivot: None,
        positions: None,
    }
}

#[test]
fn identity_edit_keeps_the_rest_pose_on_irregular_meshes() {
    for seed in 0..3 {
        let m = irregular_saddle(12, seed);
        let spec = ConstraintsSpec {
            fixed: VertexSet::Indices((0..12).collect()),
            handles: vec![HandleSpec {
                vertices: VertexSet::Indices((132..144).collect()),
                ..handle(None, None)
            }],
        };
        for energy in [Energy::TotalCurvature, Energy::ThinPlate, Energy::Membrane] {
            let params = Params {
                energy,
                ..Params::default()
            };
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
    let m = tube(1.0, 6.0, 5, 25);
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
                ..Params::default()
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
    // the literal paper's L² - 2LG is not translation invariant (dend.md §3)
    let params = Params {
        energy: Energy::TotalCurvaturePaper,
        detail: DetailTerm::Linear,
        mode: Mode::Paper,
        ..Params::default()
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

#[test]
fn twist_runs() {
    let m = tube(1.0, 6.0, 5, 25);
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
    for (name, params) in [
        ("default", Params::default()),
        (
            "membrane",
            Params {
                energy: Energy::Membrane,
                ..Params::default()
            },
        ),
        ("paper", Params::paper()),
        (
            "thin-plate linear",
            Params {
                energy: Energy::ThinPlate,
                detail: DetailTerm::Linear,
                ..Params::default()
            },
        ),
    ] {
        let (pose, rep) = solve(&m, params, &spec, 200);
        let f = dend::measure::bar_slabs(m.positions(), &pose, 0.6, 5.4, 10);
        eprintln!(
            "{name}: {rep:?} min area {:.3} twist dev {:.2} twist {:?}",
            f.min_area(),
            f.twist_deviation(0.55, 5.45, 135.0),
            f.twist_deg
        );
    }
}
