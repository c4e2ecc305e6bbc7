//! The crate's integration tests, one module per subject, in one test binary
//! (one link and one copy of the generic code instead of one per file).

#[path = "../common/mod.rs"]
mod common;

/// The fuzz targets' harness, shared by the fuzz regressions and the wire tests.
#[allow(dead_code)] // the harness also has helpers only the fuzz targets use
#[path = "../../../../fuzz/src/core_harness.rs"]
mod harness;

mod check_order;
mod cholesky_bits;
mod closed_form;
mod closed_form_diagonal;
mod ekf_chained;
mod ekf_products;
mod errors;
mod examples;
mod fast_contribution;
mod fast_trig;
mod fusion;
mod fusion_rules;
mod fuzz_regressions;
mod gate;
mod models;
mod network;
mod oracles;
mod phases;
mod proptests;
mod readme;
mod split;
mod thresholds;
mod time;
mod trig;
mod triggers;
mod wire;
