//! A simulated run recorded as MCAP and replayed (the edccif JSON topics and the
//! ROS 2 topics give the measurements back bit for bit), and the real-world-like
//! Table IV analog end to end.

use edccif_io::mcap_io::{
    mcap_to_bytes, point_topic, read_measurements, ChunkCompression, McapWriteOptions,
    TOPIC_TRUTH_POINT,
};
use edccif_io::realworld::PathKind;
use edccif_io::ros2::{read_ros2, Source};
use edccif_sim::realworld::{evaluate_path, realworld_markdown, RealWorldTable, TableSettings};
use edccif_sim::recording::{mcap_run_data, run_recording};
use edccif_sim::{run, simulate, Algorithm, RunOptions, Scenario};

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
}

#[test]
fn a_recorded_run_replays_through_both_reading_paths() {
    let mut sc = Scenario::paper(4);
    sc.steps = 30;
    let mut sim = simulate(&sc, 3).unwrap();
    // Node 1 misses steps 5..8.
    for t in 5..8 {
        sim.z[(t * 4 + 1) * 3..(t * 4 + 2) * 3].fill(f64::NAN);
    }
    let (res, local) = run_recording(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
    )
    .unwrap();
    assert_eq!(local.len(), res.estimates.len());
    let data = mcap_run_data(&sc, &sim, &res, Some(&local)).unwrap();
    for compression in [ChunkCompression::Zstd, ChunkCompression::None] {
        let opt = McapWriteOptions {
            compression,
            ros2: true,
            ..McapWriteOptions::default()
        };
        let bytes = mcap_to_bytes(&data, &opt).unwrap();
        let r = read_measurements(&bytes).unwrap();
        assert_eq!((r.steps, r.nodes), (30, 4));
        assert!(same_bits(&r.z, &sim.z), "replayed z differs");
        assert_eq!(r.triggered.len(), res.triggered.len());
        let topics: Vec<Source> = (0..4)
            .map(|i| Source::parse(&point_topic(i)).unwrap())
            .collect();
        let truth = Source::parse(TOPIC_TRUTH_POINT).unwrap();
        let rows = read_ros2(&bytes, &topics, Some(&truth))
            .unwrap()
            .on_stamps()
            .unwrap();
        assert_eq!(rows.t_ns, r.t_ns);
        assert!(same_bits(&rows.z, &sim.z), "ROS 2 replay differs");
        let tr = rows.truth.unwrap();
        for t in 0..30 {
            assert_eq!(tr[t * 3..t * 3 + 3], sim.truth[t * sim.n..t * sim.n + 3]);
        }
        // The replayed measurements give the same run.
        let again = run(
            Algorithm::EdcCif,
            &sc,
            &rows.z,
            &sim.x0_hat,
            &RunOptions::default(),
            false,
        )
        .unwrap();
        assert!(same_bits(&again.estimates, &res.estimates));
    }
}

#[test]
fn realworld_table_runs_end_to_end() {
    let settings = TableSettings {
        seeds: vec![1],
        duration_s: Some(6.0),
        algorithms: vec![Algorithm::EcCkf, Algorithm::EdcCif],
        ..TableSettings::default()
    };
    let res = evaluate_path(PathKind::Circle, &settings).unwrap();
    assert_eq!(res.rows.len(), 2);
    for row in &res.rows {
        assert!(
            row.rmse_mm
                .iter()
                .all(|v| v.is_finite() && *v > 0.1 && *v < 50.0),
            "{row:?}"
        );
        assert!(row.trigger_rate > 0.0 && row.trigger_rate <= 1.0);
    }
    let table = RealWorldTable {
        settings,
        paths: vec![res],
    };
    let md = realworld_markdown(&table);
    assert!(md.contains("| State | EC-CKF | EDC-CIF |"));
    assert!(md.contains("| x (mm) |") && md.contains("**"));
    let json = serde_json::to_string(&table).unwrap();
    assert!(json.contains("\"rmse_mm\""));
    assert!("circle".parse::<PathKind>().is_ok() && "oval".parse::<PathKind>().is_err());
}
