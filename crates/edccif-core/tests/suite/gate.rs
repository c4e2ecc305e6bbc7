//! The optional χ² innovation gate (`EtOptions::gate`): a gross outlier on a
//! triggered step is rejected in `cif_local` and in `cov_local` (CKF, EKF, UKF),
//! the step counts as missing (no information, trigger memory unchanged), the
//! network reports it, and without a gate nothing changes.

use crate::common;

use common::*;
use edccif_core::fusion::max_degree_weights;
use edccif_core::{
    cif_local, cov_local, network_step, normalised_innovation, Contribution, Error, EtOptions,
    Fusion, LocalFilter, MeasurementModel, NetworkConfig, NodeFilter, NodeScratch, NodeState,
    Observation, StepInputs, Trigger, TriggerState,
};
use nalgebra::{Matrix3, Vector3};

fn gated() -> EtOptions<f64> {
    EtOptions {
        gate: Some(16.27),
        ..EtOptions::default()
    }
}

#[test]
fn gate_rejects_outliers_and_keeps_good_measurements() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let mut r = rng(7);
    let start = initial_estimate(&mut r);
    let good = MeasurementModel::<f64, 7, 3>::measure(&sensor, &x0());
    let bad = good + Vector3::new(2.0, 0.2, 0.2); // 20σ on every component
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let ts = TriggerState::new(&trig);
    for (z, expect_gated) in [(good, false), (bad, true)] {
        let obs = Observation::Measured(z);
        let plain = cif_local(
            &motion,
            0.1,
            &sensor,
            &start,
            &obs,
            &trig,
            &ts,
            &EtOptions::default(),
        )
        .unwrap();
        let g = cif_local(&motion, 0.1, &sensor, &start, &obs, &trig, &ts, &gated()).unwrap();
        assert!(!plain.gated);
        assert_eq!(g.gated, expect_gated);
        assert_eq!(g.triggered, Some(true));
        if expect_gated {
            assert_eq!(g.contribution, Contribution::zeros());
            assert_eq!(g.trigger_state, ts, "trigger memory must not advance");
        } else {
            assert_eq!(g, plain);
        }
        for f in [
            LocalFilter::Ckf,
            LocalFilter::Ekf,
            LocalFilter::ukf_default(),
        ] {
            let plain = cov_local(
                &f,
                &motion,
                0.1,
                &sensor,
                &start,
                &obs,
                &trig,
                &ts,
                &EtOptions::default(),
            )
            .unwrap();
            let c = cov_local(
                &f,
                &motion,
                0.1,
                &sensor,
                &start,
                &obs,
                &trig,
                &ts,
                &gated(),
            )
            .unwrap();
            assert_eq!(c.gated, expect_gated, "{f:?}");
            if expect_gated {
                // posterior = prior: same as a missing measurement
                let miss = cov_local(
                    &f,
                    &motion,
                    0.1,
                    &sensor,
                    &start,
                    &Observation::Missing,
                    &trig,
                    &ts,
                    &gated(),
                )
                .unwrap();
                assert_eq!(c.posterior, miss.posterior, "{f:?}");
                assert_eq!(c.trigger_state, ts);
            } else {
                assert_eq!(c, plain, "{f:?}");
            }
        }
    }
}

#[test]
fn gate_is_validated_and_counted_by_the_network() {
    for g in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let o = EtOptions {
            gate: Some(g),
            ..EtOptions::default()
        };
        assert_eq!(
            o.validate().unwrap_err(),
            Error::InvalidParameter {
                what: "gate",
                expected: "finite and > 0"
            }
        );
    }
    assert!(
        (normalised_innovation(
            &(Matrix3::<f64>::identity() * 4.0),
            &Vector3::new(2.0, 2.0, 0.0)
        )
        .unwrap()
            - 2.0)
            .abs()
            < 1e-12
    );
    assert!(normalised_innovation(&(-Matrix3::<f64>::identity()), &Vector3::zeros()).is_err());

    let motion = ct();
    let sensors = [
        sensor_of(0, 4),
        sensor_of(1, 4),
        sensor_of(2, 4),
        sensor_of(3, 4),
    ];
    let mut w = [0.0; 16];
    max_degree_weights(&ring::<16>(), 4, &mut w).unwrap();
    let cfg = NetworkConfig {
        filter: NodeFilter::Cif,
        trigger: Trigger::SendOnDelta { delta: 0.04 },
        et: gated(),
        fusion: Fusion::DiffusionCi,
        rule: Default::default(),
    };
    let mut r = rng(3);
    let start = initial_estimate(&mut r);
    let mut nodes = [NodeState::new(start, &cfg.trigger); 4];
    let mut scratch = [NodeScratch::default(); 4];
    let mut obs: Vec<Observation<f64, 3>> = sensors
        .iter()
        .map(|s| Observation::Measured(MeasurementModel::<f64, 7, 3>::measure(s, &x0())))
        .collect();
    if let Observation::Measured(z) = &mut obs[2] {
        z[0] += 5.0;
    }
    let rep = network_step(
        &cfg,
        &motion,
        &sensors,
        &w,
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs, 0.1),
    )
    .unwrap();
    assert_eq!(rep.gated, 1);
    assert!(scratch[2].gated && !scratch[0].gated);
    assert_eq!(nodes[2].trigger, TriggerState::new(&cfg.trigger));
}
