//! The examples run as tests, so they cannot drift from the API.

#[allow(dead_code)]
#[path = "../../examples/custom_model.rs"]
mod custom_model;

/// The custom-model example tracks its target: final position error below 0.2 m
/// (σ = 5 cm ranges to beacons 20 m apart; the filter's own position standard
/// deviation is a few centimetres), and the send-on-delta trigger both sends and
/// stays silent at some steps.
#[test]
fn custom_model_example_tracks_its_target() {
    let (error, rate) = custom_model::run().unwrap();
    assert!(error < 0.2, "final position error {error} m");
    assert!(rate > 0.0 && rate < 1.0, "trigger rate {rate}");
}
