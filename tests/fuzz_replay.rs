//! Replays the fuzz corpus kept in `tests/data/fuzz/<target>/` (seeds,
//! interesting inputs found by `cargo fuzz`, crash reproducers) through the
//! same entry points as the fuzz targets, so CI covers them without a
//! fuzzer. Files named `ok_*` must be accepted; every other one must be
//! refused with an error (and nothing may panic).

use std::path::PathBuf;

fn corpus(target: &str) -> Vec<(String, Vec<u8>)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(target);
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(Result::ok)
        .map(|e| {
            (
                e.file_name().to_string_lossy().into_owned(),
                std::fs::read(e.path()).unwrap_or_default(),
            )
        })
        .collect();
    files.sort();
    assert!(files.len() >= 5, "corpus of {target} is missing");
    files
}

fn replay(target: &str, f: fn(&[u8]) -> bool) {
    for (name, data) in corpus(target) {
        let accepted = f(&data);
        if name.starts_with("ok_") {
            assert!(accepted, "{target}/{name} must be accepted");
        } else if !name.starts_with("any_") {
            assert!(!accepted, "{target}/{name} must be refused");
        }
    }
}

#[test]
fn constraints_json_corpus() {
    replay("constraints_json", dend::fuzzing::constraints_json);
}

#[test]
fn ws_message_corpus() {
    replay("ws_message", dend::fuzzing::ws_message);
}
