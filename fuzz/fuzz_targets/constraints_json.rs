//! Fuzzes the constraints JSON: parse as a `ConstraintsSpec` and resolve it
//! on a small mesh; any bytes give a spec or a typed error, never a panic
//! (replayed by `tests/it/fuzz_replay.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dend_server::fuzzing::constraints_json(data);
});
