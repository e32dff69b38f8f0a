//! Runs the built `dend` binary: `gen`, `info`, and exit code 2 on errors.

use std::path::Path;
use std::process::Command;

fn dend(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_dend"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn gen_bar_then_info_reports_856_vertices_closed_genus_0() {
    let dir = tempfile::tempdir().unwrap();
    let bar = dir.path().join("bar.obj");
    let bar = bar.to_str().unwrap();
    let (code, _, err) = dend(&["gen", "bar", "-o", bar]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = dend(&["info", bar]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("vertices:    856"), "{out}");
    assert!(out.contains("boundary:    closed"), "{out}");
    assert!(out.contains("components:  1"), "{out}");
    assert!(out.contains("genus:       0"), "{out}");
    assert!(out.contains("validation:  ok"), "{out}");
    let (code, out, _) = dend(&["info", "--json", bar]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["vertices"], 856);
    assert_eq!(v["genus"], 0);
    assert_eq!(v["boundary_loops"], 0);
}

#[test]
fn gen_every_shape_in_every_format() {
    let dir = tempfile::tempdir().unwrap();
    for (shape, nv, loops) in [
        ("cylinder", 1088, 2),
        ("flag", 289, 1),
        ("plane", 2115, 1),
        ("bumpy-plane", 2115, 1),
        ("torus", 576, 0),
        ("saddle", 2025, 1),
        ("wavy-sheet", 2025, 1),
    ] {
        for ext in ["obj", "off", "ply", "stl"] {
            let f = dir.path().join(format!("{shape}.{ext}"));
            let f = f.to_str().unwrap();
            let mut args = vec!["gen", shape, "-o", f];
            if ext == "stl" {
                args.push("--ascii"); // exact coordinates, so welding restores the vertices
            }
            assert_eq!(dend(&args).0, 0, "{shape}.{ext}");
            let (code, out, err) = dend(&["info", "--json", f]);
            assert_eq!(code, 0, "{shape}.{ext}: {err}");
            let v: serde_json::Value = serde_json::from_str(&out).unwrap();
            assert_eq!(v["vertices"], nv, "{shape}.{ext}");
            assert_eq!(v["boundary_loops"], loops, "{shape}.{ext}");
        }
    }
    let f = dir.path().join("small.off");
    let (code, _, err) = dend(&[
        "gen",
        "torus",
        "--nu",
        "5",
        "--nv",
        "4",
        "-o",
        f.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let (_, out, _) = dend(&["info", f.to_str().unwrap()]);
    assert!(
        out.contains("vertices:    20") && out.contains("genus:       1"),
        "{out}"
    );
}

#[test]
fn errors_exit_with_code_2_not_101() {
    let broken = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/broken");
    for f in [
        "truncated.off",
        "nonmanifold.ply",
        "garbage.stl",
        "nan.obj",
        "empty.obj",
    ] {
        let (code, _, err) = dend(&["info", broken.join(f).to_str().unwrap()]);
        assert_eq!(code, 2, "{f}: {err}");
        assert!(err.starts_with("error: "), "{f}: {err}");
    }
    let (code, _, err) = dend(&["info", "/nonexistent/mesh.obj"]);
    assert_eq!(code, 2, "{err}");
    let (code, _, err) = dend(&["info", "mesh.xyz"]);
    assert_eq!(code, 2, "{err}");
    let dir = tempfile::tempdir().unwrap();
    let (code, _, err) = dend(&[
        "gen",
        "torus",
        "--size2",
        "5",
        "-o",
        dir.path().join("t.obj").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    let (code, _, _) = dend(&["gen", "sphere", "-o", "x.obj"]);
    assert_eq!(code, 2);
}

/// A missing file is reported once: its path and the system's reason each
/// appear a single time, for every command that reads a mesh or a survey
/// file (they read "reading X: X: No such file …: No such file …" before).
#[test]
fn a_missing_file_is_named_once() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.obj");
    let missing = missing.to_str().unwrap();
    let sel = dir.path().join("missing.sel");
    let sel = sel.to_str().unwrap();
    let bar = dir.path().join("bar.obj");
    let bar = bar.to_str().unwrap();
    assert_eq!(dend(&["gen", "bar", "-o", bar]).0, 0);
    let out = dir.path().join("out.obj");
    let out = out.to_str().unwrap();
    for (args, path) in [
        (vec!["info", missing], missing),
        (
            vec![
                "deform",
                missing,
                "--constraints",
                "examples/bar-twist-135.json",
                "-o",
                out,
            ],
            missing,
        ),
        (vec!["measure", missing, bar, "--bar", "0", "1"], missing),
        (
            vec!["deform", bar, "--sel", sel, "--def", sel, "-o", out],
            sel,
        ),
    ] {
        let (code, _, err) = dend(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert_eq!(err.matches(path).count(), 1, "{args:?}: {err}");
        assert_eq!(err.matches("os error").count(), 1, "{args:?}: {err}");
    }
}

/// An invalid mesh is reported once: the validation's reason appears a
/// single time and "invalid mesh" is not repeated by the layers it passes
/// through (the reader's error, the command's own context).
#[test]
fn an_invalid_mesh_says_why_once() {
    let dir = tempfile::tempdir().unwrap();
    // a triangle referring to a vertex the file does not have
    let bad_off = dir.path().join("bad.off");
    std::fs::write(&bad_off, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n").unwrap();
    // a zero-area triangle, and an index past the vertices, as OBJs (read
    // as assets by `deform`)
    let flat_obj = dir.path().join("flat.obj");
    std::fs::write(&flat_obj, "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").unwrap();
    let bad_obj = dir.path().join("bad.obj");
    std::fs::write(&bad_obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let out = dir.path().join("out.obj");
    let (bad_off, flat_obj, bad_obj, out) = (
        bad_off.to_str().unwrap(),
        flat_obj.to_str().unwrap(),
        bad_obj.to_str().unwrap(),
        out.to_str().unwrap(),
    );
    let constraints = "examples/bar-twist-135.json";
    for (args, cause) in [
        (vec!["info", bad_off], "refers to vertex 7"),
        (vec!["info", flat_obj], "has zero area"),
        (vec!["info", bad_obj], "refers to vertex 8"),
        (
            vec!["deform", bad_off, "--constraints", constraints, "-o", out],
            "refers to vertex 7",
        ),
        (
            vec!["deform", bad_obj, "--constraints", constraints, "-o", out],
            "refers to vertex 8",
        ),
    ] {
        let (code, _, err) = dend(&args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert_eq!(err.matches(cause).count(), 1, "{args:?}: {err}");
        assert!(err.matches("invalid mesh").count() <= 1, "{args:?}: {err}");
    }
}
