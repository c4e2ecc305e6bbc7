//! The wire-format decoder (`edccif_core::wire::decode`) on arbitrary bytes, and
//! encode → decode of packets built from the fuzzer's values.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| edccif_fuzz::wire_case(data));
