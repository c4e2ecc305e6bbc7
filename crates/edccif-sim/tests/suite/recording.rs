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
fn a_recording_stores_its_run_and_replays_to_it_bit_for_bit() {
    use edccif_sim::recording::{StoredRun, STORED_RUN};
    use edccif_sim::replay::resolve_stored;
    let mut sc = Scenario::paper(3);
    sc.steps = 40;
    sc.sensors[1] = [-3.0, 8.0, 2.5];
    sc.dt = 0.05;
    let opt = RunOptions {
        trigger_seed: Some(11),
        ..RunOptions::default()
    };
    let sim = simulate(&sc, 8).unwrap();
    let (res, local) = run_recording(Algorithm::EdCif, &sc, &sim.z, &sim.x0_hat, &opt).unwrap();
    let data = mcap_run_data(&sc, &sim, &res, Some(&local)).unwrap();
    let mut wopt = McapWriteOptions::default();
    let stored = StoredRun::new(&sc, Algorithm::EdCif, &opt, 8, &sim.x0_hat);
    wopt.metadata
        .insert(STORED_RUN.into(), stored.to_metadata().unwrap());
    let bytes = mcap_to_bytes(&data, &wopt).unwrap();
    let back = read_measurements(&bytes).unwrap();
    let found = StoredRun::find(&back.metadata).unwrap().unwrap();
    assert_eq!(found, stored);
    assert!(same_bits(&found.x0, &sim.x0_hat));
    let r = resolve_stored("f", Some(&found), None, None, &RunOptions::default(), false).unwrap();
    let again = run(r.algorithm, &r.scenario, &back.z, &r.x0, &r.options, true).unwrap();
    assert!(same_bits(&again.estimates, &res.estimates));
    assert_eq!(again.triggered, res.triggered);
    // A damaged record is an error naming the key, not a silent default.
    let mut bad = stored.to_metadata().unwrap();
    bad.insert("x0".into(), "[1.0]".into());
    let e = StoredRun::from_metadata(&bad).unwrap_err().to_string();
    assert!(e.contains("`x0`"), "{e}");
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
