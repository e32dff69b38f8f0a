//! Fuzzes the WebSocket message decoder (JSON → `ClientMsg` → validated
//! drag delta); never a panic (replayed by `tests/it/fuzz_replay.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    dend_server::fuzzing::ws_message(data);
});
