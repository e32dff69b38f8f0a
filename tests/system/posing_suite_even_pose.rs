//! The posing suite's *even pose* (`even_pose` in `scripts/posing_suite.py`),
//! checked against the library: docs/posing.md reads the rules' conflicts
//! off its edge distortion, so it must really keep every constraint, keep
//! the cross-sections and spread the twist or bend evenly.
//!
//! The script builds the pose on `dend gen`'s bar and cylinder with the
//! examples' constraint files; this test resolves the same files with the
//! library (`ConstraintsSpec::resolve`), checks every constrained vertex
//! against its target, and measures the pose with `dend::measure`.

use std::path::{Path, PathBuf};
use std::process::Command;

use dend::deform::ConstraintsSpec;
use dend::measure::{bar_slabs, bend_angles};
use dend::mesh::Mesh;
use dend_testkit::{max_dist, python_with, read_mesh, repo_root};

/// Runs the suite's `build_case` and `even_pose` on `case`, writing the rest
/// mesh and the even pose as OFF files into `dir`.
fn even_pose(py: &Path, case: &str, dir: &Path) -> (Mesh, Mesh) {
    let script = r#"
import importlib.util, os, sys
root, case, out, dend = sys.argv[1:5]
spec = importlib.util.spec_from_file_location("ps", os.path.join(root, "scripts", "posing_suite.py"))
ps = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ps)
c = ps.build_case(case, out, dend)
u = ps.even_pose(c)
if u is None:
    sys.exit(f"{case}: no even pose")
ps.write_off(os.path.join(out, "rest.off"), c["v"], c["f"])
ps.write_off(os.path.join(out, "even.off"), u, c["f"])
"#;
    let out = Command::new(py)
        .arg("-c")
        .arg(script)
        .arg(repo_root())
        .arg(case)
        .arg(dir)
        .arg(env!("CARGO_BIN_EXE_dend"))
        .output()
        .expect("running python");
    assert!(
        out.status.success(),
        "{case}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (
        read_mesh(&dir.join("rest.off")),
        read_mesh(&dir.join("even.off")),
    )
}

/// The largest distance of a constrained vertex from its target, and the
/// rest `z` span between the fixed part and the handle.
fn constraint_error(rest: &Mesh, pose: &Mesh, file: &str) -> (f64, (f64, f64)) {
    let path: PathBuf = repo_root().join("examples").join(file);
    let spec: ConstraintsSpec =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let c = spec.resolve(rest).unwrap();
    let p = pose.positions();
    let dist = |a: [f64; 3], b: [f64; 3]| max_dist(&[a], &[b]);
    let mut err: f64 = 0.0;
    for (&v, &at) in c.fixed.iter().zip(&c.fixed_at) {
        err = err.max(dist(p[v as usize], at));
    }
    for h in &c.handles {
        for (v, want) in h.target_positions() {
            err = err.max(dist(p[v as usize], want));
        }
    }
    let z = |v: &u32| rest.positions()[*v as usize][2];
    let z0 = c.fixed.iter().map(z).fold(f64::MIN, f64::max);
    let z1 = c.handles[0].vertices.iter().map(z).fold(f64::MAX, f64::min);
    (err, (z0, z1))
}

/// The even pose of `case` (constraints from examples/`file`), its every
/// constrained vertex checked on its target: (rest, pose, free `z` span).
fn checked_even_pose(py: &Path, tmp: &Path, case: &str, file: &str) -> (Mesh, Mesh, (f64, f64)) {
    let dir = tmp.join(case);
    std::fs::create_dir_all(&dir).unwrap();
    let (rest, pose) = even_pose(py, case, &dir);
    let (err, span) = constraint_error(&rest, &pose, file);
    assert!(
        err < 1e-9,
        "{case}: a constrained vertex {err} off its target"
    );
    (rest, pose, span)
}

#[test]
fn the_even_pose_keeps_the_constraints_and_twists_and_bends_evenly() {
    let Some(py) = python_with(&["numpy", "igl"]) else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    for (case, file, degrees) in [
        ("bar-135", "bar-twist-135.json", 135.0),
        ("bar-300", "bar-twist-300.json", 300.0),
    ] {
        let (rest, pose, (z0, z1)) = checked_even_pose(&py, tmp.path(), case, file);
        let fig = bar_slabs(rest.positions(), pose.positions(), z0, z1, 20);
        let dev = fig.twist_deviation(z0, z1, degrees);
        assert!(dev < 0.05, "{case}: twist deviation {dev}°");
        assert!(
            (fig.min_area() - 1.0).abs() < 1e-6,
            "{case}: min area {}",
            fig.min_area()
        );
    }
    for (case, file) in [
        ("cylinder-120", "cylinder-bend-120.json"),
        ("cylinder-180", "cylinder-bend-180.json"),
        ("bar-bend-120", "bar-bend-120.json"),
        ("bar-bend-180", "bar-bend-180.json"),
    ] {
        let (rest, pose, (z0, z1)) = checked_even_pose(&py, tmp.path(), case, file);
        // the measure's own floor on an exact arc is 0.06 on this cylinder
        // and 0.05 on the square tube (slab centroids of two or three
        // rings); a kink or an uneven spread measures 0.3 and more
        let (angles, cv) = bend_angles(rest.positions(), pose.positions(), z0, z1, 12);
        assert_eq!(angles.len(), 10, "{case}");
        assert!(cv < 0.07, "{case}: bend CV {cv}, angles {angles:?}");
        // rings are carried rigidly: every ring keeps its shape, so the
        // rest and pose distances from a ring's vertices to its centroid agree
        let (r, p) = (rest.positions(), pose.positions());
        let mut rings: std::collections::BTreeMap<i64, Vec<usize>> = Default::default();
        for (i, q) in r.iter().enumerate() {
            rings
                .entry((q[2] * 1e6).round() as i64)
                .or_default()
                .push(i);
        }
        for ix in rings.values().filter(|ix| ix.len() > 2) {
            let centroid = |pts: &[[f64; 3]]| {
                let mut c = [0.0; 3];
                for &i in ix {
                    for k in 0..3 {
                        c[k] += pts[i][k] / ix.len() as f64;
                    }
                }
                c
            };
            let (cr, cp) = (centroid(r), centroid(p));
            for &i in ix {
                let (rest_d, pose_d) = (max_dist(&[r[i]], &[cr]), max_dist(&[p[i]], &[cp]));
                assert!(
                    (rest_d - pose_d).abs() < 1e-9,
                    "{case}: vertex {i} moved within its ring"
                );
            }
        }
    }
}
