//! `cif_local` on the default models with fuzzed parameters, estimate,
//! measurement, trigger and options.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| edccif_fuzz::cif_local_case(data));
