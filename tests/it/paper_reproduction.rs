//! The paper's Figure 1 and 2 set-ups as measured tests (design.md §10, §11;
//! docs/paper-reproduction.md): a bar twisted 135° and 300°, a cylinder bent 120° and 180°, on
//! the generated paper-sized shapes (always) and on the Botsch–Sorkine survey
//! meshes (when `$DEND_MESHES` is present), each in three modes: our default
//! (E_T, rotated internal term, nonlinear detail term), the literal paper
//! (`Params::paper()`) and thin plate + linear detail term (the paper's
//! "collapsing" baseline). The survey's cactus and bumpy plane are checked for
//! convergence, finiteness and exact handles.
//!
//! Figures (`dend::measure`): for a twisted bar, the smallest cross-section
//! area relative to rest ("min area") and the largest deviation of the
//! cross-sections' twist from a linear ramp ("twist dev"); for a bent
//! cylinder, the coefficient of variation of the bend angle between
//! consecutive slabs ("bend CV"). Every run prints its figures (run with
//! `--nocapture`); docs/paper-reproduction.md tabulates them beside libigl's
//! ARAP (`scripts/arap_reference.py`).

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use dend::deform::*;
use dend::measure::{bar_slabs, bend_angles};
use dend::mesh::gen::{generate, Shape, ShapeSpec};
use dend::mesh::io::{self, survey};
use dend::mesh::{Mesh, Point};

/// The modes compared throughout: the elastic formulation with the
/// `elastica` preset (the paper's even bend and twist, docs/posing.md), the literal paper, the paper's
/// linear variant (thin plate + linear detail term, eq. (24)) and eq. (24)
/// least squares with our reading (the default before the elastic one).
fn modes() -> [(&'static str, Params); 4] {
    let least_squares = Params::default().with_formulation(Formulation::LeastSquares);
    [
        ("elastica", Params::elastica()),
        ("paper", Params::paper()),
        (
            "thin-plate+linear",
            Params {
                energy: Energy::ThinPlate,
                detail: DetailTerm::Linear,
                ..least_squares
            },
        ),
        ("least-squares", least_squares),
    ]
}

/// What one run did.
struct Run {
    pose: Vec<Point>,
    iterations: usize,
    /// Every step converged.
    converged: bool,
    /// Some step stopped on a growing objective.
    diverged: bool,
    ms_per_iteration: f64,
    /// Final over initial objective of the last step.
    objective_ratio: f64,
}

/// Applies the handle's full target in `steps` equal increments (warm
/// started), `max_iters` iterations per increment, and checks what must hold
/// in every mode: a finite pose with the fixed and handle vertices exactly at
/// their targets.
fn run(
    mesh: &Mesh,
    constraints: &Constraints,
    params: Params,
    steps: usize,
    max_iters: usize,
) -> Run {
    let rest = Arc::new(Rest::new(mesh.clone()).unwrap());
    let factor = Factor::build(&rest, &params, constraints).unwrap();
    let mut c = constraints.clone();
    let full = c.handles[0].target;
    let mut d = Deformer::new(rest, params);
    let (mut iterations, mut converged, mut diverged) = (0, true, false);
    let mut objective_ratio = 1.0;
    let t0 = Instant::now();
    for s in 1..=steps {
        c.handles[0].target = full.fraction(s as f64 / steps as f64);
        let rep = d.step(&factor, &c, max_iters).unwrap();
        iterations += rep.iterations;
        converged &= rep.converged;
        diverged |= rep.diverged;
        objective_ratio = rep.objective / rep.initial_objective.max(f64::MIN_POSITIVE);
    }
    let ms_per_iteration = t0.elapsed().as_secs_f64() * 1e3 / iterations.max(1) as f64;
    let pose = d.pose().to_vec();
    assert!(
        pose.iter().flatten().all(|v| v.is_finite()),
        "non-finite pose"
    );
    let tol = 1e-9 * mesh.diagonal();
    let far = |a: Point, b: Point| (0..3).any(|k| (a[k] - b[k]).abs() > tol);
    for &v in &c.fixed {
        let (p, q) = (pose[v as usize], mesh.positions()[v as usize]);
        assert!(!far(p, q), "fixed vertex {v} moved: {p:?} vs {q:?}");
    }
    for (v, q) in c.handles[0].target_positions() {
        let p = pose[v as usize];
        assert!(!far(p, q), "handle vertex {v} missed: {p:?} vs {q:?}");
    }
    Run {
        pose,
        iterations,
        converged,
        diverged,
        ms_per_iteration,
        objective_ratio,
    }
}

/// Rest z range between the fixed and the handle regions.
fn free_span(mesh: &Mesh, c: &Constraints) -> (f64, f64) {
    let z = |v: &u32| mesh.positions()[*v as usize][2];
    let z0 = c.fixed.iter().map(z).fold(f64::MIN, f64::max);
    let z1 = c.handles[0].vertices.iter().map(z).fold(f64::MAX, f64::min);
    assert!(z0 < z1, "fixed region above the handle");
    (z0, z1)
}

fn example(mesh: &Mesh, file: &str) -> Constraints {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("examples")
        .join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    let spec: ConstraintsSpec = serde_json::from_str(&text).unwrap();
    spec.resolve(mesh).unwrap()
}

fn generated(shape: Shape) -> Mesh {
    generate(&ShapeSpec::default_for(shape)).unwrap()
}

fn meshes_dir() -> Option<PathBuf> {
    dend_testkit::shared_meshes()
}

/// A survey set-up: mesh, status 0 fixed, status 2 the handle, the `.def`
/// transform about the handle's rest centroid.
fn survey_setup(name: &str) -> Option<(Mesh, Constraints)> {
    let dir = meshes_dir()?;
    let mesh = io::read_path(&dir.join(format!("survey_{name}.off"))).unwrap();
    let sel = survey::read_sel(&dir.join(format!("survey_{name}.sel"))).unwrap();
    sel.check_len(mesh.num_vertices()).unwrap();
    let def = survey::read_def(&dir.join(format!("survey_{name}.def"))).unwrap();
    let fixed = sel.indices(survey::VertexStatus::Fixed);
    let handle = sel.indices(survey::VertexStatus::Handle);
    let mut c = Constraints::new(&mesh, fixed, vec![("handle".into(), handle, None)]).unwrap();
    let pivot = c.handles[0].rest_centroid;
    c.handles[0].target = RigidTransform::from_matrix(&def.matrix, pivot).unwrap();
    Some((mesh, c))
}

/// Bar figures per mode: (label, min area, twist dev, run).
type BarRow = (&'static str, f64, f64, Run);

/// Runs the three modes on a twist set-up and prints the figures. The ramp's
/// total twist is the handle's signed rotation about +z, `degrees`.
fn twist(
    label: &str,
    mesh: &Mesh,
    c: &Constraints,
    degrees: f64,
    steps: usize,
    max_iters: usize,
) -> Vec<BarRow> {
    let (z0, z1) = free_span(mesh, c);
    modes()
        .into_iter()
        .map(|(mode, params)| {
            let r = run(mesh, c, params, steps, max_iters);
            let fig = bar_slabs(mesh.positions(), &r.pose, z0, z1, 20);
            assert!(fig.z.len() >= 15, "too few populated slabs: {}", fig.z.len());
            let (area, dev) = (fig.min_area(), fig.twist_deviation(z0, z1, degrees));
            eprintln!(
                "{label} {mode}: min area {area:.3}, twist dev {dev:.1}°, {} iterations ({:.1} ms/it), converged {}, diverged {}",
                r.iterations, r.ms_per_iteration, r.converged, r.diverged
            );
            (mode, area, dev, r)
        })
        .collect()
}

/// Runs the three modes on a bend set-up: (label, bend CV, run).
fn bend(
    label: &str,
    mesh: &Mesh,
    c: &Constraints,
    steps: usize,
    max_iters: usize,
) -> Vec<(&'static str, f64, Run)> {
    let (z0, z1) = free_span(mesh, c);
    modes()
        .into_iter()
        .map(|(mode, params)| {
            let r = run(mesh, c, params, steps, max_iters);
            let (angles, cv) = bend_angles(mesh.positions(), &r.pose, z0, z1, 12);
            assert_eq!(angles.len(), 10, "empty slabs");
            let total: f64 = angles.iter().sum();
            eprintln!(
                "{label} {mode}: bend CV {cv:.3}, total {total:.1}°, {} iterations ({:.1} ms/it), converged {}, diverged {}; angles {:?}",
                r.iterations,
                r.ms_per_iteration,
                r.converged,
                r.diverged,
                angles.iter().map(|a| (a * 10.0).round() / 10.0).collect::<Vec<_>>()
            );
            (mode, cv, r)
        })
        .collect()
}

/// The default mode on a 135° twist meets the 135° rule of
/// docs/paper-reproduction.md, which beats
/// converged ARAP: min area ≥ 0.92 and twist deviation ≤ 3° in at most 20
/// iterations, converged without divergence; thin plate + linear collapses
/// (min area below `collapse`); the literal paper twists worse.
fn check_twist_135(rows: &[BarRow], collapse: f64) {
    let [(_, area, dev, d), (_, _, paper_dev, _), (_, tp_area, _, _), _] = rows else {
        unreachable!()
    };
    assert!(d.converged && !d.diverged, "default did not converge");
    assert!(
        d.iterations <= 20,
        "default took {} iterations > 20",
        d.iterations
    );
    assert!(*area >= 0.92, "default min area {area:.3} < 0.92");
    assert!(*dev <= 3.0, "default twist deviation {dev:.1}° > 3°");
    assert!(
        *tp_area < collapse,
        "thin plate + linear did not collapse: min area {tp_area:.3} ≥ {collapse}"
    );
    assert!(
        paper_dev > dev,
        "paper mode twist dev {paper_dev:.1}° not worse than default {dev:.1}°"
    );
}

#[test]
fn generated_bar_twisted_135() {
    let m = generated(Shape::Bar);
    let c = example(&m, "bar-twist-135.json");
    let rows = twist("bar 135°", &m, &c, 135.0, 1, 100);
    check_twist_135(&rows, 0.5);
}

#[test]
fn generated_bar_twisted_300_in_5_steps() {
    let m = generated(Shape::Bar);
    let c = example(&m, "bar-twist-300.json");
    let rows = twist("bar 300°", &m, &c, 300.0, 5, 100);
    // The elastic default keeps the twist's direction with min area 0.80
    // and 2.7° from the ramp in 57 iterations; tests/it/elastic.rs holds it to
    // the rule (min area ≥ 0.8). Here it is held to what held for
    // every formulation that has been the default: constraints met and a
    // finite pose (`run`), and the last step ending within the safeguard's
    // slack of its starting objective (eq. (24) least squares, the default
    // before, ended on rounding: with fused and unfused multiply-adds once
    // pinched, min area 0.241, and once unwound). The path-independent
    // modes end at the handle's −60° equivalent (dev > 300°).
    let [(_, _, _, d), (_, _, paper_dev, _), (_, _, tp_dev, _), _] = &rows[..] else {
        unreachable!()
    };
    assert_within_safeguard(d);
    assert!(
        *paper_dev > 300.0 && *tp_dev > 300.0,
        "paper {paper_dev:.1}° / thin plate {tp_dev:.1}°"
    );
}

/// The safeguard's guarantee for a run whose outcome is not reproducible:
/// its last step ended within the slack (1.05) of its starting objective.
fn assert_within_safeguard(d: &Run) {
    assert!(
        d.objective_ratio <= 1.05 + 1e-9,
        "default's last step ended above its start: ratio {}",
        d.objective_ratio
    );
}

#[test]
fn generated_cylinder_bent_120() {
    let m = generated(Shape::Cylinder);
    let c = example(&m, "cylinder-bend-120.json");
    let rows = bend("cylinder 120°", &m, &c, 1, 100);
    // measured on the arc-consistent edit (the handle where an arc of the
    // free length puts it): elastica 0.474, least squares 0.108, paper
    // 0.111, thin plate + linear 0.102; the even arc measures 0.063 (the
    // measure's floor on this cylinder), ARAP converged 0.364 (docs/posing.md)
    check_bend(&rows, 0.15, 0.6);
}

#[test]
fn generated_cylinder_bent_180_in_3_steps() {
    let m = generated(Shape::Cylinder);
    let c = example(&m, "cylinder-bend-180.json");
    let rows = bend("cylinder 180°", &m, &c, 3, 100);
    // The elastica preset converges in 75 iterations with bend CV 0.40
    // (its stretch and area terms let the tube ovalise where it bends
    // most). Asserted for it: constraints, a finite pose, and the last step
    // ending within the safeguard's slack of its start (eq. (24) least
    // squares, the default before, stopped on a growing objective at a
    // rounding-dependent CV, 0.180 or 0.475). Thin plate + linear (0.166)
    // and the paper mode (0.228) bend more evenly.
    let [(_, _, d), (_, paper_cv, _), (_, tp_cv, _), _] = &rows[..] else {
        unreachable!()
    };
    assert_within_safeguard(d);
    assert!(
        *tp_cv <= 0.2 && *paper_cv <= 0.25,
        "paper {paper_cv:.3} / thin plate {tp_cv:.3}"
    );
}

/// The default mode's bend CV is at most `max_cv`, it does not diverge, and
/// it bends at least as evenly as thin plate + linear (within 0.02 of its CV).
/// Eq. (24) least squares' bend CV is at most `max_cv`, it does not
/// diverge, and it bends at least as evenly as thin plate + linear (within
/// 0.02 of its CV). The elastic default converges and its CV is at most
/// `elastic_max_cv`: it does NOT bend as evenly (its stretch and area
/// terms let the tube ovalise where it bends most; see
/// docs/paper-reproduction.md), which this bound records.
fn check_bend(rows: &[(&'static str, f64, Run)], max_cv: f64, elastic_max_cv: f64) {
    let [(_, el_cv, el), _, (_, tp_cv, _), (_, cv, d)] = rows else {
        unreachable!()
    };
    assert!(*cv <= max_cv, "least-squares bend CV {cv:.3} > {max_cv}");
    assert!(!d.diverged, "least squares diverged");
    assert!(
        *cv <= tp_cv + 0.02,
        "least-squares bend CV {cv:.3} worse than thin plate + linear {tp_cv:.3}"
    );
    assert!(el.converged && !el.diverged, "elastic did not converge");
    assert!(
        *el_cv <= elastic_max_cv,
        "elastic bend CV {el_cv:.3} > {elastic_max_cv}"
    );
}

#[test]
fn survey_bar_twisted_135() {
    let Some((m, c)) = survey_setup("bar") else {
        return;
    };
    let degrees = c.handles[0].target.rotation.scaled_axis().z.to_degrees();
    assert!((degrees - 135.0).abs() < 0.1, "survey twist {degrees}");
    let rows = twist("survey bar 135°", &m, &c, degrees, 1, 100);
    check_twist_135(&rows, 0.5);
}

#[test]
fn survey_cylinder_bent_120() {
    let Some((m, c)) = survey_setup("cylinder") else {
        return;
    };
    let rows = bend("survey cylinder 120°", &m, &c, 1, 100);
    // measured: default 0.298, paper 0.296, thin plate + linear 0.297, ARAP
    // 1.25 after 100 iterations (the survey's target is not a uniform arc)
    check_bend(&rows, 0.35, 1.0);
}

/// Cactus and bumpy plane: every mode gives a finite pose with exact
/// handles (checked in `run`); the default lowers the objective at least
/// tenfold (and does not diverge on the bumpy plane). Measured: it does NOT converge to tol 1e-3
/// in 100 iterations on either (cactus 70 ms/it, bumpy plane 450 ms/it in
/// the dev build), so the iteration budget is `max_iters` and convergence
/// is reported, not asserted.
fn smoke(name: &str, max_iters: usize) {
    let Some((m, c)) = survey_setup(name) else {
        return;
    };
    for (mode, params) in modes() {
        let r = run(&m, &c, params, 1, max_iters);
        eprintln!(
            "survey {name} {mode}: {} iterations ({:.1} ms/it), converged {}, diverged {}, objective ratio {:.2e}",
            r.iterations, r.ms_per_iteration, r.converged, r.diverged, r.objective_ratio
        );
        if mode == "elastica" {
            // The cactus may end `diverged`: after reaching ~1e-7 of its
            // starting objective, a flip of δ̂ (|d_i| crossing 0) blows the
            // iterate up at iteration ~87; the step then keeps the best pose
            // seen, which is what the ratio below checks.
            assert!(!r.diverged || name == "cactus", "elastica diverged");
            assert!(
                r.objective_ratio < 0.1,
                "objective only fell to {:.3} of its start",
                r.objective_ratio
            );
        }
    }
}

#[test]
fn survey_cactus() {
    smoke("cactus", 100);
}

#[test]
fn survey_bumpy_plane() {
    // 40401 vertices: 30 iterations keep CI time down (450 ms/it dev build)
    smoke("bumpy_plane", 30);
}
