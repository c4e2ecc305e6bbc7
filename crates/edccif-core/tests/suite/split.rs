//! The public predict/update split: `cif_predict` + `cif_update` and
//! `cov_predict` + `cov_update` give exactly (bit for bit) what `cif_local` and
//! `cov_local` give, for every trigger, untriggered-step policy, filter and gate,
//! on successful and on failing steps.

use crate::common;

use common::*;
use edccif_core::models::ConstantVelocity;
use edccif_core::models::Position2;
use edccif_core::{
    cif_local, cif_predict, cif_update, cov_local, cov_predict, cov_update, CifPrior, EtOptions,
    EtPolicy, Gaussian, LocalFilter, Observation, Trigger, TriggerState,
};
use nalgebra::{Matrix4, Vector2, Vector4};

fn triggers() -> [Trigger<f64>; 7] {
    [
        Trigger::Always,
        Trigger::Never,
        Trigger::SendOnDelta { delta: 0.04 },
        Trigger::dynamic(0.04),
        Trigger::Stochastic { delta: 1.0 },
        Trigger::SendOnDeltaInflated { delta: 0.04 },
        Trigger::Innovation { delta: 0.8 },
    ]
}

fn options() -> [EtOptions<f64>; 4] {
    let d = EtOptions::default();
    [
        d,
        EtOptions {
            policy: EtPolicy::Hold,
            ..d
        },
        EtOptions {
            policy: EtPolicy::Skip,
            ..d
        },
        EtOptions {
            gate: Some(3.0),
            ..d
        },
    ]
}

/// 60 steps of the default scenario (every 5th measurement missing) for every
/// trigger × policy/gate: the split CIF and the split CKF/EKF/UKF equal the
/// one-call steps exactly, and so do their trigger states along the run.
#[test]
fn predict_then_update_equals_the_local_steps_bit_for_bit() {
    let motion = ct();
    let sensor = sensor_of(1, 4);
    let mut rng = rng(11);
    let (_, obs) = simulate::<_, _, 7, 3>(&mut rng, &motion, &sensor, &x0(), 60);
    let start = initial_estimate(&mut rng);
    let filters = [
        LocalFilter::Ckf,
        LocalFilter::Ekf,
        LocalFilter::ukf_default(),
    ];
    let mut compared = 0usize;
    for trig in triggers() {
        for opts in options() {
            let mut cif_est = start;
            let mut cif_ts = TriggerState::new(&trig);
            let mut cov_est = [start; 3];
            let mut cov_ts = [TriggerState::new(&trig); 3];
            for (k, z) in obs.iter().enumerate() {
                let z = if k % 5 == 4 { Observation::Missing } else { *z };
                let whole = cif_local(&motion, 0.1, &sensor, &cif_est, &z, &trig, &cif_ts, &opts);
                let split = cif_predict(&motion, 0.1, &cif_est)
                    .and_then(|p| cif_update(&sensor, &p, &z, &trig, &cif_ts, &opts));
                assert_eq!(whole, split, "CIF {trig:?} {opts:?} step {k}");
                let w = whole.unwrap();
                cif_ts = w.trigger_state;
                cif_est = w.local_posterior().to_gaussian().unwrap();
                compared += 1;
                for (i, f) in filters.iter().enumerate() {
                    let whole = cov_local(
                        f,
                        &motion,
                        0.1,
                        &sensor,
                        &cov_est[i],
                        &z,
                        &trig,
                        &cov_ts[i],
                        &opts,
                    );
                    let split = cov_predict(f, &motion, 0.1, &cov_est[i])
                        .and_then(|p| cov_update(f, &sensor, &p, &z, &trig, &cov_ts[i], &opts));
                    assert_eq!(whole, split, "{f:?} {trig:?} {opts:?} step {k}");
                    let w = whole.unwrap();
                    cov_ts[i] = w.trigger_state;
                    cov_est[i] = w.posterior;
                    compared += 1;
                }
            }
        }
    }
    assert_eq!(compared, 7 * 4 * 60 * 4);
}

/// Failing steps fail the same way: a non-positive-definite estimate, a
/// non-finite measurement, a bad time step, bad UKF parameters.
#[test]
fn predict_then_update_fails_like_the_local_steps() {
    let motion = ct();
    let sensor = sensor_of(0, 4);
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let ts = TriggerState::new(&trig);
    let opts = EtOptions::default();
    let good = Gaussian::new(x0(), p0()).unwrap();
    let mut not_pd = good;
    not_pd.p[(0, 0)] = -1.0;
    let z = Observation::Measured(Vec3::new(5.0, 0.1, 3.0));
    let nan_z = Observation::Measured(Vec3::new(f64::NAN, 0.1, 3.0));
    let cases = [
        (good, z, 0.1),
        (not_pd, z, 0.1),
        (good, nan_z, 0.1),
        (good, z, -0.1),
    ];
    let bad_ukf = LocalFilter::Ukf {
        alpha: 0.0,
        beta: 2.0,
        kappa: 0.0,
    };
    for (i, (est, z, dt)) in cases.into_iter().enumerate() {
        let whole = cif_local(&motion, dt, &sensor, &est, &z, &trig, &ts, &opts);
        let split = cif_predict(&motion, dt, &est)
            .and_then(|p| cif_update(&sensor, &p, &z, &trig, &ts, &opts));
        assert_eq!(whole, split, "case {i}");
        assert_eq!(whole.is_ok(), i == 0, "case {i}");
        for f in [
            LocalFilter::Ckf,
            LocalFilter::Ekf,
            LocalFilter::ukf_default(),
            bad_ukf,
        ] {
            let whole = cov_local(&f, &motion, dt, &sensor, &est, &z, &trig, &ts, &opts);
            let split = cov_predict(&f, &motion, dt, &est)
                .and_then(|p| cov_update(&f, &sensor, &p, &z, &trig, &ts, &opts));
            assert_eq!(whole, split, "{f:?} case {i}");
        }
    }
}

/// A prior rebuilt from its Gaussian (what a single filter keeps between
/// `predict` and `update`) is the prior `cif_predict` made, bit for bit.
#[test]
fn a_prior_rebuilt_from_its_gaussian_is_the_same() {
    let cv = ConstantVelocity::new(0.2).unwrap();
    let est = Gaussian::new(
        Vector4::new(1.0, -2.0, 0.5, 0.25),
        Matrix4::new(
            1.0, 0.1, 0.0, 0.0, 0.1, 2.0, 0.0, 0.3, 0.0, 0.0, 0.5, 0.0, 0.0, 0.3, 0.0, 0.7,
        ),
    )
    .unwrap();
    let prior = cif_predict(&cv, 0.3, &est).unwrap();
    let rebuilt = CifPrior::new(&prior.to_gaussian()).unwrap();
    assert_eq!(rebuilt, prior);
    let cam = Position2::new([0.2, 0.3]).unwrap();
    let trig = Trigger::Always;
    let z = Observation::Measured(Vector2::new(1.3, -1.9));
    let ts = TriggerState::new(&trig);
    let opts = EtOptions::default();
    assert_eq!(
        cif_update(&cam, &rebuilt, &z, &trig, &ts, &opts).unwrap(),
        cif_update(&cam, &prior, &z, &trig, &ts, &opts).unwrap()
    );
    // A non-finite state is refused.
    let mut g = prior.to_gaussian();
    g.x[0] = f64::INFINITY;
    assert!(CifPrior::new(&g).is_err());
}
