//! Fuzzes the Stl reader and the mesh validation after it: any bytes give
//! a mesh or a typed error, never a panic (replayed by `tests/it/fuzz_replay.rs`).
#![no_main]
use dend::mesh::io::Format;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dend_server::fuzzing::mesh_file(data, Format::Stl);
});
