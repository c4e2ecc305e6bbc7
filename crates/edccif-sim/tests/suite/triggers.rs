//! Triggers selected by name (`trigger=`): every one runs on every row family,
//! `sod` is the rows' own trigger bit for bit, the stochastic trigger is
//! reproducible from its seed, and the innovation trigger's feedback is counted.

use edccif_sim::{
    monte_carlo, run, simulate, Algorithm, McSettings, RunOptions, Scenario, TriggerKind, Variant,
};

fn opts(t: TriggerKind, delta: Option<f64>, seed: Option<u64>) -> RunOptions {
    RunOptions {
        trigger: Some(t),
        delta: delta.map(Into::into),
        trigger_seed: seed,
        ..RunOptions::default()
    }
}

#[test]
fn every_trigger_runs_on_diffusion_and_consensus_rows() {
    let mut sc = Scenario::paper(4);
    sc.steps = 60;
    let sim = simulate(&sc, 3).unwrap();
    for t in TriggerKind::ALL {
        for alg in [Algorithm::EdcCif, Algorithm::EcCkf, Algorithm::EcEkf] {
            let r = run(alg, &sc, &sim.z, &sim.x0_hat, &opts(t, None, None), false).unwrap();
            assert!(r.estimates.iter().all(|v| v.is_finite()), "{t} on {alg}");
            let rate = r.trigger_rate();
            assert!(rate > 0.0 && rate <= 1.0, "{t} on {alg}: rate {rate}");
            if t == TriggerKind::Always {
                assert_eq!(rate, 1.0);
            }
        }
    }
}

#[test]
fn named_sod_is_the_rows_own_trigger_bit_for_bit() {
    let sc = Scenario::paper(4);
    let sim = simulate(&sc, 5).unwrap();
    for (alg, t) in [
        (Algorithm::EdcCif, TriggerKind::Sod),
        (Algorithm::DecCkf, TriggerKind::Dynamic),
    ] {
        let own = run(alg, &sc, &sim.z, &sim.x0_hat, &RunOptions::default(), true).unwrap();
        let named = run(alg, &sc, &sim.z, &sim.x0_hat, &opts(t, None, Some(9)), true).unwrap();
        assert_eq!(own.estimates, named.estimates);
        assert_eq!(own.covariances, named.covariances);
        assert_eq!(own.triggered, named.triggered);
    }
    // sod-hold / sod-skip are the ablation policies
    let hold = RunOptions {
        et_policy: Some(edccif_core::EtPolicy::Hold),
        ..RunOptions::default()
    };
    let a = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &hold, false).unwrap();
    let b = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &opts(TriggerKind::SodHold, None, None),
        false,
    )
    .unwrap();
    assert_eq!(a.estimates, b.estimates);
}

#[test]
fn stochastic_trigger_is_reproducible_from_its_seed() {
    let mut sc = Scenario::paper(4);
    sc.steps = 80;
    let sim = simulate(&sc, 1).unwrap();
    let go = |seed| {
        run(
            Algorithm::EdcCif,
            &sc,
            &sim.z,
            &sim.x0_hat,
            &opts(TriggerKind::Stochastic, Some(3.0), Some(seed)),
            false,
        )
        .unwrap()
    };
    let (a, b, c) = (go(7), go(7), go(8));
    assert_eq!(a.estimates, b.estimates);
    assert_eq!(a.triggered, b.triggered);
    assert_ne!(a.triggered, c.triggered);
    // Monte Carlo keys the streams by the run's seed: same seeds, same numbers,
    // whatever the thread count.
    let v = [Variant {
        label: "stochastic".into(),
        algorithm: Algorithm::EdcCif,
        options: opts(TriggerKind::Stochastic, Some(3.0), None),
    }];
    let s = McSettings {
        runs: 3,
        seed: 4,
        progress: false,
    };
    let m1 = monte_carlo(&sc, &v, &s).unwrap();
    let m2 = monte_carlo(&sc, &v, &s).unwrap();
    assert_eq!(m1.variants[0].errors, m2.variants[0].errors);
}

#[test]
fn innovation_trigger_counts_its_feedback() {
    let mut sc = Scenario::paper(4);
    sc.steps = 30;
    let sim = simulate(&sc, 2).unwrap();
    let r = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &opts(TriggerKind::Innovation, None, None),
        false,
    )
    .unwrap();
    // (ẑ, Pzz): 3 + 6 floats per node-step with a measurement
    assert_eq!(r.counters.values_estimator_to_sensor, 9 * 4 * 30);
    let sod = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
        false,
    )
    .unwrap();
    assert_eq!(sod.counters.values_estimator_to_sensor, 0);
}

#[test]
fn unknown_trigger_names_the_choices() {
    let e = "stochastc".parse::<TriggerKind>().unwrap_err().to_string();
    for n in TriggerKind::NAMES {
        assert!(e.contains(n), "{e}");
    }
}
