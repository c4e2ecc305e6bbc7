//! The MCAP readers on arbitrary bytes: `edccif_io::mcap_io::read_measurements`
//! (edccif's JSON topics) and `edccif_io::ros2::read_ros2` (CDR messages of every
//! supported type), both through the `mcap` crate with zstd and lz4 chunks. No
//! panic; an accepted file has consistent shapes, increasing times and finite
//! positions.
#![no_main]
use edccif_io::mcap_io::read_measurements;
use edccif_io::ros2::{read_ros2, Source};
use libfuzzer_sys::fuzz_target;

fn src(topic: &str, frame: Option<&str>) -> Source {
    Source {
        topic: topic.into(),
        frame: frame.map(Into::into),
    }
}

fuzz_target!(|data: &[u8]| {
    if let Ok(r) = read_measurements(data) {
        assert_eq!(r.t_ns.len(), r.steps);
        assert_eq!(r.z.len(), r.steps * r.nodes * 3);
        assert_eq!(r.triggered.len(), r.steps * r.nodes);
        assert!(r.t_ns.windows(2).all(|w| w[0] < w[1]));
    }
    // Topics of the seed bags (tests/ros2.rs, `edccif simulate --ros2`).
    let m = [
        src("/drone1/target", None),
        src("/drone2/target", Some("cam2")),
        src("/drone3/target", None),
        src("/odom", None),
        src("/node0/point", None),
    ];
    let truth = src("/tf", Some("vicon/target"));
    for k in [1, m.len()] {
        if let Ok(rec) = read_ros2(data, &m[..k], Some(&truth)) {
            for s in rec.measurements.iter().chain(rec.truth.iter().map(|t| &t.1)) {
                assert_eq!(s.t_ns.len(), s.p.len());
                assert!(s.t_ns.windows(2).all(|w| w[0] < w[1]));
                assert!(s.p.iter().flatten().all(|v| v.is_finite()));
            }
            if let Ok(rows) = rec.on_stamps() {
                assert_eq!(rows.z.len(), rows.steps * rows.nodes * 3);
                assert!(rows.t_ns.windows(2).all(|w| w[0] < w[1]));
            }
            // Frames (the file's /tf and /tf_static) and the messages' noise.
            let position = vec![true; rec.measurements.len()];
            let opt = edccif_io::replay_input::InputOptions::default();
            if let Ok(input) = edccif_io::replay_input::prepare(&rec, &opt, &position) {
                let rows = &input.rows;
                assert_eq!(rows.cov.len(), rows.steps * rows.nodes * 9);
                assert!(rows.z.iter().all(|v| v.is_finite() || v.is_nan()));
            }
        }
    }
});
