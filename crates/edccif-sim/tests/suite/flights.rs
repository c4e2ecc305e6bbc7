//! Real flights as targets: the datasets' ground truths read from the data
//! directory (a clear error when missing), observers simulated around them, the
//! pipeline and the rows; the constant-acceleration model through the runner.

use edccif_io::flights::{Flight, FlightFile};
use edccif_io::realworld::{generate_following, PathKind, RealWorldConfig};
use edccif_io::{run_pipeline, Track};
use edccif_sim::realworld::{
    default_data_dir, evaluate_flight, flights_markdown, position_nees, realworld_scenario_with,
    FlightSettings, FlightTable, TableSettings,
};
use edccif_sim::{run, simulate, Algorithm, MotionSpec, RunOptions, Scenario};

#[test]
fn a_missing_data_directory_is_a_clear_error() {
    let dir = std::env::temp_dir().join("edccif-no-such-data-dir");
    let e = Flight::EurocV102.load(&dir).unwrap_err().to_string();
    assert!(e.contains("V102_groundtruth.csv"), "{e}");
    assert!(e.contains("--data-dir"), "{e}");
    let s = FlightSettings::new(&dir);
    let e = evaluate_flight(&FlightFile::known(Flight::TumFr1Xyz, &dir), &s)
        .unwrap_err()
        .to_string();
    assert!(e.contains("freiburg1_xyz-groundtruth.txt"), "{e}");
}

#[test]
fn the_flights_of_this_checkout_are_read() {
    let dir = default_data_dir();
    if !dir.join(Flight::EurocV102.file_name()).exists() {
        eprintln!("skipped: no data directory at {}", dir.display());
        return;
    }
    let v = Flight::EurocV102.load(&dir).unwrap();
    assert_eq!(v.len(), 16702);
    // 200 Hz, 83.5 s (ns stamps read as s: the period to better than 1 µs).
    assert!((v.t[1] - v.t[0] - 0.005).abs() < 1e-6);
    assert!((v.t[v.len() - 1] - v.t[0] - 83.505).abs() < 1e-3);
    assert_eq!(v.p[0], [0.515356, 1.996773, 0.971104]);
    let f = Flight::TumFr1Xyz.load(&dir).unwrap();
    assert_eq!(f.len(), 3000);
    assert_eq!(f.p[0], [1.3563, 0.6305, 1.6380]);
}

/// A 20 s helix sampled at 100 Hz.
fn helix() -> Track {
    let t: Vec<f64> = (0..=2000).map(|j| 1000.0 + j as f64 * 0.01).collect();
    let p = t
        .iter()
        .map(|&s| {
            let u = s - 1000.0;
            [2.0 * (0.4 * u).cos(), 2.0 * (0.4 * u).sin(), 1.0 + 0.02 * u]
        })
        .collect();
    Track::new(t, p).unwrap()
}

#[test]
fn observers_around_a_recorded_track_and_the_pipeline() {
    let target = helix();
    let cfg = RealWorldConfig::new(PathKind::Manual, 4);
    let rec = generate_following(&cfg, &target).unwrap();
    assert_eq!(rec, generate_following(&cfg, &target).unwrap()); // seeded
                                                                 // The truth is the track itself, on the motion capture's clock.
    assert_eq!(rec.truth.p, target.p);
    let off = rec.truth.t[0];
    assert!(rec
        .truth
        .t
        .iter()
        .zip(&target.t)
        .all(|(a, b)| (a - off - (b - 1000.0)).abs() < 1e-9));
    // The cameras stand 2.8–3.4 m beyond the horizontal extent around the centroid.
    let m = target.len() as f64;
    let c = [0, 1].map(|a| target.p.iter().map(|q| q[a]).sum::<f64>() / m);
    let extent = target
        .p
        .iter()
        .map(|q| ((q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2)).sqrt())
        .fold(0.0, f64::max);
    for pose in &rec.poses {
        let r = ((pose.position[0] - c[0]).powi(2) + (pose.position[1] - c[1]).powi(2)).sqrt();
        assert!(
            (2.8..3.4).contains(&(r - extent)),
            "camera {r} m from the centroid, extent {extent} m"
        );
    }
    // 30 Hz over 20 s, minus drops and stalls.
    assert!(rec.observers.iter().all(|o| (500..=640).contains(&o.len())));
    let data = run_pipeline(&rec.truth, &rec.observers, &Default::default()).unwrap();
    assert!(data.steps > 550);
    // The aligned measurements follow the helix within a few cm.
    let (mut acc, mut cnt) = (0.0, 0.0);
    for t in 0..data.steps {
        for i in 0..data.nodes {
            let z = &data.z[(t * data.nodes + i) * 3..(t * data.nodes + i) * 3 + 3];
            let x = &data.truth[t * 3..t * 3 + 3];
            if z.iter().chain(x).all(|v| v.is_finite()) {
                acc += (0..3).map(|c| (z[c] - x[c]).powi(2)).sum::<f64>();
                cnt += 1.0;
            }
        }
    }
    let rms = (acc / cnt).sqrt();
    assert!(rms < 0.08, "aligned measurement error {rms} m");
    // A track of one sample or going backwards is refused.
    let one = Track::new(vec![0.0], vec![[0.0; 3]]).unwrap();
    assert!(generate_following(&cfg, &one).is_err());
    let back = Track::new(vec![0.0, 1.0, 0.5], vec![[0.0; 3]; 3]).unwrap();
    assert!(generate_following(&cfg, &back)
        .unwrap_err()
        .to_string()
        .contains("strictly increasing"));
}

#[test]
fn every_motion_model_tracks_the_helix_and_nees_is_computed() {
    let target = helix();
    let rec = generate_following(&RealWorldConfig::new(PathKind::Manual, 2), &target).unwrap();
    let data = run_pipeline(&rec.truth, &rec.observers, &Default::default()).unwrap();
    let s = TableSettings::default();
    for (motion, n) in [
        (MotionSpec::ConstantVelocity { q: 0.5, dim: 3 }, 6),
        (MotionSpec::CoordinatedTurn { q1: 0.5, q2: 0.01 }, 7),
        (MotionSpec::ConstantAcceleration { q: 10.0, dim: 3 }, 9),
    ] {
        let (sc, x0) = realworld_scenario_with(&data, &s, motion.clone()).unwrap();
        assert_eq!((sc.state_dim(), x0.len(), sc.p0_diag.len()), (n, n, n));
        let r = run(
            Algorithm::EdcCif,
            &sc,
            &data.z,
            &x0,
            &RunOptions::default(),
            true,
        )
        .unwrap();
        assert_eq!(r.n, n);
        let e =
            edccif_sim::realworld::position_rmse(&r.estimates, &data.truth, r.steps, r.nodes, r.n);
        assert!(e.iter().all(|v| *v < 0.05), "{motion:?}: RMSE {e:?} m");
        let (nees, cnt) = position_nees(
            &r.estimates,
            &r.covariances,
            &data.truth,
            r.steps,
            r.nodes,
            r.n,
        );
        assert!(
            cnt > 3 * 500 && nees.is_finite() && nees > 0.3 && nees < 30.0,
            "{motion:?}: NEES {nees}"
        );
    }
}

#[test]
fn position_nees_of_a_known_error() {
    // One frame, one node, n = 6: e = (1, 2, 0), P_pp = diag(1, 4, 9) → 1 + 1 = 2.
    let est = [1.0, 2.0, 0.0, 9.0, 9.0, 9.0];
    let mut cov = [0.0; 36];
    for (j, v) in [1.0, 4.0, 9.0, 1.0, 1.0, 1.0].iter().enumerate() {
        cov[j * 6 + j] = *v;
    }
    assert_eq!(position_nees(&est, &cov, &[0.0; 3], 1, 1, 6), (2.0, 1));
    // An unknown truth is skipped.
    let (v, c) = position_nees(&est, &cov, &[f64::NAN; 3], 1, 1, 6);
    assert!(v.is_nan() && c == 0);
}

#[test]
fn constant_acceleration_scenarios_simulate_and_run() {
    let mut sc = Scenario::paper(3);
    sc.motion = MotionSpec::ConstantAcceleration { q: 0.1, dim: 3 };
    sc.x0 = vec![5.0, 0.0, 1.0, 0.0, 1.0, 0.1, 0.0, 0.0, 0.0];
    sc.p0_diag = vec![0.01; 9];
    sc.steps = 50;
    let sim = simulate(&sc, 1).unwrap();
    assert_eq!(sim.x0_hat.len(), 9);
    let r = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
        false,
    )
    .unwrap();
    assert_eq!((r.steps, r.n), (50, 9));
    assert!(r.estimates.iter().all(|v| v.is_finite()));
    let toml = sc.to_toml().unwrap();
    assert!(toml.contains("constant-acceleration"), "{toml}");
    assert_eq!(Scenario::from_toml_str(&toml).unwrap(), sc);
    sc.motion = MotionSpec::ConstantAcceleration { q: -1.0, dim: 3 };
    assert!(sc.validate().unwrap_err().to_string().contains("motion.q"));
}

#[test]
fn the_markdown_names_the_datasets_and_the_command() {
    let dir = default_data_dir();
    if !dir.join(Flight::TumFr1Xyz.file_name()).exists() {
        eprintln!("skipped: no data directory at {}", dir.display());
        return;
    }
    let mut s = FlightSettings::new(&dir);
    let tum = FlightFile::known(Flight::TumFr1Xyz, &dir);
    s.flights = vec![tum.clone()];
    s.table.seeds = vec![1];
    let f = evaluate_flight(&tum, &s).unwrap();
    assert_eq!(f.rows.len(), 6);
    assert_eq!(
        f.models
            .iter()
            .map(|m| m.model.as_str())
            .collect::<Vec<_>>(),
        ["CV", "CT", "CA"]
    );
    let md = flights_markdown(&FlightTable {
        settings: s,
        flights: vec![f],
    });
    for needle in [
        "Sturm",
        "freiburg1_xyz-groundtruth.txt",
        "--data-dir",
        "edccif-results",
        "position NEES",
    ] {
        assert!(md.contains(needle), "{needle}");
    }
}

/// A helix with some turns of speed, written as a TUM file and as a EuRoC CSV
/// (100 Hz, 12 s), sample 500's stamp repeated once.
fn write_files(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    std::fs::create_dir_all(dir).unwrap();
    let (mut tum, mut euroc) = (
        String::from("# t x y z qx qy qz qw\n"),
        String::from("#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z\n"),
    );
    for j in 0..1200 {
        let k = if j == 501 { 500 } else { j };
        let s = k as f64 * 0.01;
        let a = 0.4 * s + 0.2 * (0.7 * s).sin();
        let (x, y, z) = (2.0 * a.cos(), 2.0 * a.sin(), 1.0 + 0.02 * s);
        tum += &format!("{} {x} {y} {z} 0 0 0 1\n", 1_600_000_000.0 + s);
        euroc += &format!(
            "{},{x},{y},{z},1,0,0,0\n",
            1_600_000_000_000_000_000u64 + k as u64 * 10_000_000
        );
    }
    let (a, b) = (dir.join("lab_run.txt"), dir.join("lab_run.csv"));
    std::fs::write(&a, tum).unwrap();
    std::fs::write(&b, euroc).unwrap();
    (a, b)
}

#[test]
fn any_tum_or_euroc_ground_truth_is_a_flight() {
    use edccif_io::preprocess::DuplicateStamps;
    use edccif_sim::realworld::flight_table;
    let dir = std::env::temp_dir().join(format!("edccif-flights-{}", std::process::id()));
    let (tum, euroc) = write_files(&dir);
    for path in [&tum, &euroc] {
        let f = FlightFile::new(path);
        assert_eq!((f.known, f.name()), (None, "lab_run".to_string()));
        let (track, dup) = f.load(DuplicateStamps::Drop).unwrap();
        assert_eq!(
            (track.len(), dup.dropped, dup.removed.clone()),
            (1199, 1, vec![501])
        );
        let e = f.load(DuplicateStamps::Refuse).unwrap_err().to_string();
        assert!(
            e.contains("lab_run") && e.contains("t[501]") && e.contains("repeats t[500]"),
            "{e}"
        );
    }
    let mut s = FlightSettings::from_files(vec![FlightFile::new(&tum)]);
    s.table.seeds = vec![1];
    let t = flight_table(&s).unwrap();
    assert_eq!(t.flights[0].duplicates_dropped, 1);
    let md = flights_markdown(&t);
    assert!(md.contains("`lab_run.txt` (lab_run): 1199 samples"), "{md}");
    assert!(
        md.contains("1 sample(s) with a repeated timestamp dropped"),
        "{md}"
    );
    assert!(
        md.contains(&format!("edccif reproduce --flight {}", tum.display())),
        "{md}"
    );
    // a file in neither format is refused with both formats named
    let bad = dir.join("notes.txt");
    std::fs::write(&bad, "# only a comment\n").unwrap();
    let e = FlightFile::new(&bad)
        .load(DuplicateStamps::Drop)
        .unwrap_err()
        .to_string();
    assert!(e.contains("TUM") && e.contains("EuRoC"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn reproduce_reads_every_flight_before_any_study() {
    use edccif_io::preprocess::DuplicateStamps;
    use edccif_sim::report::{reproduce, ReproduceSettings};
    let dir = std::env::temp_dir().join(format!("edccif-flights-first-{}", std::process::id()));
    let (tum, _) = write_files(&dir);
    // Node count 0 would fail the first Monte Carlo study: the flight's error
    // comes first, so no study ran.
    let s = ReproduceSettings {
        nodes: vec![0],
        runs: 1,
        flight_files: vec![tum.clone()],
        duplicates: DuplicateStamps::Refuse,
        ..ReproduceSettings::default()
    };
    let e = reproduce(&s).unwrap_err().to_string();
    assert!(e.contains("lab_run") && e.contains("repeats"), "{e}");
    let missing = ReproduceSettings {
        flight_files: vec![dir.join("no-such-file.txt")],
        ..s
    };
    let e = reproduce(&missing).unwrap_err().to_string();
    assert!(e.contains("no-such-file.txt"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}
