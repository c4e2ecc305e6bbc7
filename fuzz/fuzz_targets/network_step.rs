//! A few `network_step`s of 1–4 nodes with fuzzed graph, weights, masks,
//! observations and configuration. On error no node state may change; on success
//! every active node's estimate is finite and PD.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| edccif_fuzz::network_step_case(data));
