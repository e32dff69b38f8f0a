//! Fuzzes the binary pose frame decoder (versions 2 and 3, as clients
//! read frames); never a panic (replayed by `tests/it/fuzz_replay.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dend_server::fuzzing::pose_frame(data);
});
