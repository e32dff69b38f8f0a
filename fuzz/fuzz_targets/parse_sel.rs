//! Fuzzes the survey .sel reader: any bytes parse or give a typed error,
//! never a panic (replayed by `tests/it/fuzz_replay.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dend_server::fuzzing::sel_file(data);
});
