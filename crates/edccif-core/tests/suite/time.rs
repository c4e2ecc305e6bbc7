//! Time in the motion models: `dt` is given at each call, `Q` scales with it, and a
//! bad time step is a named error that changes nothing.

use edccif_core::fusion::max_degree_weights;
use edccif_core::models::{ConstantVelocity, CoordinatedTurn, RangePitchAzimuth};
use edccif_core::{
    cif_local, cov_local, network_step, Error, EtOptions, Fusion, Gaussian, LocalFilter,
    MotionModel, NetworkConfig, NodeFilter, NodeScratch, NodeState, Observation, StepInputs,
    Trigger, TriggerState,
};
use nalgebra::{SMatrix, SVector, Vector3};

fn bad_dt() -> Error {
    Error::InvalidParameter {
        what: "time step dt",
        expected: "finite and > 0",
    }
}

fn start() -> Gaussian<f64, 7> {
    Gaussian::new(
        SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]),
        SMatrix::<f64, 7, 7>::identity() * 0.01,
    )
    .unwrap()
}

/// The coordinated turn and constant velocity are exact discretisations: two
/// half steps equal one whole step (to rounding), and the process noise
/// composes the same way, `F(dt/2) Q(dt/2) F(dt/2)ᵀ + Q(dt/2) = Q(dt)` for the
/// constant-velocity blocks.
#[test]
fn half_steps_compose() {
    let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    for w in [0.3f64, -1.2, 0.0] {
        let x = SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.4, 1.5, 0.1, w]);
        for dt in [0.1f64, 0.37, 2.0] {
            let whole = ct.transition(&x, dt);
            let halves = ct.transition(&ct.transition(&x, dt / 2.0), dt / 2.0);
            assert!((whole - halves).norm() < 1e-12, "ω = {w}, dt = {dt}");
        }
    }
    let cv = ConstantVelocity::new(0.7).unwrap();
    let x = SVector::<f64, 6>::from([1.0, 2.0, 3.0, -0.5, 0.25, 2.0]);
    for dt in [0.1f64, 0.37, 2.0] {
        let h = dt / 2.0;
        let whole = cv.transition(&x, dt);
        let halves = cv.transition(&cv.transition(&x, h), h);
        assert!((whole - halves).norm() < 1e-12);
        let f = cv.jacobian(&x, h);
        let q = |dt| MotionModel::<f64, 6>::process_noise(&cv, dt);
        let composed = f * q(h) * f.transpose() + q(h);
        assert!((composed - q(dt)).norm() < 1e-12 * (1.0 + dt.powi(3)));
    }
}

/// `Q(dt)` of the white-acceleration blocks: position variance ∝ dt³, covariance
/// ∝ dt², velocity variance and the turn-rate variance ∝ dt.
#[test]
fn process_noise_scales_with_dt() {
    let ct = CoordinatedTurn::<f64>::new(0.5, 1e-4).unwrap();
    let q = |dt| MotionModel::<f64, 7>::process_noise(&ct, dt);
    let (q1, q2) = (q(0.1), q(0.2));
    for a in 0..3 {
        assert!((q2[(a, a)] / q1[(a, a)] - 8.0).abs() < 1e-12);
        assert!((q2[(a, a + 3)] / q1[(a, a + 3)] - 4.0).abs() < 1e-12);
        assert!((q2[(a + 3, a + 3)] / q1[(a + 3, a + 3)] - 2.0).abs() < 1e-12);
    }
    assert!((q2[(6, 6)] / q1[(6, 6)] - 2.0).abs() < 1e-12);
    assert_eq!(q1, q1.transpose());
}

/// A bad time step is rejected by every entry point with the same named error.
#[test]
fn bad_time_steps_are_named_errors() {
    let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    let s = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01).unwrap();
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let ts = TriggerState::new(&trig);
    let z = Observation::Measured(Vector3::new(5.0, 0.02, 3.1));
    let opts = EtOptions::default();
    for dt in [0.0, -0.1, f64::NAN, f64::INFINITY] {
        let e = cif_local(&ct, dt, &s, &start(), &z, &trig, &ts, &opts).unwrap_err();
        assert_eq!(e, bad_dt(), "cif_local, dt = {dt}");
        for f in [
            LocalFilter::Ckf,
            LocalFilter::Ekf,
            LocalFilter::ukf_default(),
        ] {
            let e = cov_local(&f, &ct, dt, &s, &start(), &z, &trig, &ts, &opts).unwrap_err();
            assert_eq!(e, bad_dt(), "{f:?}, dt = {dt}");
        }
    }
}

/// `network_step` with a bad `dt` returns the error and changes no node.
#[test]
fn network_step_with_bad_dt_changes_nothing() {
    let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    let sensors = [
        RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01).unwrap(),
        RangePitchAzimuth::new([-10.0, 0.0, 3.0], 0.1, 0.01).unwrap(),
    ];
    let mut w = [0.0; 4];
    max_degree_weights(&[false, true, true, false], 2, &mut w).unwrap();
    let cfg = NetworkConfig {
        filter: NodeFilter::Cif,
        trigger: Trigger::SendOnDelta { delta: 0.04 },
        et: EtOptions::default(),
        fusion: Fusion::DiffusionCi,
        rule: Default::default(),
    };
    let mut nodes = [NodeState::new(start(), &cfg.trigger); 2];
    let mut scratch = [NodeScratch::default(); 2];
    let obs = [
        Observation::Measured(Vector3::new(5.0, 0.05, 3.1)),
        Observation::Missing,
    ];
    network_step(
        &cfg,
        &ct,
        &sensors,
        &w,
        &mut nodes,
        &mut scratch,
        &StepInputs::new(&obs, 0.1),
    )
    .unwrap();
    let before = nodes;
    for dt in [0.0, -1.0, f64::NAN] {
        let e = network_step(
            &cfg,
            &ct,
            &sensors,
            &w,
            &mut nodes,
            &mut scratch,
            &StepInputs::new(&obs, dt),
        )
        .unwrap_err();
        assert_eq!(e, bad_dt());
        assert_eq!(nodes, before);
    }
    // A longer step predicts further: the position moves on and the uncertainty grows.
    let mut long = before;
    let mut short = before;
    let missing = [Observation::Missing; 2];
    for (n, dt) in [(&mut long, 0.5), (&mut short, 0.1)] {
        network_step(
            &cfg,
            &ct,
            &sensors,
            &w,
            n,
            &mut scratch,
            &StepInputs::new(&missing, dt),
        )
        .unwrap();
    }
    assert!(long[0].estimate.p.trace() > short[0].estimate.p.trace());
}
