//! Fuzzes the Stl reader: any bytes parse or give an error, never a panic.
#![no_main]
use dend::mesh::io::{parse_bytes, Format};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(raw) = parse_bytes(data, Format::Stl) {
        let _ = raw.into_mesh();
    }
});
