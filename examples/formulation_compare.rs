//! Eq. (24) least squares vs eq. (23) square (docs/design.md) on the paper figures,
//! in one process: prints a markdown table for docs/performance.md.
//!
//! ```text
//! cargo run --release --example formulation_compare [-- --energy total]
//! ```
//!
//! Rows: the generated bar twisted 135° (min slab area, twist deviation), the
//! survey bar `.sel/.def` 135° (when `$DEND_MESHES` or `../shared/meshes`
//! holds it), the generated cylinder bent 120° (bend CV), each solved from
//! rest with at most 100 iterations; then the identity, translation and
//! rigid-motion errors (relative to the diagonal, tol 1e-10) on the generated
//! bar with both ends constrained.

use std::sync::Arc;
use std::time::Instant;

use dend::deform::*;
use dend::measure::{bar_slabs, bend_angles};
use dend::mesh::gen::{generate, Shape, ShapeSpec};
use dend::mesh::io::{self, survey};
use dend::mesh::{Mesh, Point};
use nalgebra::{UnitQuaternion, Vector3};

struct Run {
    pose: Vec<Point>,
    rep: StepReport,
    ms_per_it: f64,
    factor_nnz: usize,
}

fn run(mesh: &Mesh, params: Params, c: &Constraints) -> Run {
    let rest = Arc::new(Rest::new(mesh.clone()).expect("rest"));
    let f = Factor::build(&rest, &params, c).expect("factor");
    let mut d = Deformer::new(rest, params);
    let t = Instant::now();
    let rep = d.step(&f, c, params.max_iters).expect("step");
    let ms_per_it = t.elapsed().as_secs_f64() * 1e3 / rep.iterations.max(1) as f64;
    Run {
        pose: d.pose().to_vec(),
        rep,
        ms_per_it,
        factor_nnz: f.factor_nnz(),
    }
}

fn example(mesh: &Mesh, file: &str) -> Constraints {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(file);
    let spec: ConstraintsSpec =
        serde_json::from_str(&std::fs::read_to_string(path).expect("example")).expect("json");
    spec.resolve(mesh).expect("resolve")
}

fn free_span(mesh: &Mesh, c: &Constraints) -> (f64, f64) {
    let z = |v: &u32| mesh.positions()[*v as usize][2];
    let z0 = c.fixed.iter().map(z).fold(f64::MIN, f64::max);
    let z1 = c.handles[0].vertices.iter().map(z).fold(f64::MAX, f64::min);
    (z0, z1)
}

fn survey_bar() -> Option<(Mesh, Constraints)> {
    let dir = dend_testkit::shared_meshes()?;
    let mesh = io::read_path(&dir.join("survey_bar.off")).ok()?;
    let sel = survey::read_sel(&dir.join("survey_bar.sel")).ok()?;
    let def = survey::read_def(&dir.join("survey_bar.def")).ok()?;
    let fixed = sel.indices(survey::VertexStatus::Fixed);
    let handle = sel.indices(survey::VertexStatus::Handle);
    let mut c = Constraints::new(&mesh, fixed, vec![("handle".into(), handle, None)]).ok()?;
    let pivot = c.handles[0].rest_centroid;
    c.handles[0].target = RigidTransform::from_matrix(&def.matrix, pivot).ok()?;
    Some((mesh, c))
}

fn line(label: &str, figure: String, r: &Run) -> String {
    format!(
        "| {label} | {figure} | {} | {} / {} | {:.2} | {} |",
        r.rep.iterations, r.rep.converged, r.rep.diverged, r.ms_per_it, r.factor_nnz
    )
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let energy = args
        .iter()
        .position(|a| a == "--energy")
        .and_then(|i| args.get(i + 1))
        .map(|n| Energy::from_name(n).expect("energy"))
        .unwrap_or_default();
    let max_iters: usize = args
        .iter()
        .position(|a| a == "--max-iters")
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(100);
    println!("energy {energy:?}, max_iters {max_iters}, default parameters otherwise; ms/it = full solve time / iterations\n");
    println!("| set-up | formulation | figure | iterations | converged / diverged | ms/it | factor nnz |");
    println!("|---|---|---|---|---|---|---|");
    let bar = generate(&ShapeSpec::default_for(Shape::Bar)).expect("bar");
    twist_rows(&bar, energy, max_iters);
    cylinder_rows(energy, max_iters);
    invariance_table(&bar, energy);
}

/// The three formulations compared.
const FORMS: [Formulation; 3] = [
    Formulation::LeastSquares,
    Formulation::Square,
    Formulation::SquareLu,
];

/// The bar twists' rows (generated, and the survey's when present).
fn twist_rows(bar: &Mesh, energy: Energy, max_iters: usize) {
    let mut twists = vec![(
        "generated bar 135°",
        bar.clone(),
        example(bar, "bar-twist-135.json"),
        135.0,
    )];
    if let Some((m, c)) = survey_bar() {
        let deg = c.handles[0].target.rotation.scaled_axis().z.to_degrees();
        twists.push(("survey bar 135°", m, c, deg));
    }
    for (label, m, c, deg) in &twists {
        let (z0, z1) = free_span(m, c);
        for f in FORMS {
            let r = run(
                m,
                Params {
                    energy,
                    max_iters,
                    ..Params::default().with_formulation(f)
                },
                c,
            );
            let fig = bar_slabs(m.positions(), &r.pose, z0, z1, 20);
            let figure = format!(
                "min area {:.3}, twist dev {:.2}°",
                fig.min_area(),
                fig.twist_deviation(z0, z1, *deg)
            );
            println!("{}", line(&format!("{label} | {f:?}"), figure, &r));
        }
    }
}

/// The generated cylinder's bend rows.
fn cylinder_rows(energy: Energy, max_iters: usize) {
    let cyl = generate(&ShapeSpec::default_for(Shape::Cylinder)).expect("cylinder");
    let c = example(&cyl, "cylinder-bend-120.json");
    let (z0, z1) = free_span(&cyl, &c);
    for f in FORMS {
        let r = run(
            &cyl,
            Params {
                energy,
                max_iters,
                ..Params::default().with_formulation(f)
            },
            &c,
        );
        let (_, cv) = bend_angles(cyl.positions(), &r.pose, z0, z1, 12);
        println!(
            "{}",
            line(
                &format!("generated cylinder 120° | {f:?}"),
                format!("bend CV {cv:.3}"),
                &r
            )
        );
    }
}

/// The invariance table: both ends of the bar moved by one motion.
fn invariance_table(bar: &Mesh, energy: Energy) {
    let (lo, hi) = bar.bounding_box();
    let z = |v: usize| bar.positions()[v][2];
    let n = bar.num_vertices();
    let span = hi[2] - lo[2];
    let bottom: Vec<u32> = (0..n)
        .filter(|&v| z(v) < lo[2] + 0.05 * span)
        .map(|v| v as u32)
        .collect();
    let top: Vec<u32> = (0..n)
        .filter(|&v| z(v) > hi[2] - 0.05 * span)
        .map(|v| v as u32)
        .collect();
    let q = UnitQuaternion::from_axis_angle(
        &nalgebra::Unit::new_normalize(Vector3::new(0.3, 1.0, 0.2)),
        40f64.to_radians(),
    );
    let t = [0.5, -0.3, 0.2];
    let cases = [
        ("identity", UnitQuaternion::identity(), [0.0; 3]),
        ("translation", UnitQuaternion::identity(), t),
        ("rigid motion 40°", q, t),
    ];
    println!("\n| invariance (generated bar) | formulation | max error / diagonal | iterations |");
    println!("|---|---|---|---|");
    for (label, rot, t) in cases {
        let mut c = Constraints::new(
            bar,
            vec![],
            vec![
                ("bottom".into(), bottom.clone(), None),
                ("top".into(), top.clone(), None),
            ],
        )
        .expect("constraints");
        for h in &mut c.handles {
            h.target = RigidTransform {
                rotation: rot,
                translation: t,
                pivot: [0.0; 3],
            };
        }
        let want: Vec<Point> = bar
            .positions()
            .iter()
            .map(|&p| {
                let v = rot * Vector3::from(p) + Vector3::from(t);
                [v.x, v.y, v.z]
            })
            .collect();
        for f in FORMS {
            let params = Params {
                energy,
                tol: 1e-10,
                max_iters: 300,
                ..Params::default().with_formulation(f)
            };
            let r = run(bar, params, &c);
            let err = dend_testkit::max_dist(&r.pose, &want) / bar.diagonal();
            println!("| {label} | {f:?} | {err:.2e} | {} |", r.rep.iterations);
        }
    }
}
