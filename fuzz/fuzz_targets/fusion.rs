//! The fusion functions: adaptation, CI / information / convex combination,
//! a consensus iteration and optimal-weight CI, on fuzzed information pairs,
//! estimates and weights.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| edccif_fuzz::fusion_case(data));
