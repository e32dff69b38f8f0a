//! `dend deform` end to end: the README's commands, the survey format, and
//! errors with exit code 2.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dend::deform::ConstraintsSpec;
use dend::mesh::io;

fn dend(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dend"))
        .args(args)
        .output()
        .unwrap()
}

/// A generated bar in `dir` (written as `file`) and the README's 135°
/// twist constraints for it.
fn bar_and_twist(dir: &Path, file: &str) -> (PathBuf, PathBuf) {
    let bar = dir.join(file);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let example = root.join("examples/bar-twist-135.json");
    assert!(dend(&["gen", "bar", "-o", bar.to_str().unwrap()])
        .status
        .success());
    (bar, example)
}

/// `dend deform BAR --constraints EXAMPLE -o OUT EXTRA…`.
fn deform_bar(bar: &Path, example: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "deform",
        bar.to_str().unwrap(),
        "--constraints",
        example.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    dend(&args)
}

#[test]
fn readme_bar_twist_meets_the_handle_targets_and_keeps_the_section() {
    let dir = tempfile::tempdir().unwrap();
    let (bar, example) = bar_and_twist(dir.path(), "bar.obj");
    let out = dir.path().join("out.obj");
    let o = deform_bar(&bar, &example, &out, &[]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("converged"), "{stderr}");
    assert!(stderr.contains("per iteration"), "{stderr}");
    let rest = io::read_path(&bar).unwrap();
    let pose = io::read_path(&out).unwrap();
    assert_eq!(pose.triangles(), rest.triangles());
    // handle vertices sit on their targets (OBJ keeps ~1e-6 relative precision)
    let spec: ConstraintsSpec =
        serde_json::from_str(&std::fs::read_to_string(&example).unwrap()).unwrap();
    let c = spec.resolve(&rest).unwrap();
    for (v, p) in c.handles[0].target_positions() {
        let got = pose.positions()[v as usize];
        assert!(
            dend_testkit::max_dist(&[got], &[p]) < 1e-5,
            "handle vertex {v}: {got:?} vs {p:?}"
        );
    }
    for &v in &c.fixed {
        assert!(
            dend_testkit::max_dist(
                &[pose.positions()[v as usize]],
                &[rest.positions()[v as usize]]
            ) < 1e-6
        );
    }
    let fig = dend::measure::bar_slabs(rest.positions(), pose.positions(), 0.5, 5.5, 10);
    assert!(fig.min_area() > 0.85, "cross-section collapsed: {fig:?}");
    assert!(fig.twist_deviation(0.5, 5.5, 135.0) < 8.0, "{fig:?}");
}

#[test]
fn survey_files_are_read_directly() {
    let Some(meshes) = dend_testkit::shared_meshes() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cactus.off");
    let p = |s: &str| meshes.join(s).to_str().unwrap().to_string();
    let o = dend(&[
        "deform",
        &p("survey_cactus.off"),
        "--sel",
        &p("survey_cactus.sel"),
        "--def",
        &p("survey_cactus.def"),
        "-o",
        out.to_str().unwrap(),
        "--max-iters",
        "30",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rest = io::read_path(&meshes.join("survey_cactus.off")).unwrap();
    let pose = io::read_path(&out).unwrap();
    let sel = io::survey::read_sel(&meshes.join("survey_cactus.sel")).unwrap();
    let def = io::survey::read_def(&meshes.join("survey_cactus.def")).unwrap();
    // the handle follows the .def matrix (re-orthonormalised), the fixed part stays
    for v in sel.indices(io::survey::VertexStatus::Handle) {
        let want = def.apply(rest.positions()[v as usize]);
        assert!(
            dend_testkit::max_dist(&[pose.positions()[v as usize]], &[want])
                < 1e-3 * rest.diagonal()
        );
    }
    for v in sel.indices(io::survey::VertexStatus::Fixed) {
        assert!(
            dend_testkit::max_dist(
                &[pose.positions()[v as usize]],
                &[rest.positions()[v as usize]]
            ) < 1e-9 * rest.diagonal()
        );
    }
}

#[test]
fn bad_inputs_exit_with_code_2_and_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let bar = dir.path().join("bar.off");
    assert!(dend(&["gen", "bar", "-o", bar.to_str().unwrap()])
        .status
        .success());
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p.to_str().unwrap().to_string()
    };
    let cases = [
        (
            write(
                "overlap.json",
                r#"{"fixed": [0, 1], "handles": [{"vertices": [1]}]}"#,
            ),
            "already fixed",
        ),
        (
            write("unknown.json", r#"{"fixed": [0, 100000]}"#),
            "unknown vertex",
        ),
        (
            write(
                "empty.json",
                r#"{"fixed": [0], "handles": [{"name": "h", "vertices": {"sphere": {"center": [9,9,9], "radius": 0.1}}}]}"#,
            ),
            "selects no vertex",
        ),
        (write("syntax.json", r#"{"fixed": [0"#), "parsing"),
        (
            write(
                "nan.json",
                r#"{"fixed": [0], "handles": [{"vertices": [5], "rotate": {"axis": [0,0,0], "degrees": 10}}]}"#,
            ),
            "axis is zero",
        ),
    ];
    let out = dir.path().join("o.obj");
    for (file, needle) in &cases {
        let o = dend(&[
            "deform",
            bar.to_str().unwrap(),
            "--constraints",
            file,
            "-o",
            out.to_str().unwrap(),
        ]);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{file}: {stderr}");
        assert!(
            stderr.contains("error:") && stderr.contains(needle),
            "{file}: {stderr}"
        );
    }
    // unreadable mesh, bad parameter
    let o = dend(&[
        "deform",
        "/nonexistent.off",
        "--constraints",
        &cases[0].0,
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let o = dend(&[
        "deform",
        bar.to_str().unwrap(),
        "--constraints",
        &cases[0].0,
        "--lambda2",
        "-1",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn formulation_flag_selects_the_square_system_and_rejects_unknown_names() {
    let dir = tempfile::tempdir().unwrap();
    let (bar, example) = bar_and_twist(dir.path(), "bar.off");
    let out = dir.path().join("out.off");
    let run = |formulation: &str| deform_bar(&bar, &example, &out, &["--formulation", formulation]);
    let o = run("square_lu");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    let rest = io::read_path(&bar).unwrap();
    let pose = io::read_path(&out).unwrap();
    assert!(dend_testkit::max_dist(pose.positions(), rest.positions()) > 0.1);
    let o = run("cubic");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("unknown formulation"), "{stderr}");
}

/// `--weights characters` is `--stretch 3 --laplacian 0.1 --coarse-ratio 4
/// --corrections while-gaining --correction-period 5` (the same pose to the
/// last written digit), differs from the defaults, and yields to an
/// explicit `--stretch`; a coarse ratio under 2 and a correction period of
/// 0 are refused with exit code 2.
#[test]
fn characters_weights_are_the_documented_stretch_and_laplacian() {
    let dir = tempfile::tempdir().unwrap();
    let (bar, example) = bar_and_twist(dir.path(), "bar.obj");
    let pose = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let o = deform_bar(&bar, &example, &out, extra);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read_to_string(&out).unwrap()
    };
    // the preset's flags but the stretch
    let rest_of_preset = [
        "--laplacian",
        "0.1",
        "--coarse-ratio",
        "4",
        "--corrections",
        "while-gaining",
        "--correction-period",
        "5",
    ];
    let preset = pose("preset.obj", &["--weights", "characters"]);
    let explicit = pose(
        "explicit.obj",
        &[&["--stretch", "3"][..], &rest_of_preset].concat(),
    );
    let defaults = pose("defaults.obj", &["--preset", "elastica"]);
    let overridden = pose(
        "overridden.obj",
        &["--weights", "characters", "--stretch", "1"],
    );
    // elastica (stretch 1) with the characters' other fields written out
    let laplacian_only = pose(
        "laplacian.obj",
        &[&["--preset", "elastica"][..], &rest_of_preset].concat(),
    );
    assert_eq!(preset, explicit);
    assert_ne!(preset, defaults);
    assert_eq!(overridden, laplacian_only);
    let o = dend(&[
        "deform",
        bar.to_str().unwrap(),
        "-o",
        "x.obj",
        "--weights",
        "cartoon",
    ]);
    assert_eq!(o.status.code(), Some(2));
    for (flag, value, name) in [
        ("--coarse-ratio", "1", "coarse_ratio"),
        ("--correction-period", "0", "correction_period"),
    ] {
        let o = deform_bar(
            &bar,
            &example,
            &dir.path().join("refused.obj"),
            &[flag, value],
        );
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag} {value}: {stderr}");
        assert!(stderr.contains(name), "{flag} {value}: {stderr}");
    }
}

/// `--galerkin` on the generated cylinder (1,088 vertices: one coarse
/// level) bent 120°: `1` fills LAG, PERIOD and SMOOTH with the documented
/// defaults (the same pose to the last written digit as `1,6,1,1`, and as
/// `2`: DEPTH 2 falls back to the one level), the flag and its LAG and
/// SMOOTH reach the solver (other poses without it, with `off` (the same
/// as without), `1,1,1` and `1,6,1,0`), the report names the setting and
/// counts the
/// solve in fine iterations; malformed values (a zero, a word, an empty or
/// a fifth field) and a setting without coarse levels are refused with
/// exit code 2 and a message naming the flag.
#[test]
fn galerkin_flag_fills_defaults_reaches_the_solver_and_rejects_bad_values() {
    let dir = tempfile::tempdir().unwrap();
    let cylinder = dir.path().join("cylinder.obj");
    assert!(dend(&["gen", "cylinder", "-o", cylinder.to_str().unwrap()])
        .status
        .success());
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cylinder-bend-120.json");
    let run = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let o = deform_bar(&cylinder, &example, &out, extra);
        let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
        (o.status.code(), stderr, std::fs::read_to_string(&out).ok())
    };
    let report = dir.path().join("report.json");
    let (code, stderr, short) = run(
        "short.obj",
        &["--galerkin", "1", "--report", report.to_str().unwrap()],
    );
    assert_eq!(code, Some(0), "{stderr}");
    assert!(stderr.contains("converged"), "{stderr}");
    let pose = |name: &str, extra: &[&str]| {
        let (code, stderr, pose) = run(name, extra);
        assert_eq!(code, Some(0), "{stderr}");
        pose.unwrap()
    };
    let short = short.unwrap();
    assert_eq!(short, pose("full.obj", &["--galerkin", "1,6,1,1"]));
    assert_eq!(short, pose("depth2.obj", &["--galerkin", "2"]));
    let fas = pose("fas.obj", &[]);
    assert_ne!(short, fas);
    assert_eq!(fas, pose("off.obj", &["--galerkin", "off"]));
    assert_ne!(short, pose("lag1.obj", &["--galerkin", "1,1,1"]));
    assert_ne!(short, pose("rigid.obj", &["--galerkin", "1,6,1,0"]));
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(rep["galerkin"], serde_json::json!([1, 6, 1, 1]), "{rep}");
    let fie = rep["fine_iteration_equivalents"].as_f64().unwrap();
    let iterations = rep["iterations"].as_f64().unwrap();
    // the solve holds at least its fine iterations (less timer noise)
    assert!(fie >= 0.5 * iterations, "{fie} for {iterations} iterations");
    for (value, needle) in [
        ("0", "DEPTH"),
        ("1,x", "LAG"),
        ("1,6,0", "PERIOD"),
        ("", "DEPTH"),
        ("1,6,1,-1", "SMOOTH"),
        ("1,6,1,0,2", "5 fields"),
    ] {
        let (code, stderr, _) = run("refused.obj", &["--galerkin", value]);
        assert_eq!(code, Some(2), "{value:?}: {stderr}");
        assert!(
            stderr.contains("--galerkin") && stderr.contains(needle),
            "{value:?}: {stderr}"
        );
    }
    let (code, stderr, _) = run("one_level.obj", &["--galerkin", "1", "--levels", "1"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("--levels"), "{stderr}");
}
