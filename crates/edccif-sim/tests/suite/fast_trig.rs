//! The scenario's fast trigonometry (the default) (`Scenario::fast_trig`) against the
//! reference path on whole runs of every row: the same discrete events, per-step
//! estimates within 1e-10 relative, position RMSE within 1e-12 relative (measured
//! with the `atan2`/`sin_cos` kernel: at most 2.3e-13 and 1.5e-14; run with
//! `--nocapture` for each row's figures).

use crate::common;

use common::run_difference;
use edccif_sim::{run, simulate, Algorithm, MeasurementSpec, MotionSpec, RunOptions, Scenario};

#[test]
fn fast_trig_stays_within_stated_bounds_of_the_reference_path() {
    let reference = Scenario {
        fast_trig: false,
        ..Scenario::paper(4)
    };
    let fast = Scenario {
        fast_trig: true,
        ..reference.clone()
    };
    let sim = simulate(&reference, 1).unwrap();
    let opt = RunOptions::default();
    for alg in Algorithm::ALL {
        let a = run(alg, &reference, &sim.z, &sim.x0_hat, &opt, false).unwrap();
        let b = run(alg, &fast, &sim.z, &sim.x0_hat, &opt, false).unwrap();
        // Discrete events (trigger decisions) unchanged on this run.
        assert_eq!(a.triggered, b.triggered, "{alg:?}: trigger decisions");
        // Per step: every estimate entry within 1e-10 relative (scale ≥ 1 m, m/s,
        // rad/s); whole run: position RMSE within 1e-12 relative.
        let (worst, ra, rb) = run_difference(&a, &b, &sim);
        assert!(
            worst < 1e-10,
            "{alg:?}: largest per-step difference {worst:e}"
        );
        eprintln!(
            "{alg:?}: per-step max rel diff {worst:.2e}, pos RMSE {ra:.12} vs {rb:.12} (rel {:.2e})",
            (ra - rb).abs() / ra
        );
        assert!(
            (ra - rb).abs() <= 1e-12 * ra,
            "{alg:?}: position RMSE {ra} (reference) vs {rb} (fast)"
        );
        // And the fast path is not the reference path under another name (the
        // EKF's too: its h(x) and f(x), F(x) take the kernel's atan2, sin_cos).
        assert_ne!(a.estimates, b.estimates, "{alg:?}: fast path not taken");
    }
}

#[test]
fn fast_trig_is_on_by_default_and_serialised_only_when_off() {
    let sc = Scenario::paper(3);
    assert!(sc.fast_trig);
    assert!(sc.coordinated_turn().unwrap().fast_trig());
    let json = serde_json::to_string(&sc).unwrap();
    assert!(!json.contains("fast_trig"));
    let off: Scenario =
        serde_json::from_str(&json.replacen('{', "{\"fast_trig\":false,", 1)).unwrap();
    assert!(!off.fast_trig);
    assert!(!off.coordinated_turn().unwrap().fast_trig());
    assert!(serde_json::to_string(&off)
        .unwrap()
        .contains("\"fast_trig\":false"));
    // A scenario whose models have no fast path takes the default and ignores it.
    let cv = Scenario {
        motion: MotionSpec::ConstantVelocity { q: 0.5, dim: 3 },
        measurement: Some(MeasurementSpec::Position { sigma: [0.1; 3] }),
        x0: vec![5.0, 0.0, 1.0, 0.0, 1.5, 0.1],
        p0_diag: vec![0.01; 6],
        ..Scenario::paper(3)
    };
    assert!(cv.fast_trig);
    cv.validate().unwrap();
    let sim = simulate(&cv, 0).unwrap();
    let a = run(
        Algorithm::EdcCif,
        &cv,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
        false,
    );
    let off = Scenario {
        fast_trig: false,
        ..cv.clone()
    };
    let b = run(
        Algorithm::EdcCif,
        &off,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
        false,
    );
    assert_eq!(a.unwrap().estimates, b.unwrap().estimates);
}
