//! Regression tests for the inputs `cargo fuzz` (fuzz/) found, each replayed
//! through the fuzz targets' own harness (`fuzz/src/core_harness.rs`, included
//! here) and read from the crash files `cargo fuzz` wrote:
//!
//! - `cov_local`: badly scaled inputs made `P⁻ − K Pxzᵀ` indefinite by
//!   cancellation and it was returned → `cov_local` now factorises its posterior.
//! - `cif_local`: `ŷ⁻ = Y⁻ x̂⁻` overflowed to ∞ with a finite `Y⁻` → now checked.
//! - `fusion`: `combine_information` returned non-finite sums → now checked
//!   (also `combine_convex`, which now factorises its result).
//! - `network_step`: a fused covariance from `InfoPair::to_gaussian` of a badly
//!   conditioned `Y` was indefinite → `to_gaussian` now factorises `P = Y⁻¹`.
//!   (`70979f67` was a harness bug — comparing NaN states with `==` — kept as a
//!   check that a failed step leaves the nodes bit-for-bit unchanged.)

use crate::harness;
use harness::*;

#[test]
fn cif_local_regressions() {
    cif_local_case(include_bytes!(
        "../../../../fuzz/artifacts/cif_local/crash-74c5ae2351a4d9cec262f055af76215f56e48f8d"
    ));
}

#[test]
fn cov_local_regressions() {
    cov_local_case(include_bytes!(
        "../../../../fuzz/artifacts/cov_local/crash-d9d1704cc174391186a0b680cfe0fb56446a0560"
    ));
}

#[test]
fn fusion_regressions() {
    fusion_case(include_bytes!(
        "../../../../fuzz/artifacts/fusion/crash-0860408ae2b47e4082e462dc60e26fe315e1a5a4"
    ));
}

#[test]
fn network_step_regressions() {
    network_step_case(include_bytes!(
        "../../../../fuzz/artifacts/network_step/crash-3a80a97dd6071b059f37bbdad2167de20c6ddb80"
    ));
    network_step_case(include_bytes!(
        "../../../../fuzz/artifacts/network_step/crash-70979f677ce1bb7ba9132e1d41b9c43bb22306be"
    ));
}
