//! Non-uniform time steps through the runner.

use edccif_sim::{
    dt_from_times, run, run_with_dt, simulate, simulate_with_dt, Algorithm, AnyNetwork, Error,
    RunOptions, Scenario,
};

/// Every step equal to the scenario's `dt` is the uniform run, bit for bit, for
/// every algorithm row.
#[test]
fn uniform_steps_are_the_uniform_run() {
    let sc = Scenario {
        steps: 60,
        ..Scenario::paper(4)
    };
    let sim = simulate(&sc, 5).unwrap();
    let dt = vec![sc.dt; sc.steps];
    for alg in Algorithm::ALL {
        let a = run(alg, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), true).unwrap();
        let b = run_with_dt(
            alg,
            &sc,
            &sim.z,
            &dt,
            &sim.x0_hat,
            &RunOptions::default(),
            true,
        )
        .unwrap();
        assert_eq!(a.estimates, b.estimates, "{alg:?}");
        assert_eq!(a.covariances, b.covariances, "{alg:?}");
    }
}

fn position_rmse(truth: &[f64], est: &[f64], nodes: usize, n: usize) -> f64 {
    let steps = truth.len() / n;
    let mut s = 0.0;
    for t in 0..steps {
        for i in 0..nodes {
            for a in 0..3 {
                let d = est[(t * nodes + i) * n + a] - truth[t * n + a];
                s += d * d;
            }
        }
    }
    (s / (steps * nodes) as f64).sqrt()
}

/// With jittered sampling (steps of 0.05–0.30 s), filtering with the true steps
/// is more accurate than pretending the steps were uniform, for EDC-CIF and EC-CKF
/// over 10 seeded runs.
#[test]
fn true_time_steps_beat_pretending_uniform() {
    let sc = Scenario::paper(4);
    let dt: Vec<f64> = (0..150)
        .map(|k| 0.05 + 0.05 * ((k * 7) % 6) as f64)
        .collect();
    let uniform = vec![sc.dt; dt.len()];
    for alg in [Algorithm::EdcCif, Algorithm::EcCkf] {
        let (mut right, mut wrong) = (0.0, 0.0);
        for seed in 0..10 {
            let sim = simulate_with_dt(&sc, seed, &dt).unwrap();
            let opt = RunOptions::default();
            let a = run_with_dt(alg, &sc, &sim.z, &dt, &sim.x0_hat, &opt, false).unwrap();
            let b = run_with_dt(alg, &sc, &sim.z, &uniform, &sim.x0_hat, &opt, false).unwrap();
            assert!(a.estimates.iter().all(|v| v.is_finite()));
            right += position_rmse(&sim.truth, &a.estimates, 4, 7);
            wrong += position_rmse(&sim.truth, &b.estimates, 4, 7);
        }
        assert!(
            right < wrong,
            "{alg:?}: true steps {right} vs uniform {wrong}"
        );
    }
}

/// Wrong lengths and bad steps are named errors; a bad step in the streaming API
/// leaves the network as it was.
#[test]
fn bad_time_steps_are_rejected() {
    let sc = Scenario {
        steps: 10,
        ..Scenario::paper(3)
    };
    let sim = simulate(&sc, 1).unwrap();
    let opt = RunOptions::default();
    let short = vec![0.1; 9];
    let e = run_with_dt(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &short,
        &sim.x0_hat,
        &opt,
        false,
    )
    .unwrap_err();
    assert!(matches!(e, Error::Shape { .. }), "{e}");
    assert!(e.to_string().contains("dt"), "{e}");
    let mut bad = vec![0.1; 10];
    bad[4] = -0.1;
    let e = run_with_dt(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &bad,
        &sim.x0_hat,
        &opt,
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("dt[4]"), "{e}");
    assert!(dt_from_times(&[0.1, 0.3, 0.2], 0.0)
        .unwrap_err()
        .to_string()
        .contains("t[2]"));
    assert!(simulate_with_dt(&sc, 0, &[0.1, f64::NAN]).is_err());

    let mut net = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
    net.step(&sim.z[..9]).unwrap();
    let mut before = vec![0.0; 3 * 7];
    net.write_estimates(&mut before);
    for dt in [0.0, f64::NAN, -1.0] {
        assert!(net.step_dt(&sim.z[9..18], dt).is_err());
    }
    let mut after = vec![0.0; 3 * 7];
    net.write_estimates(&mut after);
    assert_eq!(before, after);
    assert_eq!(net.counters().steps, 1);
}
