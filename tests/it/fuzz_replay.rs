//! Replays the fuzz corpus kept in `tests/data/fuzz/<target>/` (seeds,
//! interesting inputs found by `cargo fuzz`, crash reproducers) through the
//! same entry points as the fuzz targets, so CI covers them without a
//! fuzzer. Files named `ok_*` must be accepted, `any_*` may go either way,
//! every other one must be refused with an error; nothing may panic.
//! `tests/data/fuzz/<target>/corpus/` holds the minimised corpus of the last
//! campaign (`cargo fuzz cmin`, libFuzzer's SHA-1 names; see
//! docs/reliability.md): each file may be accepted or refused.

use std::path::{Path, PathBuf};

use dend::mesh::io::Format;

/// The regular files of `dir`, sorted by name.
fn files_in(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(Result::ok)
        .filter(|e| e.path().is_file())
        .map(|e| {
            let data = std::fs::read(e.path())
                .unwrap_or_else(|err| panic!("{}: {err}", e.path().display()));
            (e.file_name().to_string_lossy().into_owned(), data)
        })
        .collect();
    files.sort();
    files
}

fn replay(target: &str, f: fn(&[u8]) -> bool) {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(target);
    let named = files_in(&dir);
    assert!(named.len() >= 5, "corpus of {target} is missing");
    for (name, data) in named {
        let accepted = f(&data);
        if name.starts_with("ok_") {
            assert!(accepted, "{target}/{name} must be accepted");
        } else if !name.starts_with("any_") {
            assert!(!accepted, "{target}/{name} must be refused");
        }
    }
    let minimised = dir.join("corpus");
    if minimised.is_dir() {
        for (_, data) in files_in(&minimised) {
            // accepted or refused, but returns
            f(&data);
        }
    }
}

#[test]
fn constraints_json_corpus() {
    replay("constraints_json", dend_server::fuzzing::constraints_json);
}

#[test]
fn ws_message_corpus() {
    replay("ws_message", dend_server::fuzzing::ws_message);
}

#[test]
fn pose_frame_corpus() {
    replay("pose_frame", dend_server::fuzzing::pose_frame);
}

#[test]
fn parse_obj_corpus() {
    replay("parse_obj", |d| {
        dend_server::fuzzing::mesh_file(d, Format::Obj)
    });
}

#[test]
fn parse_off_corpus() {
    replay("parse_off", |d| {
        dend_server::fuzzing::mesh_file(d, Format::Off)
    });
}

#[test]
fn parse_ply_corpus() {
    replay("parse_ply", |d| {
        dend_server::fuzzing::mesh_file(d, Format::Ply)
    });
}

#[test]
fn parse_stl_corpus() {
    replay("parse_stl", |d| {
        dend_server::fuzzing::mesh_file(d, Format::Stl)
    });
}

#[test]
fn parse_gltf_corpus() {
    replay("parse_gltf", dend_server::fuzzing::gltf_asset);
}

#[test]
fn parse_sel_corpus() {
    replay("parse_sel", dend_server::fuzzing::sel_file);
}

#[test]
fn parse_def_corpus() {
    replay("parse_def", dend_server::fuzzing::def_file);
}
