//! `cov_local` for the CKF, EKF and UKF with fuzzed inputs.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| edccif_fuzz::cov_local_case(data));
