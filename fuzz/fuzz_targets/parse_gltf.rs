//! Fuzzes the glTF/GLB asset reader (container, document, accessors, weld,
//! validation) and its export: any bytes give an asset or a typed error,
//! never a panic (replayed by `tests/it/fuzz_replay.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dend_server::fuzzing::gltf_asset(data);
});
