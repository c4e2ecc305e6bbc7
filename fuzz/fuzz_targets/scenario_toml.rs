//! `Scenario::from_toml_str` on arbitrary text; an accepted scenario validates,
//! round-trips through TOML and builds its sensors and weights.
#![no_main]
use edccif_sim::Scenario;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(sc) = Scenario::from_toml_str(text) {
        sc.validate().expect("accepted scenario must validate");
        sc.sensor_models().expect("sensors of an accepted scenario");
        let w = sc.weights().expect("weights of an accepted scenario");
        assert!(w.iter().all(|v| v.is_finite() && *v >= 0.0));
        if sc.nodes() <= 16 {
            sc.consensus_iterations()
                .expect("L of an accepted scenario");
        }
        let back = Scenario::from_toml_str(&sc.to_toml().expect("to_toml")).expect("round trip");
        assert_eq!(back.nodes(), sc.nodes());
    }
});
