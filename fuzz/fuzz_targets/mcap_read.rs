//! `edccif_io::mcap_io::read_measurements` on arbitrary bytes: no panic, and an
//! accepted file has consistent shapes and increasing times.
#![no_main]
use edccif_io::mcap_io::read_measurements;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(r) = read_measurements(data) {
        assert_eq!(r.t_ns.len(), r.steps);
        assert_eq!(r.z.len(), r.steps * r.nodes * 3);
        assert_eq!(r.triggered.len(), r.steps * r.nodes);
        assert!(r.t_ns.windows(2).all(|w| w[0] < w[1]));
    }
});
