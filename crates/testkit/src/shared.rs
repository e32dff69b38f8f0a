//! What the tests find beside them: the repository, the public meshes, the
//! test venv's Python; and the skip log that says what could not run.

use std::path::{Path, PathBuf};

use dend::mesh::Mesh;

/// The repository root (the root package's folder).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Prints a skip and appends it, with the test's name, to the file named by
/// `DEND_SKIP_LOG` (`scripts/test.sh` prints that file as the run's skip
/// summary: cargo hides a passing test's output).
pub fn record_skip(why: &str) {
    let test = std::thread::current().name().unwrap_or("?").to_owned();
    eprintln!("skipping {test}: {why}");
    if let Ok(path) = std::env::var("DEND_SKIP_LOG") {
        use std::io::Write;
        if let Ok(mut f) = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
        {
            let _ = writeln!(f, "{test}: {why}");
        }
    }
}

/// Whether this run is CI's (`CI=true`), where a missing tool is a failure.
pub fn under_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true")
}

/// The public meshes folder (`$DEND_MESHES`, default `../shared/meshes`
/// beside the repository), or `None` after recording that the caller skips
/// ([`record_skip`]). Under `CI=true` a missing folder is a failure (a
/// panic naming it): `.ci/run` provides the meshes, so CI never skips their
/// tests silently. Elsewhere the README makes them optional: their tests
/// skip (listed at the end of `scripts/test.sh`), and each has a
/// generated-mesh counterpart that always runs.
pub fn shared_meshes() -> Option<PathBuf> {
    let dir = std::env::var_os("DEND_MESHES")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join("../shared/meshes"));
    if dir.is_dir() {
        return Some(dir);
    }
    let why = format!("shared meshes not found at {}", dir.display());
    if under_ci() {
        panic!("{why} (CI=true: set DEND_MESHES to the public meshes)");
    }
    record_skip(&why);
    None
}

/// The public mesh `name`, read by the library, or `None` after a recorded
/// skip when the folder or the file is missing (a panic under `CI=true`,
/// as [`shared_meshes`]).
pub fn shared_mesh(name: &str) -> Option<Mesh> {
    let path = shared_meshes()?.join(name);
    if !path.is_file() {
        let why = format!("shared mesh {} not found", path.display());
        if under_ci() {
            panic!("{why} (CI=true)");
        }
        record_skip(&why);
        return None;
    }
    Some(read_mesh(&path))
}

/// Reads a mesh file with the library's reader (panics, naming the file, on
/// any error: for tests).
pub fn read_mesh(path: &Path) -> Mesh {
    dend::mesh::io::read_path(path).unwrap_or_else(|e| panic!("reading {}: {e}", path.display()))
}

/// Writes `mesh` with the library's writer, the format by the extension
/// (OFF coordinates round-trip exactly).
pub fn write_mesh(mesh: &Mesh, path: &Path) {
    dend::mesh::io::write_path(path, mesh)
        .unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
}

/// The test venv's Python (`DEND_PYTHON`, else `.venv/bin/python` in the
/// repository) if it can import every one of `modules`. Otherwise `None`
/// after a recorded skip, or a panic under `CI=true` (`scripts/setup-test-env.sh`
/// installs the venv, so a missing one must fail CI).
pub fn python_with(modules: &[&str]) -> Option<PathBuf> {
    let py = std::env::var_os("DEND_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| repo_root().join(".venv/bin/python"));
    let ok = std::process::Command::new(&py)
        .arg("-c")
        .arg(format!("import {}", modules.join(", ")))
        .output()
        .is_ok_and(|o| o.status.success());
    if ok {
        return Some(py);
    }
    let why = format!(
        "python {} with {} not usable (run scripts/setup-test-env.sh)",
        py.display(),
        modules.join(", ")
    );
    assert!(!under_ci(), "{why}; under CI=true it is required");
    record_skip(&why);
    None
}

/// The libigl oracle's Python ([`python_with`] `igl, numpy, scipy`).
pub fn oracle_python() -> Option<PathBuf> {
    python_with(&["igl", "numpy", "scipy"])
}
