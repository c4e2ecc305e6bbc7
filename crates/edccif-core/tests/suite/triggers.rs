//! The triggers beyond the paper (`docs/triggers.md`): on a linear-Gaussian
//! model each silent-step update equals its closed form, the stochastic trigger
//! is reproducible from its seed and sends at the rate its law predicts.

use edccif_core::models::{LinearMotion, Position3};
use edccif_core::silence::innovation_beta;
use edccif_core::{
    cif_local, cov_local, EtOptions, Gaussian, LocalFilter, Observation, Trigger, TriggerState,
};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

type M6 = SMatrix<f64, 6, 6>;

fn linear() -> (LinearMotion<f64, 6>, Position3<f64>, Gaussian<f64, 6>) {
    let mut f = M6::identity();
    for a in 0..3 {
        f[(a, a + 3)] = 0.1;
    }
    let motion = LinearMotion::new(f, M6::identity() * 1e-3).unwrap();
    let sensor = Position3::new([0.1, 0.2, 0.15]).unwrap();
    let mut p = M6::identity() * 0.05;
    p[(0, 3)] = 0.01;
    p[(3, 0)] = 0.01;
    let est = Gaussian::new(SVector::<f64, 6>::from([1.0, -0.5, 2.0, 0.3, 0.1, -0.2]), p).unwrap();
    (motion, sensor, est)
}

/// Kalman update of a linear position sensor `z = [I 0] x + v`, `v ~ N(0, Rs)`.
fn kalman(prior: &Gaussian<f64, 6>, z: &Vector3<f64>, rs: &Matrix3<f64>) -> Gaussian<f64, 6> {
    let h = SMatrix::<f64, 3, 6>::identity();
    let s = h * prior.p * h.transpose() + rs;
    let k = prior.p * h.transpose() * s.try_inverse().unwrap();
    Gaussian {
        x: prior.x + k * (z - h * prior.x),
        p: prior.p - k * h * prior.p,
    }
}

/// The CIF and covariance-form local steps at a silent step of `trig`, after the
/// sensor last sent `zt` and now measures `z`.
fn silent_steps(
    trig: Trigger<f64>,
    zt: Vector3<f64>,
    z: Vector3<f64>,
) -> (Gaussian<f64, 6>, Gaussian<f64, 6>, Gaussian<f64, 6>) {
    let (motion, sensor, est) = linear();
    let mut ts = TriggerState::new(&trig);
    ts.last_sent = Some(zt);
    let o = EtOptions::default();
    let obs = Observation::Measured(z);
    let cif = cif_local(&motion, 0.1, &sensor, &est, &obs, &trig, &ts, &o).unwrap();
    assert_eq!(cif.triggered, Some(false), "{trig:?} must stay silent");
    let cov = cov_local(
        &LocalFilter::Ckf,
        &motion,
        0.1,
        &sensor,
        &est,
        &obs,
        &trig,
        &ts,
        &o,
    )
    .unwrap();
    assert_eq!(cov.triggered, Some(false));
    let prior = Gaussian {
        x: cif.x_prior,
        p: cif.p_prior,
    };
    (
        prior,
        cif.local_posterior().to_gaussian().unwrap(),
        cov.posterior,
    )
}

fn close(a: &Gaussian<f64, 6>, b: &Gaussian<f64, 6>, tol: f64) {
    assert!((a.x - b.x).norm() < tol, "x: {} vs {}", a.x, b.x);
    assert!((a.p - b.p).norm() < tol, "P: {} vs {}", a.p, b.p);
}

#[test]
fn inflated_send_on_delta_is_a_measurement_of_z_tau_with_ball_covariance() {
    let zt = Vector3::new(1.05, -0.45, 2.0);
    let delta = 0.04;
    let (prior, cif, cov) = silent_steps(
        Trigger::SendOnDeltaInflated { delta },
        zt,
        zt + Vector3::new(0.1, 0.05, 0.0),
    );
    let r = Matrix3::from_diagonal(&Vector3::new(0.01, 0.04, 0.0225));
    let expect = kalman(&prior, &zt, &(r + Matrix3::identity() * (delta / 5.0)));
    close(&cif, &expect, 1e-9);
    close(&cov, &expect, 1e-9);
}

#[test]
fn stochastic_silence_is_the_exact_gaussian_update() {
    // Han et al.: P(silent | z) = exp(−½ ΔᵀR⁻¹Δ/δ) is a Gaussian likelihood of z
    // centred at z_τ with covariance δR, so the posterior is a Kalman update with
    // z_τ and noise (1+δ)R. A tiny Δ and a stream whose first draw is small
    // keep this step silent.
    let zt = Vector3::new(1.05, -0.45, 2.0);
    let delta = 2.0;
    let trig = Trigger::Stochastic { delta };
    let (motion, sensor, est) = linear();
    let r = Matrix3::from_diagonal(&Vector3::new(0.01, 0.04, 0.0225));
    let expect_for = |prior: &Gaussian<f64, 6>| kalman(prior, &zt, &(r * (1.0 + delta)));
    let mut silent = 0;
    for node in 0..20 {
        let mut ts = TriggerState::seeded(&trig, 9, node);
        ts.last_sent = Some(zt);
        let obs = Observation::Measured(zt + Vector3::new(0.05, 0.0, 0.0));
        let out = cif_local(
            &motion,
            0.1,
            &sensor,
            &est,
            &obs,
            &trig,
            &ts,
            &EtOptions::default(),
        )
        .unwrap();
        // reproducible: the same state decides the same way
        let again = cif_local(
            &motion,
            0.1,
            &sensor,
            &est,
            &obs,
            &trig,
            &ts,
            &EtOptions::default(),
        )
        .unwrap();
        assert_eq!(out, again);
        assert_ne!(out.trigger_state.rng, ts.rng, "one draw per decision");
        if out.triggered == Some(false) {
            silent += 1;
            let prior = Gaussian {
                x: out.x_prior,
                p: out.p_prior,
            };
            close(
                &out.local_posterior().to_gaussian().unwrap(),
                &expect_for(&prior),
                1e-9,
            );
        }
    }
    // P(silent) = exp(−½·0.25/2) ≈ 0.94 per node
    assert!(silent >= 14, "{silent} of 20 silent");
}

#[test]
fn stochastic_trigger_sends_at_the_rate_of_its_law() {
    let trig = Trigger::Stochastic { delta: 0.5 };
    let sensor = Position3::new([0.1; 3]).unwrap();
    let zt = Vector3::new(0.0, 0.0, 0.0);
    // ΔᵀR⁻¹Δ = 1 → P(send) = 1 − e^{−1}
    let z = Vector3::new(0.1, 0.0, 0.0);
    let mut s = TriggerState::<f64, 3>::seeded(&trig, 3, 1);
    let n = 20_000;
    let mut sent = 0;
    for _ in 0..n {
        s.last_sent = Some(zt);
        let (g, next) = trig.decide::<_, 6, 3>(&sensor, &s, &z);
        sent += usize::from(g);
        s = next;
    }
    let rate = sent as f64 / n as f64;
    let p = 1.0 - (-1.0f64).exp();
    assert!(
        (rate - p).abs() < 4.0 * (p * (1.0 - p) / n as f64).sqrt(),
        "{rate} vs {p}"
    );
}

#[test]
fn innovation_silence_keeps_the_share_beta_of_the_update() {
    let delta = 1.5;
    let (motion, sensor, est) = linear();
    let trig = Trigger::Innovation { delta };
    // the prediction: z near ẑ stays silent
    let probe = cif_local(
        &motion,
        0.1,
        &sensor,
        &est,
        &Observation::Missing,
        &trig,
        &TriggerState::new(&trig),
        &EtOptions::default(),
    )
    .unwrap();
    let z_hat = probe.x_prior.fixed_rows::<3>(0).into_owned();
    let (prior, cif, cov) = silent_steps(trig, z_hat, z_hat + Vector3::new(0.05, 0.0, 0.0));
    let h = SMatrix::<f64, 3, 6>::identity();
    let r = Matrix3::from_diagonal(&Vector3::new(0.01, 0.04, 0.0225));
    let s = h * prior.p * h.transpose() + r;
    let k = prior.p * h.transpose() * s.try_inverse().unwrap();
    let beta = innovation_beta(delta);
    let expect = Gaussian {
        x: prior.x,
        p: prior.p - k * s * k.transpose() * beta,
    };
    close(&cif, &expect, 1e-9);
    close(&cov, &expect, 1e-9);
    // and a far measurement sends
    let (motion, sensor, est) = linear();
    let out = cif_local(
        &motion,
        0.1,
        &sensor,
        &est,
        &Observation::Measured(z_hat + Vector3::new(0.5, 0.0, 0.0)),
        &trig,
        &TriggerState::new(&trig),
        &EtOptions::default(),
    )
    .unwrap();
    assert_eq!(out.triggered, Some(true));
}

#[test]
fn new_triggers_validate_their_threshold() {
    for t in [
        Trigger::Stochastic { delta: 0.0 },
        Trigger::SendOnDeltaInflated { delta: -1.0 },
        Trigger::Innovation { delta: f64::NAN },
    ] {
        assert!(t.validate().is_err(), "{t:?}");
    }
    assert!(Trigger::Innovation { delta: 1.0 }.validate().is_ok());
}
