//! Fuzzes the survey .def reader: any bytes parse or give an error, never a panic.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = dend::mesh::io::survey::parse_def(data);
});
