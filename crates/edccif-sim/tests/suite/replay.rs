//! What a replay runs: a scenario's network equals the run it replays, bit for
//! bit, and a stored run decides the scenario unless a different one is given
//! with the override.

use edccif_sim::recording::StoredRun;
use edccif_sim::replay::{check_position_scenario, resolve_stored, scenario_network};
use edccif_sim::{simulate, Algorithm, RunOptions, Scenario};

#[test]
fn a_scenario_network_equals_run_with_dt_bit_for_bit() {
    let mut sc = Scenario::paper(4);
    sc.steps = 40;
    let sim = simulate(&sc, 3).unwrap();
    let dt: Vec<f64> = (0..40).map(|k| 0.05 + 0.002 * (k % 7) as f64).collect();
    for alg in Algorithm::ALL {
        let opt = RunOptions::default();
        let a = edccif_sim::run_with_dt(alg, &sc, &sim.z, &dt, &sim.x0_hat, &opt, true).unwrap();
        let mut net = scenario_network(alg, &sc, &sim.x0_hat, &opt).unwrap();
        let b = net.run(&sim.z, &dt, None).unwrap();
        assert_eq!(a.estimates, b.estimates, "{alg}");
        assert_eq!(a.covariances, b.covariances, "{alg}");
        assert_eq!(a.triggered, b.triggered, "{alg}");
    }
}

#[test]
fn stored_runs_and_given_scenarios() {
    let sc = Scenario::paper(3);
    let st = StoredRun::new(&sc, Algorithm::EcCkf, &RunOptions::default(), 4, &sc.x0);
    let r = resolve_stored("f", Some(&st), None, None, &RunOptions::default(), false).unwrap();
    assert_eq!(
        (r.algorithm, r.scenario.clone()),
        (Algorithm::EcCkf, sc.clone())
    );
    let mut other = sc.clone();
    other.sensors[0][0] += 1.0;
    let e = resolve_stored(
        "f",
        Some(&st),
        Some(&other),
        None,
        &RunOptions::default(),
        false,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("--override") && e.contains("sensors"), "{e}");
    let r = resolve_stored(
        "f",
        Some(&st),
        Some(&other),
        None,
        &RunOptions::default(),
        true,
    )
    .unwrap();
    assert_eq!(r.scenario, other);
    let e = resolve_stored("f", None, None, None, &RunOptions::default(), false)
        .unwrap_err()
        .to_string();
    assert!(e.contains("no default geometry"), "{e}");
    assert!(check_position_scenario(&sc, false).is_err());
    assert!(check_position_scenario(&sc, true).is_ok());
}
