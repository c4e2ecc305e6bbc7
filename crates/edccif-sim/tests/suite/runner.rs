//! Network runner, rows, scenarios and Monte Carlo determinism.

use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::{cif_local, EtOptions, Gaussian, Observation, Trigger, TriggerState};
use edccif_sim::{
    monte_carlo, run, simulate, Algorithm, AnyNetwork, McSettings, RunOptions, RunResult, Scenario,
    Simulation, Topology, Variant,
};
use nalgebra::{SMatrix, SVector, Vector3};

/// `run` with default options on a simulation's data (covariances when `cov`).
fn run_default(alg: Algorithm, sc: &Scenario, sim: &Simulation, cov: bool) -> RunResult {
    run(alg, sc, &sim.z, &sim.x0_hat, &RunOptions::default(), cov).unwrap()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn every_row_runs_on_3_4_8_nodes() {
    for nodes in [3, 4, 8] {
        let sc = Scenario::paper(nodes);
        let sim = simulate(&sc, 11).unwrap();
        for alg in Algorithm::ALL {
            let r = run_default(alg, &sc, &sim, true);
            assert_eq!(r.estimates.len(), 200 * nodes * 7);
            assert!(
                r.estimates.iter().all(|v| v.is_finite()),
                "{alg} on {nodes}"
            );
            // mean position error over the run stays small (bound: 0.5 m, ~4× the RMSE seen)
            let mut err = 0.0;
            for t in 0..200 {
                for i in 0..nodes {
                    let e = &r.estimates[(t * nodes + i) * 7..(t * nodes + i) * 7 + 3];
                    let x = &sim.truth[t * 7..t * 7 + 3];
                    err += e
                        .iter()
                        .zip(x)
                        .map(|(a, b)| (a - b).powi(2))
                        .sum::<f64>()
                        .sqrt();
                }
            }
            err /= (200 * nodes) as f64;
            assert!(
                err < 0.5,
                "{alg} on {nodes} nodes: mean position error {err}"
            );
            if alg.is_event_triggered() {
                assert!(
                    r.trigger_rate() > 0.2 && r.trigger_rate() < 0.9,
                    "{alg}: {}",
                    r.trigger_rate()
                );
            } else {
                assert_eq!(r.trigger_rate(), 1.0);
            }
        }
    }
}

#[test]
fn forced_trigger_edc_cif_equals_dc_cif() {
    let sc = Scenario::paper(4);
    let sim = simulate(&sc, 5).unwrap();
    let forced = RunOptions {
        force_trigger: true,
        ..RunOptions::default()
    };
    let a = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &forced, false).unwrap();
    let b = run_default(Algorithm::DcCif, &sc, &sim, false);
    assert_eq!(a.estimates, b.estimates);
    // and δ → 0 (every measurement moves more than δ) gives the same
    let tiny = RunOptions {
        delta: Some(1e-300.into()),
        ..RunOptions::default()
    };
    let c = run(Algorithm::EdcCif, &sc, &sim.z, &sim.x0_hat, &tiny, false).unwrap();
    assert_eq!(c.trigger_rate(), 1.0);
    assert_eq!(c.estimates, b.estimates);
}

#[test]
fn complete_graph_of_three_makes_ci_and_plain_combination_agree() {
    // Every node sees every contribution, so all adapted pairs are equal and both
    // combinations return them (to rounding).
    let sc = Scenario {
        topology: Topology::Complete,
        ..Scenario::paper(3)
    };
    let sim = simulate(&sc, 9).unwrap();
    let a = run_default(Algorithm::EdCif, &sc, &sim, false);
    let b = run_default(Algorithm::EdcCif, &sc, &sim, false);
    assert!(max_abs_diff(&a.estimates, &b.estimates) < 1e-9);
    assert_eq!(a.triggered, b.triggered);
}

#[test]
fn runner_agrees_with_core_single_step_api() {
    // One node: the network's fused estimate is the node's local ET-CIF posterior.
    let sc = Scenario::paper(1);
    let sim = simulate(&sc, 2).unwrap();
    let r = run_default(Algorithm::EdcCif, &sc, &sim, true);
    let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    let s = RangePitchAzimuth::new(sc.sensors[0], 0.1, 0.01).unwrap();
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let mut ts = TriggerState::new(&trig);
    let p0 = SMatrix::<f64, 7, 7>::from_diagonal(&SVector::from_column_slice(&sc.p0_diag));
    let mut est = Gaussian::new(SVector::from_column_slice(&sim.x0_hat), p0).unwrap();
    for t in 0..sc.steps {
        let z = Observation::Measured(Vector3::from_column_slice(&sim.z[t * 3..t * 3 + 3]));
        let out = cif_local(&ct, 0.1, &s, &est, &z, &trig, &ts, &EtOptions::default()).unwrap();
        ts = out.trigger_state;
        est = out.local_posterior().to_gaussian().unwrap();
        assert_eq!(r.triggered[t], out.triggered == Some(true));
        let d = max_abs_diff(est.x.as_slice(), &r.estimates[t * 7..t * 7 + 7]);
        assert!(d < 1e-9, "step {t}: {d}");
    }
}

#[test]
fn streaming_equals_batch() {
    let sc = Scenario::paper(4);
    let sim = simulate(&sc, 3).unwrap();
    for alg in [Algorithm::EdcCif, Algorithm::EcUkf, Algorithm::DecCkf] {
        let r = run_default(alg, &sc, &sim, false);
        let mut net = AnyNetwork::new(alg, &sc, &sim.x0_hat, &RunOptions::default()).unwrap();
        let mut est = vec![0.0; 4 * 7];
        for t in 0..sc.steps {
            net.step(&sim.z[t * 12..(t + 1) * 12]).unwrap();
            net.write_estimates(&mut est);
            assert_eq!(&est[..], &r.estimates[t * 28..(t + 1) * 28]);
        }
    }
}

#[test]
fn scenario_files_match_the_builtin_and_roundtrip() {
    for n in [3, 4, 8] {
        let path = format!(
            "{}/../../scenarios/paper-{n}.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let from_file = Scenario::from_toml_file(&path).unwrap();
        assert_eq!(from_file, Scenario::paper(n), "{path}");
        let text = Scenario::paper(n).to_toml().unwrap();
        assert_eq!(Scenario::from_toml_str(&text).unwrap(), Scenario::paper(n));
    }
    let custom = Scenario {
        topology: Topology::RandomGeometric {
            radius: 0.6,
            seed: 4,
        },
        consensus_iters: Some(3),
        ..Scenario::paper(6)
    };
    assert_eq!(
        Scenario::from_toml_str(&custom.to_toml().unwrap()).unwrap(),
        custom
    );
}

#[test]
fn scenario_errors_name_the_field() {
    let base = Scenario::paper(4).to_toml().unwrap();
    let e = Scenario::from_toml_str(&base.replace("dt = 0.1", "dt = -0.1")).unwrap_err();
    assert!(e.to_string().contains("dt"), "{e}");
    let e = Scenario::from_toml_str(&base.replace("steps = 200", "steps = \"x\"")).unwrap_err();
    assert!(
        e.to_string().contains("steps") || e.to_string().contains("line"),
        "{e}"
    );
    let e = Scenario::from_toml_str(&base.replace("delta = 0.04", "delta = 0.04\nbogus = 1"))
        .unwrap_err();
    assert!(e.to_string().contains("bogus"), "{e}");
    let bad = Scenario {
        topology: Topology::Custom {
            adjacency: vec![
                vec![false, true, false],
                vec![true, false, false],
                vec![false, false, false],
            ],
            weights: None,
        },
        ..Scenario::paper(3)
    };
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("disconnected"));
}

#[test]
fn topologies() {
    for (t, edges) in [
        (Topology::Ring, 6),
        (Topology::Line, 5),
        (Topology::Star { center: 0 }, 5),
        (Topology::Complete, 15),
    ] {
        let a = t.adjacency(6).unwrap();
        assert_eq!(a.iter().filter(|e| **e).count(), 2 * edges, "{t:?}");
    }
    let a = Topology::RandomGeometric {
        radius: 0.5,
        seed: 1,
    }
    .adjacency(10)
    .unwrap();
    assert_eq!(
        a,
        Topology::RandomGeometric {
            radius: 0.5,
            seed: 1
        }
        .adjacency(10)
        .unwrap()
    );
    assert!(Topology::RandomGeometric {
        radius: 0.01,
        seed: 1
    }
    .adjacency(10)
    .is_err());
    assert_eq!(
        Topology::Ring.adjacency(2).unwrap(),
        vec![false, true, true, false]
    );
}

#[test]
fn missing_measurements_are_handled() {
    let sc = Scenario::paper(4);
    let sim = simulate(&sc, 1).unwrap();
    let mut z = sim.z.clone();
    for t in 40..60 {
        for c in 0..3 {
            z[t * 12 + 3 + c] = f64::NAN; // node 1 dark for 2 s
        }
    }
    for alg in Algorithm::ALL {
        let r = run(alg, &sc, &z, &sim.x0_hat, &RunOptions::default(), false).unwrap();
        assert!(r.estimates.iter().all(|v| v.is_finite()));
        assert!((40..60).all(|t| !r.measured[t * 4 + 1]));
        assert_eq!(r.counters.measured, (200 * 4 - 20) as u64);
    }
}

#[test]
fn monte_carlo_is_deterministic_across_thread_counts() {
    let sc = Scenario {
        steps: 60,
        ..Scenario::paper(4)
    };
    let vs: Vec<Variant> = vec![Algorithm::EdcCif.into(), Algorithm::EcCkf.into()];
    let settings = McSettings {
        runs: 40,
        seed: 7,
        progress: false,
    };
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let two = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let a = one.install(|| monte_carlo(&sc, &vs, &settings)).unwrap();
    let b = two.install(|| monte_carlo(&sc, &vs, &settings)).unwrap();
    for (x, y) in a.variants.iter().zip(&b.variants) {
        assert_eq!(x.errors, y.errors);
        assert_eq!(x.trigger_rate, y.trigger_rate);
    }
}

#[test]
fn consensus_iterations_and_communication_counts() {
    let sc = Scenario::paper(4);
    let sim = simulate(&sc, 0).unwrap();
    let r = run_default(Algorithm::EcCkf, &sc, &sim, false);
    // ring of 4: 8 directed links, L = 5, 7 + 28 floats per message, 200 steps
    assert_eq!(r.counters.values_estimator_to_estimator, 200 * 8 * 5 * 35);
    assert_eq!(
        r.counters.values_sensor_to_estimator,
        3 * r.counters.triggered
    );
    let d = run_default(Algorithm::EdcCif, &sc, &sim, false);
    assert_eq!(d.counters.values_estimator_to_estimator, 200 * 8 * 2 * 35);
}
