//! The network of one's own models: with the scenario's sensors it is the
//! scenario network bit for bit on every row; nodes of different measurement
//! dimensions fuse; a failed step leaves the network as it was.

use edccif_core::models::{CoordinatedTurn, Position3};
use edccif_core::{Gaussian, MeasurementModel, MotionModel};
use edccif_sim::mixed::{MixedNetwork, NodeSensor, SensorNode};
use edccif_sim::{
    run, simulate, Algorithm, AnyNetwork, RowParams, RunOptions, Scenario, TriggerKind,
};
use nalgebra::{SMatrix, SVector, Vector1};

fn start(sc: &Scenario, x0: &[f64]) -> Gaussian<f64, 7> {
    Gaussian::new(
        SVector::from_column_slice(x0),
        SMatrix::from_diagonal(&SVector::from_column_slice(&sc.p0_diag)),
    )
    .unwrap()
}

fn paper_network(sc: &Scenario, alg: Algorithm, x0: &[f64], opt: &RunOptions) -> MixedNetwork<7> {
    let motion: Box<dyn MotionModel<f64, 7> + Send + Sync> =
        Box::new(sc.coordinated_turn().unwrap());
    let sensors: Vec<Box<dyn NodeSensor<7>>> = sc
        .sensor_models()
        .unwrap()
        .into_iter()
        .map(|s| Box::new(SensorNode::<_, 3>::new(s)) as Box<dyn NodeSensor<7>>)
        .collect();
    let params = RowParams::of(sc, sc.consensus_iterations().unwrap());
    MixedNetwork::new(
        alg,
        &params,
        opt,
        motion,
        sensors,
        sc.weights().unwrap(),
        start(sc, x0),
        sc.dt,
    )
    .unwrap()
}

#[test]
fn scenario_sensors_give_the_scenario_network_bit_for_bit() {
    let sc = Scenario {
        steps: 60,
        ..Scenario::paper(4)
    };
    let sim = simulate(&sc, 5).unwrap();
    let dts: Vec<f64> = (0..sc.steps)
        .map(|t| 0.05 + 0.01 * (t % 7) as f64)
        .collect();
    let mut opts = vec![RunOptions::default()];
    for t in [TriggerKind::Stochastic, TriggerKind::Innovation] {
        opts.push(RunOptions {
            trigger: Some(t),
            trigger_seed: Some(3),
            ..RunOptions::default()
        });
    }
    for alg in Algorithm::ALL {
        for opt in &opts {
            let mut a = AnyNetwork::new(alg, &sc, &sim.x0_hat, opt).unwrap();
            let mut b = paper_network(&sc, alg, &sim.x0_hat, opt);
            let mut z = sim.z.clone();
            // some nodes miss some steps
            for t in 0..sc.steps {
                if t % 3 == 1 {
                    z[t * 12 + 3..t * 12 + 6].fill(f64::NAN);
                }
            }
            for (t, zt) in z.chunks(12).enumerate() {
                a.step_dt(zt, dts[t]).unwrap();
                b.step(zt, dts[t]).unwrap();
                let mut est = vec![0.0; 4 * 7];
                a.write_estimates(&mut est);
                let mine: Vec<f64> = b
                    .estimates()
                    .iter()
                    .flat_map(|g| g.x.iter().copied())
                    .collect();
                assert_eq!(est, mine, "{alg} {opt:?} step {t}");
                assert_eq!(a.last_triggered(), b.last_triggered().collect::<Vec<_>>());
            }
            assert_eq!(a.counters(), b.counters(), "{alg}");
        }
    }
}

#[test]
fn run_equals_run_of_the_scenario() {
    let sc = Scenario {
        steps: 40,
        ..Scenario::paper(3)
    };
    let sim = simulate(&sc, 1).unwrap();
    let r = run(
        Algorithm::EdcCif,
        &sc,
        &sim.z,
        &sim.x0_hat,
        &RunOptions::default(),
        true,
    )
    .unwrap();
    let mut net = paper_network(&sc, Algorithm::EdcCif, &sim.x0_hat, &RunOptions::default());
    let m = net.run(&sim.z, &vec![sc.dt; sc.steps], true).unwrap();
    assert_eq!(r.estimates, m.estimates);
    assert_eq!(r.covariances, m.covariances);
    assert_eq!(r.triggered, m.triggered);
    assert_eq!(r.counters, m.counters);
}

/// A 1-value sensor: the x coordinate only.
#[derive(Debug, Clone, Copy)]
struct XOnly;
impl MeasurementModel<f64, 7, 1> for XOnly {
    fn measure(&self, x: &SVector<f64, 7>) -> Vector1<f64> {
        Vector1::new(x[0])
    }
    fn noise(&self) -> SMatrix<f64, 1, 1> {
        SMatrix::identity() * 0.01
    }
}

fn mixed(alg: Algorithm) -> (MixedNetwork<7>, Scenario) {
    let sc = Scenario::paper(3);
    let motion: Box<dyn MotionModel<f64, 7> + Send + Sync> =
        Box::new(CoordinatedTurn::new(0.5, 1e-4).unwrap());
    let sensors: Vec<Box<dyn NodeSensor<7>>> = vec![
        Box::new(SensorNode::<_, 3>::new(Position3::new([0.05; 3]).unwrap())),
        Box::new(SensorNode::<_, 1>::new(XOnly)),
        Box::new(SensorNode::<_, 3>::new(sc.sensor_models().unwrap()[2])),
    ];
    let w = vec![0.5, 0.5, 0.0, 0.5, 0.25, 0.25, 0.0, 0.25, 0.75];
    let net = MixedNetwork::new(
        alg,
        &RowParams::paper(4),
        &RunOptions::default(),
        motion,
        sensors,
        w,
        start(&sc, &sc.x0),
        0.1,
    )
    .unwrap();
    (net, sc)
}

#[test]
fn nodes_of_different_measurement_dimensions_fuse_on_every_row() {
    for alg in Algorithm::ALL {
        let (mut net, sc) = mixed(alg);
        assert_eq!(net.meas_dims(), vec![3, 1, 3]);
        let sim = simulate(
            &Scenario {
                steps: 30,
                ..sc.clone()
            },
            2,
        )
        .unwrap();
        for t in 0..30 {
            let truth = &sim.truth[t * 7..t * 7 + 3];
            let rpa = &sim.z[t * 9 + 6..t * 9 + 9];
            let z = [
                truth[0], truth[1], truth[2], truth[0], rpa[0], rpa[1], rpa[2],
            ];
            net.step(&z, 0.1).unwrap();
        }
        let truth = &sim.truth[29 * 7..29 * 7 + 3];
        for g in net.estimates() {
            let e = (g.x.fixed_rows::<3>(0) - SVector::<f64, 3>::from_column_slice(truth)).norm();
            // exact positions at node 0 (σ = 5 cm): every node within 0.5 m
            assert!(e < 0.5, "{alg}: {e}");
        }
        let c = net.counters();
        assert_eq!(c.measured, 90);
        assert!(c.values_sensor_to_estimator <= 30 * 7);
    }
}

#[test]
fn bad_steps_leave_the_network_unchanged() {
    let (mut net, _) = mixed(Algorithm::EdcCif);
    let z = [5.0, 0.0, 1.0, 5.0, 5.0, 0.05, 3.1];
    net.step(&z, 0.1).unwrap();
    let before: Vec<_> = net.estimates().to_vec();
    let counters = net.counters();
    for (zz, dt) in [
        (&z[..6], 0.1),
        (&z[..], 0.0),
        (&z[..], f64::NAN),
        (&[5.0, f64::NAN, 1.0, 5.0, 5.0, 0.05, 3.1][..], 0.1),
        (&[5.0, 0.0, 1.0, f64::INFINITY, 5.0, 0.05, 3.1][..], 0.1),
        // a measurement so far away that a covariance breaks: the core refuses
        (&[5.0, 0.0, 1.0, 5.0, 5.0, 0.05, 1e300][..], 1e300),
    ] {
        assert!(net.step(zz, dt).is_err());
        assert_eq!(net.estimates(), &before[..]);
        assert_eq!(net.counters(), counters);
    }
    // and it continues as if nothing had happened
    let (mut fresh, _) = mixed(Algorithm::EdcCif);
    fresh.step(&z, 0.1).unwrap();
    fresh.step(&z, 0.1).unwrap();
    net.step(&z, 0.1).unwrap();
    assert_eq!(net.estimates(), fresh.estimates());
}

#[test]
fn bad_graphs_are_refused() {
    let sc = Scenario::paper(2);
    let make = |w: Vec<f64>| {
        let motion: Box<dyn MotionModel<f64, 7> + Send + Sync> =
            Box::new(CoordinatedTurn::new(0.5, 1e-4).unwrap());
        let sensors: Vec<Box<dyn NodeSensor<7>>> = vec![
            Box::new(SensorNode::<_, 1>::new(XOnly)),
            Box::new(SensorNode::<_, 1>::new(XOnly)),
        ];
        MixedNetwork::new(
            Algorithm::EdcCif,
            &RowParams::paper(1),
            &RunOptions::default(),
            motion,
            sensors,
            w,
            start(&sc, &sc.x0),
            0.1,
        )
        .map(|_| ())
        .unwrap_err()
        .to_string()
    };
    assert!(make(vec![1.0, 0.0, 0.0, 1.0]).contains("disconnected"));
    assert!(make(vec![0.5, 0.5, 0.25, 0.75]).contains("symmetric"));
    assert!(make(vec![0.6, 0.5, 0.5, 0.6]).contains("sum to 1"));
    assert!(make(vec![0.5; 3]).contains("weights"));
}

#[test]
fn own_model_networks_reject_parallel_threads() {
    let sc = Scenario::paper(4);
    let make = |threads| {
        let sensors: Vec<Box<dyn NodeSensor<7>>> = sc
            .sensor_models()
            .unwrap()
            .into_iter()
            .map(|s| Box::new(SensorNode::<_, 3>::new(s)) as Box<dyn NodeSensor<7>>)
            .collect();
        let opt = RunOptions {
            threads,
            ..RunOptions::default()
        };
        MixedNetwork::new(
            Algorithm::EdcCif,
            &RowParams::of(&sc, 3),
            &opt,
            Box::new(sc.coordinated_turn().unwrap()),
            sensors,
            sc.weights().unwrap(),
            start(&sc, &sc.x0),
            sc.dt,
        )
    };
    assert!(make(None).is_ok() && make(Some(1)).is_ok());
    for t in [0, 2] {
        let e = make(Some(t)).unwrap_err().to_string();
        assert!(e.contains("threads"), "{e}");
    }
}

/// Every fusion rule (`docs/fusion.md`) on the model network with the
/// scenario's sensors gives the scenario network's numbers bit for bit: the
/// fused and pre-combination estimates and covariances, the triggers and the
/// counters, also over steps with lost links and a node down.
#[test]
fn every_fusion_rule_gives_the_scenario_network_bit_for_bit() {
    use edccif_core::FusionRule;
    use edccif_sim::FusionKind;
    let sc = Scenario {
        steps: 30,
        ..Scenario::paper(4)
    };
    let sim = simulate(&sc, 6).unwrap();
    let k = 4;
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let mixed_rows = |net: &MixedNetwork<7>| {
        let mut x = Vec::new();
        let mut p = Vec::new();
        for g in net.estimates() {
            x.extend(g.x.iter().copied());
            p.extend(g.p.transpose().iter().copied());
        }
        let local: Vec<f64> = net
            .local_estimates()
            .flat_map(|g| g.x.iter().copied().collect::<Vec<_>>())
            .collect();
        (bits(&x), bits(&p), bits(&local))
    };
    for rule in FusionRule::ALL {
        let opt = RunOptions {
            fusion: Some(if rule.is_paper() {
                FusionKind::DiffusionCi
            } else {
                FusionKind::Rule(rule)
            }),
            ..RunOptions::default()
        };
        let mut a = AnyNetwork::new(Algorithm::EdcCif, &sc, &sim.x0_hat, &opt).unwrap();
        let mut b = paper_network(&sc, Algorithm::EdcCif, &sim.x0_hat, &opt);
        for (t, zt) in sim.z.chunks(12).enumerate() {
            // every third step node 0 loses node 1's messages; every fifth (from the fifth) node 2 is down
            let mut links = vec![true; k * k];
            links[1] = t % 3 != 0;
            let active: Vec<bool> = (0..k).map(|i| i != 2 || t % 5 != 4).collect();
            a.step_dt_with(zt, sc.dt, Some(&links), Some(&active))
                .unwrap();
            b.step_with(zt, sc.dt, Some(&links), Some(&active)).unwrap();
            let (mut x, mut p, mut local) = (vec![0.0; k * 7], vec![0.0; k * 49], vec![0.0; k * 7]);
            a.write_estimates(&mut x);
            a.write_covariances(&mut p);
            a.write_local_estimates(&mut local);
            assert_eq!(
                (bits(&x), bits(&p), bits(&local)),
                mixed_rows(&b),
                "{rule} step {t}"
            );
            assert_eq!(
                a.last_triggered(),
                b.last_triggered().collect::<Vec<_>>(),
                "{rule}"
            );
        }
        assert_eq!(a.counters(), b.counters(), "{rule}");
    }
}
