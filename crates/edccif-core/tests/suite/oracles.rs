//! Oracle tests of the local filters: algebraic identities that must hold between
//! the information form, the covariance form and a textbook Kalman filter
//! (ALGORITHM.md §3, §5), and between trigger settings and plain updates.
//!
//! Tolerances are stated at each assertion as `rel` (relative to the Frobenius
//! norm of the reference) and `abs` (absolute), see `common::assert_close`.

use crate::common;

use common::*;
use edccif_core::models::{LinearMeasurement, LinearMotion, RangePitchAzimuth};
use edccif_core::nalgebra::{Matrix2, Matrix2x4, SMatrix, Vector2, Vector4};
use edccif_core::sigma::{point_offsets, sigma_measure, sigma_measure_mean, sigma_predict};
use edccif_core::{
    cif_local, cov_local, kalman_update, untriggered_contribution, EtGain, EtOptions, EtPolicy,
    Gaussian, LocalFilter, MeasurementModel, MotionModel, Observation, SigmaRule, Trigger,
    TriggerState,
};

/// Requirement 1: the CIF with γ ≡ 1 is the CKF written in information form.
/// 50 steps of the default scenario (ALGORITHM.md §1/§6), sensor at (10, 0, 0),
/// noisy measurements from a seeded ChaCha8 generator. Each filter runs its own
/// chain (the CIF never sees the CKF's numbers).
///
/// Tolerance: at every step `‖x_cif − x_ckf‖ ≤ 1e-9·‖x_ckf‖` and
/// `‖P_cif − P_ckf‖_F ≤ 1e-9·‖P_ckf‖_F` (relative; the two forms differ by a
/// Cholesky inversion per step, whose rounding is ~cond(P)·ε ≈ 1e-12).
#[test]
fn cif_always_equals_ckf_on_default_model() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let mut rng = rng(1);
    let start = initial_estimate(&mut rng);
    let (truth, obs) = simulate(&mut rng, &motion, &sensor, &x0(), 50);
    let trig = Trigger::Always;
    let opts = EtOptions::default();
    let (mut cif, mut ckf) = (start, start);
    let (mut ts_cif, mut ts_ckf) = (TriggerState::new(&trig), TriggerState::new(&trig));
    for (k, z) in obs.iter().enumerate() {
        let a = cif_local(&motion, 0.1, &sensor, &cif, z, &trig, &ts_cif, &opts).unwrap();
        let b = cov_local(
            &LocalFilter::Ckf,
            &motion,
            0.1,
            &sensor,
            &ckf,
            z,
            &trig,
            &ts_ckf,
            &opts,
        )
        .unwrap();
        assert_eq!(a.triggered, Some(true));
        assert_eq!(b.triggered, Some(true));
        cif = a.local_posterior().to_gaussian().unwrap();
        ckf = b.posterior;
        ts_cif = a.trigger_state;
        ts_ckf = b.trigger_state;
        let step = format!("step {}", k + 1);
        assert_close(&cif.x, &ckf.x, 1e-9, 0.0, &format!("{step}: x"));
        assert_close(&cif.p, &ckf.p, 1e-9, 0.0, &format!("{step}: P"));
    }
    // A real filter run: the final position error is small (position std is
    // ≈ 0.09 m here; 0.5 m is > 5σ) and consistent with P (NEES-like bound).
    let e = truth.last().unwrap() - ckf.x;
    let e_pos = e.fixed_rows::<3>(0).into_owned();
    assert!(e_pos.norm() < 0.5, "position error {}", e_pos.norm());
    let nees = e.dot(&(ckf.p.try_inverse().unwrap() * e));
    assert!(nees < 30.0, "NEES {nees} (χ²₇ 99.9 % quantile ≈ 24.3)");
}

/// Textbook Kalman filter (plain nalgebra, LU inverses, Joseph form).
struct Kf {
    f: SMatrix<f64, 4, 4>,
    q: SMatrix<f64, 4, 4>,
    h: Matrix2x4<f64>,
    r: Matrix2<f64>,
}

impl Kf {
    fn step(&self, g: &Gaussian<f64, 4>, z: Option<&Vector2<f64>>) -> Gaussian<f64, 4> {
        let x = self.f * g.x;
        let p = self.f * g.p * self.f.transpose() + self.q;
        let Some(z) = z else { return Gaussian { x, p } };
        let s = self.h * p * self.h.transpose() + self.r;
        let k = p * self.h.transpose() * s.try_inverse().unwrap();
        let a = SMatrix::<f64, 4, 4>::identity() - k * self.h;
        Gaussian {
            x: x + k * (z - self.h * x),
            p: a * p * a.transpose() + k * self.r * k.transpose(),
        }
    }
}

/// Requirement 2: on a linear-Gaussian model the CKF, the CIF, the EKF and the
/// UKF ((α, β, κ) = (1, 2, 0)) all reduce to the Kalman filter. 2-D constant
/// velocity (n = 4), a correlated 2-D measurement with a non-trivial H, 40 steps,
/// every 7th measurement missing (pure prediction).
///
/// Tolerance: `‖x − x_kf‖ ≤ 1e-9·‖x_kf‖ + 1e-12`, `‖P − P_kf‖_F ≤ 1e-9·‖P_kf‖_F`
/// at every step (the forms are algebraically identical; rounding is ~1e-14).
#[test]
fn linear_model_all_filters_equal_textbook_kf() {
    let dt = 0.5;
    let f = SMatrix::<f64, 4, 4>::from_row_slice(&[
        1.0, 0.0, dt, 0.0, //
        0.0, 1.0, 0.0, dt, //
        0.0, 0.0, 1.0, 0.0, //
        0.0, 0.0, 0.0, 1.0,
    ]);
    let qa = 0.2;
    let q = SMatrix::<f64, 4, 4>::from_row_slice(&[
        qa * dt.powi(3) / 3.0,
        0.0,
        qa * dt * dt / 2.0,
        0.0, //
        0.0,
        qa * dt.powi(3) / 3.0,
        0.0,
        qa * dt * dt / 2.0, //
        qa * dt * dt / 2.0,
        0.0,
        qa * dt,
        0.0, //
        0.0,
        qa * dt * dt / 2.0,
        0.0,
        qa * dt,
    ]);
    let h = Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.3, 1.0, 0.0, 0.1);
    let r = Matrix2::new(0.04, 0.01, 0.01, 0.09);
    let kf = Kf { f, q, h, r };
    let motion = LinearMotion::new(f, q).unwrap();
    let sensor = LinearMeasurement::new(h, r).unwrap();

    let mut rng = rng(2);
    let truth0 = Vector4::new(0.0, 1.0, 1.0, -0.5);
    let (_, mut obs) = simulate::<_, _, 4, 2>(&mut rng, &motion, &sensor, &truth0, 40);
    for k in (6..obs.len()).step_by(7) {
        obs[k] = Observation::Missing;
    }
    let p_start = SMatrix::<f64, 4, 4>::from_row_slice(&[
        1.0, 0.1, 0.0, 0.0, //
        0.1, 1.0, 0.0, 0.2, //
        0.0, 0.0, 0.5, 0.0, //
        0.0, 0.2, 0.0, 0.5,
    ]);
    let start = Gaussian::new(truth0 + sample(&mut rng, &p_start), p_start).unwrap();

    let trig = Trigger::Always;
    let ts = TriggerState::new(&trig);
    let opts = EtOptions::default();
    let filters = [
        ("CKF", LocalFilter::Ckf),
        ("EKF", LocalFilter::Ekf),
        ("UKF", LocalFilter::ukf_default()),
    ];
    let mut oracle = start;
    let mut cov_est = [start; 3];
    let mut cif = start;
    for (k, z) in obs.iter().enumerate() {
        let zv = match z {
            Observation::Measured(v) => Some(v),
            Observation::Missing => None,
        };
        oracle = kf.step(&oracle, zv);
        for ((name, filt), est) in filters.iter().zip(cov_est.iter_mut()) {
            *est = cov_local(filt, &motion, 0.1, &sensor, est, z, &trig, &ts, &opts)
                .unwrap()
                .posterior;
            assert_close(
                &est.x,
                &oracle.x,
                1e-9,
                1e-12,
                &format!("{name} x, step {k}"),
            );
            assert_close(&est.p, &oracle.p, 1e-9, 0.0, &format!("{name} P, step {k}"));
        }
        let c = cif_local(&motion, 0.1, &sensor, &cif, z, &trig, &ts, &opts).unwrap();
        assert_eq!(c.triggered, zv.map(|_| true));
        cif = c.local_posterior().to_gaussian().unwrap();
        assert_close(&cif.x, &oracle.x, 1e-9, 1e-12, &format!("CIF x, step {k}"));
        assert_close(&cif.p, &oracle.p, 1e-9, 0.0, &format!("CIF P, step {k}"));
    }
}

/// A predicted state of the default scenario after `steps` CKF steps from the
/// §6 start, with a measurement `z_τ` of the truth: `(x̂⁻, P⁻, Y⁻, ẑ, G, z_τ)`.
struct UntriggeredCase {
    x_prior: Vec7,
    p_prior: Mat7,
    y_prior: Mat7,
    z_hat: Vec3,
    g: SMatrix<f64, 3, 7>,
    z_tau: Vec3,
}

fn untriggered_case(seed: u64, steps: usize) -> (RangePitchAzimuth<f64>, UntriggeredCase) {
    let motion = ct();
    let sensor = sensor_of(seed as usize % 4, 4);
    let mut rng = rng(seed);
    let mut est = initial_estimate(&mut rng);
    let (_, obs) = simulate(&mut rng, &motion, &sensor, &x0(), steps + 1);
    let trig = Trigger::Always;
    let ts = TriggerState::new(&trig);
    let opts = EtOptions::default();
    for z in &obs[..steps] {
        est = cov_local(
            &LocalFilter::Ckf,
            &motion,
            0.1,
            &sensor,
            &est,
            z,
            &trig,
            &ts,
            &opts,
        )
        .unwrap()
        .posterior;
    }
    let rule = SigmaRule::cubature(7);
    let (x_prior, p_prior) = sigma_predict(&rule, &motion, 0.1, &est.x, &est.p).unwrap();
    let ch = p_prior.cholesky().unwrap();
    let y_prior = p_prior.try_inverse().unwrap();
    let y_prior = (y_prior + y_prior.transpose()) * 0.5;
    let z_hat = sigma_measure_mean(&rule, &sensor, &x_prior, &point_offsets(&ch, &rule)).unwrap();
    let g = MeasurementModel::<f64, 7, 3>::jacobian(&sensor, &x_prior);
    let Observation::Measured(z_tau) = obs[steps] else {
        unreachable!()
    };
    (
        sensor,
        UntriggeredCase {
            x_prior,
            p_prior,
            y_prior,
            z_hat,
            g,
            z_tau,
        },
    )
}

/// Requirement 3 (a): the untriggered contribution equals the paper's N-form
/// `Ī = −Y⁻[N⁻¹ + Y⁻]⁻¹Y⁻`, `N = P̄ − P⁻`, where N is well conditioned
/// (σ1 = σ2 = 0.5, δ = 0.04), on several prior states of the default scenario.
///
/// Precondition checked: cond(N) < 1e6. Tolerance:
/// `‖Ī − Ī_N‖_F ≤ 1e-9·‖Y⁻‖_F` (both are differences of O(‖Y⁻‖) quantities).
#[test]
fn untriggered_information_matches_paper_n_form() {
    let opts = EtOptions {
        policy: EtPolicy::Optimal,
        sigma1: 0.5,
        sigma2: 0.5,
        gate: None,
        untriggered_closed_form: false,
    };
    for (seed, steps) in [(10, 0), (11, 5), (12, 20), (13, 40)] {
        let (sensor, c) = untriggered_case(seed, steps);
        let r = MeasurementModel::<f64, 7, 3>::noise(&sensor);
        let gain = EtGain::new(&c.p_prior, &c.g, &r, 0.04, &opts).unwrap();
        let dz = edccif_core::angles::residual::<f64, _, 7, 3>(&sensor, &c.z_tau, &c.z_hat);
        let contrib = untriggered_contribution(&c.x_prior, &c.y_prior, &c.g, &gain, &dz).unwrap();

        let n = gain.p_bar - c.p_prior;
        let sv = n.singular_values();
        let cond = sv.max() / sv.min();
        assert!(
            cond < 1e6,
            "seed {seed}: N is ill conditioned, cond = {cond:e}"
        );
        let y = c.y_prior;
        let i_n = -(y * (n.try_inverse().unwrap() + y).try_inverse().unwrap() * y);
        assert_close(
            &contrib.imat,
            &i_n,
            0.0,
            1e-9 * y.norm(),
            &format!("seed {seed}: Ī"),
        );
        // The contribution is genuinely non-trivial (and not PSD: an untriggered
        // step both adds information along G and removes μ1-inflation elsewhere).
        assert!(contrib.imat.norm() > 1e-3 * y.norm());
    }
}

/// Requirement 3 (b): `Ī = P̄⁻¹ − Y⁻` for small and large σ and δ, with M, P̄ and
/// ī re-derived by hand from ALGORITHM.md §3 (LU inverses, no symmetrisation
/// shortcuts), and the posterior `(Y⁻+Ī)⁻¹(ŷ⁻+ī) = x̂⁻ + M Δz̄`, `(Y⁻+Ī)⁻¹ = P̄`.
///
/// Tolerances: M, P̄ `rel 1e-9`; Ī, ī `1e-9·‖Y⁻‖` resp. `1e-9·‖Y⁻‖·‖x̂⁻‖`
/// absolute; posterior mean `rel 1e-9`, covariance `rel 1e-8` (it passes through
/// two inversions of matrices with cond ≈ 1e4).
#[test]
fn untriggered_contribution_equals_pbar_inverse_minus_prior() {
    for (seed, steps) in [(20, 0), (21, 3), (22, 15), (23, 30)] {
        let (sensor, c) = untriggered_case(seed, steps);
        let r = MeasurementModel::<f64, 7, 3>::noise(&sensor);
        for (sigma, delta) in [(5e-4, 0.04), (0.5, 0.04), (5e-4, 1.0), (0.05, 1e-3)] {
            let opts = EtOptions {
                policy: EtPolicy::Optimal,
                sigma1: sigma,
                sigma2: sigma,
                gate: None,
                untriggered_closed_form: false,
            };
            let tag = format!("seed {seed}, σ {sigma}, δ {delta}");
            let gain = EtGain::new(&c.p_prior, &c.g, &r, delta, &opts).unwrap();
            let dz = edccif_core::angles::residual::<f64, _, 7, 3>(&sensor, &c.z_tau, &c.z_hat);
            let contrib =
                untriggered_contribution(&c.x_prior, &c.y_prior, &c.g, &gain, &dz).unwrap();

            // ALGORITHM.md §3 step 5, γ = 0, by hand.
            let (mu1, mu2, mu3) = (1.0 + sigma, 1.0 + sigma, 1.0 + 2.0 / sigma);
            let s = mu1 * c.g * c.p_prior * c.g.transpose()
                + mu2 * r
                + mu3 * delta * SMatrix::<f64, 3, 3>::identity();
            let s_inv = s.try_inverse().unwrap();
            let m = mu1 * c.p_prior * c.g.transpose() * s_inv;
            let p_bar = mu1 * (Mat7::identity() - m * c.g) * c.p_prior;
            assert_close(&gain.m, &m, 1e-9, 0.0, &format!("{tag}: M"));
            assert_close(&gain.p_bar, &p_bar, 1e-9, 0.0, &format!("{tag}: P̄"));
            let y = c.y_prior;
            let i_direct = p_bar.try_inverse().unwrap() - y;
            assert_close(
                &contrib.imat,
                &i_direct,
                0.0,
                1e-9 * y.norm(),
                &format!("{tag}: Ī"),
            );
            let i_vec = mu1 * c.g.transpose() * s_inv * dz + i_direct * (c.x_prior + m * dz);
            let scale = y.norm() * c.x_prior.norm();
            assert_close(&contrib.i, &i_vec, 0.0, 1e-9 * scale, &format!("{tag}: ī"));

            // Posterior of the untriggered step: x̂⁻ + M Δz̄ with covariance P̄.
            let y_post = y + contrib.imat;
            let p_post = y_post.try_inverse().unwrap();
            let x_post = p_post * (y * c.x_prior + contrib.i);
            assert_close(
                &x_post,
                &(c.x_prior + m * dz),
                1e-9,
                0.0,
                &format!("{tag}: x̂"),
            );
            assert_close(&p_post, &p_bar, 1e-8, 0.0, &format!("{tag}: P"));
        }
    }
}

/// The untriggered branch of `cif_local` is exactly `untriggered_contribution` at
/// its prior, with `Δz̄ = z_τ − ẑ` (the held measurement, not the new one).
#[test]
fn cif_local_untriggered_step_uses_held_measurement() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let mut rng = rng(30);
    let est = initial_estimate(&mut rng);
    let z_tau = measure(&mut rng, &sensor, &motion.transition(&x0(), 0.1));
    let z_new = z_tau + Vec3::new(0.1, 0.05, -0.05); // ‖Δ‖² = 0.015 ≤ δ
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let state = TriggerState {
        last_sent: Some(z_tau),
        eta: 0.04,
        rng: 0,
    };
    // the stable form, which this oracle's equations are
    let opts = EtOptions {
        untriggered_closed_form: false,
        ..EtOptions::default()
    };
    let out = cif_local(
        &motion,
        0.1,
        &sensor,
        &est,
        &Observation::Measured(z_new),
        &trig,
        &state,
        &opts,
    )
    .unwrap();
    assert_eq!(out.triggered, Some(false));
    assert_eq!(out.trigger_state, state, "z_τ is kept when γ = 0");

    let rule = SigmaRule::cubature(7);
    let ch = out.p_prior.cholesky().unwrap();
    let z_hat =
        sigma_measure_mean(&rule, &sensor, &out.x_prior, &point_offsets(&ch, &rule)).unwrap();
    let g = MeasurementModel::<f64, 7, 3>::jacobian(&sensor, &out.x_prior);
    let r = MeasurementModel::<f64, 7, 3>::noise(&sensor);
    let gain = EtGain::new(&out.p_prior, &g, &r, 0.04, &opts).unwrap();
    let dz = edccif_core::angles::residual::<f64, _, 7, 3>(&sensor, &z_tau, &z_hat);
    let expected = untriggered_contribution(&out.x_prior, &out.prior.ymat, &g, &gain, &dz).unwrap();
    // Same code path, same inputs: bit-identical.
    assert_eq!(out.contribution, expected);
}

/// Requirement 10 (a): `Trigger::Never` with `EtPolicy::Skip` is pure prediction,
/// in both forms, over 20 steps. The covariance form is bit-identical to a chain
/// of `sigma_predict`; the information form returns the prior (ī = 0, Ī = 0) and
/// round-trips it to `rel 1e-9`. With `Never`, no `z_τ` ever exists, so the
/// `Optimal` policy also has nothing to use and gives the same zero contribution.
#[test]
fn never_trigger_equals_pure_prediction() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let mut rng = rng(40);
    let start = initial_estimate(&mut rng);
    let (_, obs) = simulate(&mut rng, &motion, &sensor, &x0(), 20);
    let trig = Trigger::Never;
    let ts = TriggerState::new(&trig);
    let rule = SigmaRule::cubature(7);
    for policy in [EtPolicy::Skip, EtPolicy::Optimal, EtPolicy::Hold] {
        let opts = EtOptions {
            policy,
            ..EtOptions::default()
        };
        let (mut pred, mut cov, mut cif) = (start, start, start);
        for z in &obs {
            let (x, p) = sigma_predict(&rule, &motion, 0.1, &pred.x, &pred.p).unwrap();
            pred = Gaussian { x, p };
            let c = cov_local(
                &LocalFilter::Ckf,
                &motion,
                0.1,
                &sensor,
                &cov,
                z,
                &trig,
                &ts,
                &opts,
            )
            .unwrap();
            assert_eq!(c.triggered, Some(false));
            assert_eq!(c.trigger_state, ts);
            cov = c.posterior;
            assert_eq!(
                cov, pred,
                "{policy:?}: covariance form must be the prediction"
            );

            let i = cif_local(&motion, 0.1, &sensor, &cif, z, &trig, &ts, &opts).unwrap();
            assert_eq!(i.triggered, Some(false));
            assert_eq!(i.contribution, edccif_core::Contribution::zeros());
            cif = i.local_posterior().to_gaussian().unwrap();
            assert_close(&cif.x, &pred.x, 1e-9, 0.0, &format!("{policy:?}: CIF x"));
            assert_close(&cif.p, &pred.p, 1e-9, 0.0, &format!("{policy:?}: CIF P"));
        }
    }
}

/// Requirement 10 (b): `Trigger::Always` in `cov_local` is the plain CKF,
/// assembled here from the public pieces (`sigma_predict`, `sigma_measure`,
/// `kalman_update` with the angle-wrapped innovation): bit-identical, 30 steps.
#[test]
fn always_trigger_equals_plain_ckf() {
    let motion = ct();
    let sensor = rpa([0.0, 10.0, 3.0]);
    let mut rng = rng(41);
    let start = initial_estimate(&mut rng);
    let (_, obs) = simulate(&mut rng, &motion, &sensor, &x0(), 30);
    let trig = Trigger::Always;
    let opts = EtOptions::default();
    let rule = SigmaRule::cubature(7);
    let (mut a, mut b) = (start, start);
    let mut ts = TriggerState::new(&trig);
    for z in &obs {
        let out = cov_local(
            &LocalFilter::Ckf,
            &motion,
            0.1,
            &sensor,
            &a,
            z,
            &trig,
            &ts,
            &opts,
        )
        .unwrap();
        ts = out.trigger_state;
        a = out.posterior;
        let Observation::Measured(zv) = z else {
            unreachable!()
        };
        assert_eq!(ts.last_sent, Some(*zv));
        let (x, p) = sigma_predict(&rule, &motion, 0.1, &b.x, &b.p).unwrap();
        let ch = p.cholesky().unwrap();
        let st = sigma_measure(&rule, &sensor, &x, &point_offsets(&ch, &rule)).unwrap();
        let dz = edccif_core::angles::residual::<f64, _, 7, 3>(&sensor, zv, &st.z_hat);
        b = kalman_update(&x, &p, &st.pxz, &st.pzz, &dz).unwrap();
        assert_eq!(a, b);
    }
}

/// Requirement 10 (c): `EtPolicy::Hold` at an untriggered step is the triggered
/// update with `z_τ`: bit-identical contributions (CIF) and posteriors (CKF, UKF).
#[test]
fn hold_policy_equals_triggered_update_with_z_tau() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let mut rng = rng(42);
    let est = initial_estimate(&mut rng);
    let z_tau = measure(&mut rng, &sensor, &motion.transition(&x0(), 0.1));
    let z_new = Observation::Measured(z_tau + Vec3::new(-0.15, 0.01, 0.02)); // ‖Δ‖² ≈ 0.0228 ≤ δ
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let held = TriggerState {
        last_sent: Some(z_tau),
        eta: 0.04,
        rng: 0,
    };
    let hold = EtOptions {
        policy: EtPolicy::Hold,
        ..EtOptions::default()
    };
    let always = Trigger::Always;
    let fresh = TriggerState::new(&always);
    let z_tau_obs = Observation::Measured(z_tau);

    let a = cif_local(&motion, 0.1, &sensor, &est, &z_new, &trig, &held, &hold).unwrap();
    let b = cif_local(
        &motion, 0.1, &sensor, &est, &z_tau_obs, &always, &fresh, &hold,
    )
    .unwrap();
    assert_eq!(a.triggered, Some(false));
    assert_eq!(b.triggered, Some(true));
    assert_eq!(a.prior, b.prior);
    assert_eq!(a.contribution, b.contribution);

    for filt in [
        LocalFilter::Ckf,
        LocalFilter::ukf_default(),
        LocalFilter::Ekf,
    ] {
        let a = cov_local(
            &filt, &motion, 0.1, &sensor, &est, &z_new, &trig, &held, &hold,
        )
        .unwrap();
        let b = cov_local(
            &filt, &motion, 0.1, &sensor, &est, &z_tau_obs, &always, &fresh, &hold,
        )
        .unwrap();
        assert_eq!(a.triggered, Some(false));
        assert_eq!(a.posterior, b.posterior, "{filt:?}");
    }
}

/// ET-CIF and ET-CKF are the same filter under send-on-delta: a triggered CIF
/// step is the CKF update (requirement 1) and an untriggered one has posterior
/// `(x̂⁻ + M Δz̄, P̄)` (requirement 3), which is exactly the covariance-form
/// untriggered step. 60 steps of the default scenario with δ = 0.04, both
/// triggered and untriggered steps occurring.
///
/// Tolerance: `rel 1e-9` on x and P at every step.
#[test]
fn et_cif_equals_et_ckf_under_send_on_delta() {
    let motion = ct();
    let sensor = rpa([10.0, 0.0, 0.0]);
    let mut rng = rng(43);
    let start = initial_estimate(&mut rng);
    let (_, obs) = simulate(&mut rng, &motion, &sensor, &x0(), 60);
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let opts = EtOptions::default();
    let (mut cif, mut ckf) = (start, start);
    let (mut ts_a, mut ts_b) = (TriggerState::new(&trig), TriggerState::new(&trig));
    let mut sent = 0;
    for (k, z) in obs.iter().enumerate() {
        let a = cif_local(&motion, 0.1, &sensor, &cif, z, &trig, &ts_a, &opts).unwrap();
        let b = cov_local(
            &LocalFilter::Ckf,
            &motion,
            0.1,
            &sensor,
            &ckf,
            z,
            &trig,
            &ts_b,
            &opts,
        )
        .unwrap();
        assert_eq!(a.triggered, b.triggered, "step {k}");
        sent += usize::from(a.triggered == Some(true));
        cif = a.local_posterior().to_gaussian().unwrap();
        ckf = b.posterior;
        ts_a = a.trigger_state;
        ts_b = b.trigger_state;
        assert_close(&cif.x, &ckf.x, 1e-9, 0.0, &format!("step {k}: x"));
        assert_close(&cif.p, &ckf.p, 1e-9, 0.0, &format!("step {k}: P"));
    }
    assert!(
        sent > 3 && sent < 57,
        "both branches must be exercised, sent {sent}/60"
    );
}

/// The error-minimised gain degenerates correctly: as δ → 0 and σ → 0 the
/// untriggered covariance update tends to the EKF update `(I − K G) P⁻`.
/// Tolerance: rel 1e-5 at σ = 1e-9, δ = 0 (the gap is O(σ)).
#[test]
fn et_gain_tends_to_kalman_gain() {
    let (sensor, c) = untriggered_case(50, 10);
    let r = MeasurementModel::<f64, 7, 3>::noise(&sensor);
    let opts = EtOptions {
        policy: EtPolicy::Optimal,
        sigma1: 1e-9,
        sigma2: 1e-9,
        gate: None,
        untriggered_closed_form: false,
    };
    let gain = EtGain::new(&c.p_prior, &c.g, &r, 0.0, &opts).unwrap();
    let s = c.g * c.p_prior * c.g.transpose() + r;
    let k = c.p_prior * c.g.transpose() * s.try_inverse().unwrap();
    assert_close(&gain.m, &k, 1e-5, 0.0, "M → K");
    let p = (Mat7::identity() - k * c.g) * c.p_prior;
    assert_close(&gain.p_bar, &p, 1e-5, 0.0, "P̄ → (I − KG)P⁻");
}
