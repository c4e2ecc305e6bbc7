//! Fault injection: no faults = `run`, seeded and independent of the data,
//! dropout/rejoin, outages, outliers with and without the gate, bad fault specs,
//! and the reliability health checks on a short study.

use edccif_sim::faults::{run_with_faults, Faults, Window};
use edccif_sim::reliability::{checked_run, replace_block, standard_conditions};
use edccif_sim::{run, simulate, Algorithm, AnyNetwork, Error, RunOptions, Scenario};

fn short(n: usize) -> Scenario {
    Scenario {
        steps: 60,
        ..Scenario::paper(n)
    }
}

#[test]
fn no_faults_is_run_and_faults_are_seeded() {
    let sc = short(4);
    let sim = simulate(&sc, 3).unwrap();
    let o = RunOptions::default();
    for alg in [Algorithm::EdcCif, Algorithm::EcCkf] {
        let a = run(alg, &sc, &sim.z, &sim.x0_hat, &o, true).unwrap();
        let b =
            run_with_faults(alg, &sc, &sim.z, &sim.x0_hat, &o, &Faults::default(), true).unwrap();
        assert_eq!(a.estimates, b.estimates);
        assert_eq!(a.covariances, b.covariances);
        let f = Faults {
            seed: 9,
            message_loss: 0.3,
            outlier_prob: 0.1,
            ..Faults::default()
        };
        let c = run_with_faults(alg, &sc, &sim.z, &sim.x0_hat, &o, &f, true).unwrap();
        let d = run_with_faults(alg, &sc, &sim.z, &sim.x0_hat, &o, &f, true).unwrap();
        assert_eq!(c.estimates, d.estimates);
        assert_ne!(c.estimates, a.estimates);
        let e = run_with_faults(
            alg,
            &sc,
            &sim.z,
            &sim.x0_hat,
            &o,
            &Faults {
                seed: 10,
                ..f.clone()
            },
            true,
        )
        .unwrap();
        assert_ne!(c.estimates, e.estimates);
        // fewer messages delivered than without loss
        assert!(
            c.counters.values_estimator_to_estimator < a.counters.values_estimator_to_estimator
        );
    }
}

#[test]
fn dropout_outage_and_rejoin() {
    let sc = short(4);
    let sim = simulate(&sc, 4).unwrap();
    let (k, n) = (4, 7);
    let f = Faults {
        dropout: vec![Window {
            node: 1,
            start: 20,
            end: 40,
        }],
        outage: vec![Window {
            node: 0,
            start: 10,
            end: 30,
        }],
        ..Faults::default()
    };
    let r = run_with_faults(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
        &f,
        false,
    )
    .unwrap();
    let est = |t: usize, i: usize| &r.estimates[(t * k + i) * n..(t * k + i + 1) * n];
    // node 1 keeps its state while down, and neither measures
    for t in 20..40 {
        assert_eq!(est(t, 1), est(19, 1));
        assert!(!r.measured[t * k + 1]);
    }
    // node 0's sensor is out but it still fuses (its estimate moves)
    for t in 10..30 {
        assert!(!r.measured[t * k]);
    }
    assert_ne!(est(29, 0), est(10, 0));
    // on rejoin (step 40) node 1 starts from neighbour 0's fused estimate of step 39
    let mut net =
        AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &RunOptions::default()).unwrap();
    let mut inj = edccif_sim::faults::FaultInjector::new(&f, &sc).unwrap();
    let mut z = vec![0.0; k * 3];
    for t in 0..41 {
        z.copy_from_slice(&sim.z[t * k * 3..(t + 1) * k * 3]);
        inj.prepare(t, &mut z, &mut net).unwrap();
        if t == 40 {
            let mut e = vec![0.0; k * n];
            net.write_estimates(&mut e);
            assert_eq!(&e[n..2 * n], est(39, 0));
        }
        net.step_with_mask(&z, Some(inj.mask()), Some(&inj.active))
            .unwrap();
    }
    assert_eq!(inj.rejoins, 1);
}

#[test]
fn gate_defends_against_outliers() {
    let sc = short(4);
    let bad = &standard_conditions(sc.steps, sc.dt)[6];
    let good = &standard_conditions(sc.steps, sc.dt)[7];
    assert!(bad.gate.is_none() && good.gate.is_some());
    for alg in [Algorithm::EdcCif, Algorithm::EcCkf, Algorithm::EcEkf] {
        let hb = checked_run(alg, &sc, bad, 1, 2).unwrap();
        let hg = checked_run(alg, &sc, good, 1, 2).unwrap();
        assert!(hb.healthy() && hg.healthy());
        assert!(
            hb.outliers > 0 && hg.counters.gated >= hg.outliers / 2,
            "{alg}"
        );
        assert!(hg.pos_rmse() < hb.pos_rmse(), "{alg}");
    }
}

#[test]
fn bad_fault_specs_are_named_errors() {
    let sc = short(4);
    let sim = simulate(&sc, 0).unwrap();
    let o = RunOptions::default();
    for (f, what) in [
        (
            Faults {
                message_loss: 1.5,
                ..Faults::default()
            },
            "message_loss",
        ),
        (
            Faults {
                outlier_prob: f64::NAN,
                ..Faults::default()
            },
            "outlier_prob",
        ),
        (
            Faults {
                outlier_sigma: -1.0,
                ..Faults::default()
            },
            "outlier_sigma",
        ),
        (
            Faults {
                dropout: vec![Window {
                    node: 4,
                    start: 0,
                    end: 1,
                }],
                ..Faults::default()
            },
            "dropout[0].node",
        ),
        (
            Faults {
                outage: vec![Window {
                    node: 0,
                    start: 5,
                    end: 1,
                }],
                ..Faults::default()
            },
            "outage[0]",
        ),
    ] {
        let e = run_with_faults(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &o, &f, false)
            .unwrap_err();
        assert!(
            matches!(e, Error::Value { .. }) && e.to_string().contains(what),
            "{e}"
        );
    }
    let e = toml::from_str::<Faults>("message_loss = 0.1\nlosss = 2").unwrap_err();
    assert!(e.to_string().contains("losss"), "{e}");
    let e = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &RunOptions {
            gate: Some(0.0),
            ..o
        },
        false,
    )
    .unwrap_err();
    assert!(e.to_string().contains("gate"), "{e}");
}

#[test]
fn reset_node_rejects_bad_covariances_and_keeps_state() {
    let sc = short(4);
    let sim = simulate(&sc, 0).unwrap();
    let mut net =
        AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &RunOptions::default()).unwrap();
    net.step(&sim.z[..12]).unwrap();
    let mut before = vec![0.0; 4 * 49];
    net.write_covariances(&mut before);
    let x = vec![0.0; 7];
    let mut asym = vec![0.0; 49];
    for i in 0..7 {
        asym[i * 7 + i] = 1.0;
    }
    asym[1] = 0.5; // (0, 1) without (1, 0)
    let neg: Vec<f64> = (0..49)
        .map(|i| if i % 8 == 0 { -1.0 } else { 0.0 })
        .collect();
    let mut nan = neg.clone();
    nan[0] = f64::NAN;
    for (p, what) in [
        (asym, "not symmetric"),
        (neg, "positive definite"),
        (nan, "NaN"),
    ] {
        let e = net.reset_node(1, &x, &p).unwrap_err();
        assert!(e.to_string().contains(what), "{e}");
    }
    assert!(net.reset_node(9, &x, &before[..49]).is_err());
    assert!(net.copy_estimate(0, 9).is_err());
    let mut after = vec![0.0; 4 * 49];
    net.write_covariances(&mut after);
    assert_eq!(before, after);
}

#[test]
fn replace_block_keeps_the_rest() {
    let d = "# T\n<!-- BEGIN a -->\nold\n<!-- END a -->\ntail\n";
    assert_eq!(
        replace_block(d, "a", "new"),
        "# T\n<!-- BEGIN a -->\nnew\n<!-- END a -->\ntail\n"
    );
    assert!(replace_block("# T\n", "b", "x").ends_with("<!-- BEGIN b -->\nx\n<!-- END b -->\n"));
}
