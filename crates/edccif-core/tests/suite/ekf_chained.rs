//! The EKF step bit for bit against its general expressions, and the chained
//! step (`cov_local_chained` from a `CheckedGaussian`) bit for bit against
//! `cov_local`, on seeded runs of every covariance-form filter; the checked
//! estimate and the chained step reject bad input with the named errors of
//! `cov_local` and leave the caller's state as it was.

use crate::common;

use common::{ct, initial_estimate, p0, rng, sensor_of, simulate, x0, Mat7};
use edccif_core::angles::residual;
use edccif_core::models::{LinearMeasurement, RandomWalk};
use edccif_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, SMatrix, SVector, Vector1, Vector2};
use edccif_core::{
    cov_local, cov_local_chained, CheckedGaussian, Error, EtOptions, Gaussian, LocalFilter,
    MeasurementModel, MotionModel, Observation, Trigger, TriggerState,
};

fn bits(g: &Gaussian<f64, 7>) -> Vec<u64> {
    g.x.iter().chain(g.p.iter()).map(|v| v.to_bits()).collect()
}

/// A symmetric, finite, indefinite "covariance" (the 2×2 block [[1, 2], [2, 1]]
/// has the eigenvalue −1).
fn indefinite_7() -> Mat7 {
    let mut p = p0();
    p[(0, 0)] = 1.0;
    p[(1, 1)] = 1.0;
    p[(0, 1)] = 2.0;
    p[(1, 0)] = 2.0;
    p
}

fn sym<const D: usize>(a: &SMatrix<f64, D, D>) -> SMatrix<f64, D, D> {
    (a + a.transpose()) * 0.5
}

/// One EKF step with `Trigger::Always` in the general nalgebra expressions the
/// step is written out from (ALGORITHM.md §5): `x⁻ = f(x)`, `P⁻ = sym(F P Fᵀ + Q)`,
/// `S = sym(G P⁻ Gᵀ + R)`, `K = S⁻¹`-solve of `(P⁻ Gᵀ)ᵀ`, `x = x⁻ + K Δz`,
/// `P = sym(P⁻ − K (P⁻ Gᵀ)ᵀ)`.
fn ekf_reference<F, H>(
    motion: &F,
    sensor: &H,
    est: &Gaussian<f64, 7>,
    z: &SVector<f64, 3>,
) -> Gaussian<f64, 7>
where
    F: MotionModel<f64, 7>,
    H: MeasurementModel<f64, 7, 3>,
{
    let dt = 0.1;
    let f = motion.jacobian(&est.x, dt);
    let xp = motion.transition(&est.x, dt);
    let pp = sym(&(f * est.p * f.transpose() + motion.process_noise(dt)));
    let g = sensor.jacobian(&xp);
    let pxz = pp * g.transpose();
    let s = sym(&(g * pxz + sensor.noise()));
    let dz = residual(sensor, z, &sensor.measure(&xp));
    let k = s.cholesky().unwrap().solve(&pxz.transpose()).transpose();
    Gaussian {
        x: xp + k * dz,
        p: sym(&(pp - k * pxz.transpose())),
    }
}

#[test]
fn ekf_step_equals_its_general_expressions_bit_for_bit() {
    let motion = ct();
    let opts = EtOptions::default();
    let trig = Trigger::Always;
    let ts = TriggerState::new(&trig);
    for (node, seed) in [(0, 41), (1, 42), (3, 43)] {
        let sensor = sensor_of(node, 4);
        let mut r = rng(seed);
        let est0 = initial_estimate(&mut r);
        let (_, obs) = simulate(&mut r, &motion, &sensor, &est0.x, 200);
        let mut est = est0;
        let mut checked = CheckedGaussian::new(&est0).unwrap();
        for (t, o) in obs.iter().enumerate() {
            let Observation::Measured(z) = o else {
                unreachable!("the simulator measures every step")
            };
            let want = ekf_reference(&motion, &sensor, &est, z);
            let plain = cov_local(
                &LocalFilter::Ekf,
                &motion,
                0.1,
                &sensor,
                &est,
                o,
                &trig,
                &ts,
                &opts,
            )
            .unwrap();
            let (chained, next) = cov_local_chained(
                &LocalFilter::Ekf,
                &motion,
                0.1,
                &sensor,
                &checked,
                o,
                &trig,
                &ts,
                &opts,
            )
            .unwrap();
            assert_eq!(bits(&plain.posterior), bits(&want), "node {node}, step {t}");
            assert_eq!(
                bits(&chained.posterior),
                bits(&want),
                "node {node}, step {t}"
            );
            assert_eq!(bits(next.gaussian()), bits(&want), "node {node}, step {t}");
            (est, checked) = (plain.posterior, next);
        }
    }
}

#[test]
fn chained_steps_equal_cov_local_bit_for_bit() {
    let motion = ct();
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let plain_opts = EtOptions::default();
    // A tight gate, so that some triggered measurements are rejected.
    let gated_opts = EtOptions {
        gate: Some(1.0),
        ..plain_opts
    };
    let mut seed = 50;
    for filter in [
        LocalFilter::Ekf,
        LocalFilter::Ckf,
        LocalFilter::ukf_default(),
    ] {
        for (trigger, opts) in [
            (Trigger::Always, plain_opts),
            (sod, plain_opts),
            (sod, gated_opts),
        ] {
            seed += 1;
            let sensor = sensor_of(seed as usize % 4, 4);
            let mut r = rng(seed);
            let est0 = initial_estimate(&mut r);
            let (_, mut obs) = simulate(&mut r, &motion, &sensor, &est0.x, 150);
            for o in obs.iter_mut().skip(5).step_by(7) {
                *o = Observation::Missing;
            }
            let (mut est, mut checked) = (est0, CheckedGaussian::new(&est0).unwrap());
            let (mut ta, mut tb) = (TriggerState::new(&trigger), TriggerState::new(&trigger));
            let (mut quiet, mut gated, mut missing) = (0, 0, 0);
            for (t, o) in obs.iter().enumerate() {
                let a = cov_local(
                    &filter, &motion, 0.1, &sensor, &est, o, &trigger, &ta, &opts,
                )
                .unwrap();
                let (b, next) = cov_local_chained(
                    &filter, &motion, 0.1, &sensor, &checked, o, &trigger, &tb, &opts,
                )
                .unwrap();
                let what = format!("{filter:?} {trigger:?} gate {:?}, step {t}", opts.gate);
                assert_eq!(bits(&a.posterior), bits(&b.posterior), "{what}");
                assert_eq!(bits(next.gaussian()), bits(&a.posterior), "{what}");
                assert_eq!(
                    (a.triggered, a.gated, a.trigger_state),
                    (b.triggered, b.gated, b.trigger_state),
                    "{what}"
                );
                quiet += usize::from(a.triggered == Some(false));
                gated += usize::from(a.gated);
                missing += usize::from(a.triggered.is_none());
                (est, checked, ta, tb) = (a.posterior, next, a.trigger_state, b.trigger_state);
            }
            // every kind of step was exercised
            assert!(missing > 15, "{missing} missing steps");
            if trigger != Trigger::Always && opts.gate.is_none() {
                assert!(quiet > 10, "{filter:?}: {quiet} quiet steps");
            }
            if opts.gate.is_some() {
                assert!(gated > 0, "{filter:?}: no gated step");
            }
        }
    }
}

#[test]
fn checked_gaussian_rejects_bad_estimates_by_name() {
    let nonfinite = |what| Error::NonFinite { what };
    let mut x_nan = x0();
    x_nan[6] = f64::NAN;
    let mut p_inf_upper = p0();
    p_inf_upper[(0, 5)] = f64::INFINITY; // the upper triangle counts too
    let cases = [
        (
            Gaussian { x: x_nan, p: p0() },
            nonfinite("state estimate x"),
        ),
        (
            Gaussian {
                x: x0(),
                p: p0() * f64::NAN,
            },
            nonfinite("covariance P"),
        ),
        (
            Gaussian {
                x: x0(),
                p: p_inf_upper,
            },
            nonfinite("covariance P"),
        ),
        (
            Gaussian {
                x: x0(),
                p: indefinite_7(),
            },
            Error::NotPositiveDefinite {
                what: "covariance P",
            },
        ),
    ];
    let motion = ct();
    let sensor = sensor_of(0, 4);
    let trig = Trigger::Always;
    let ts = TriggerState::new(&trig);
    let z = Observation::Measured(SVector::<f64, 3>::new(5.0, 0.05, 3.1));
    for (g, want) in cases {
        assert_eq!(CheckedGaussian::new(&g).unwrap_err(), want);
        // the error `cov_local` reports for the same estimate
        let got = cov_local(
            &LocalFilter::Ekf,
            &motion,
            0.1,
            &sensor,
            &g,
            &z,
            &trig,
            &ts,
            &EtOptions::default(),
        )
        .unwrap_err();
        assert_eq!(got, want);
    }
    let good = Gaussian { x: x0(), p: p0() };
    assert_eq!(CheckedGaussian::new(&good).unwrap().gaussian(), &good);
}

#[test]
fn chained_step_rejects_bad_input_by_name_and_changes_nothing() {
    let motion = ct();
    let sensor = sensor_of(1, 4);
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let opts = EtOptions::default();
    let est = Gaussian::new(x0(), p0()).unwrap();
    let checked = CheckedGaussian::new(&est).unwrap();
    let ts = TriggerState {
        last_sent: Some(SVector::<f64, 3>::new(5.0, 0.05, 3.1)),
        eta: 0.04,
        rng: 7,
    };
    let (checked_before, ts_before) = (checked, ts);
    let z_ok = Observation::Measured(SVector::<f64, 3>::new(5.0, 0.05, 3.1));
    let z_nan = Observation::Measured(SVector::<f64, 3>::new(5.0, f64::NAN, 3.1));
    let bad_ukf = LocalFilter::Ukf {
        alpha: 1e-3,
        beta: 2.0,
        kappa: -7.0,
    };
    let invalid_dt = Error::InvalidParameter {
        what: "time step dt",
        expected: "finite and > 0",
    };
    for filter in [
        LocalFilter::Ekf,
        LocalFilter::Ckf,
        LocalFilter::ukf_default(),
    ] {
        for (dt, obs, want) in [
            (
                0.1,
                &z_nan,
                Error::NonFinite {
                    what: "measurement z",
                },
            ),
            (0.0, &z_ok, invalid_dt),
            (f64::NAN, &z_ok, invalid_dt),
            (-0.1, &z_ok, invalid_dt),
        ] {
            let got = cov_local_chained(
                &filter, &motion, dt, &sensor, &checked, obs, &sod, &ts, &opts,
            )
            .unwrap_err();
            assert_eq!(got, want, "{filter:?}, dt {dt}");
            let plain = cov_local(&filter, &motion, dt, &sensor, &est, obs, &sod, &ts, &opts);
            assert_eq!(plain.unwrap_err(), want, "{filter:?}, dt {dt}");
        }
    }
    // A UKF whose parameters are invalid: the error of `cov_local`.
    let want = cov_local(
        &bad_ukf, &motion, 0.1, &sensor, &est, &z_ok, &sod, &ts, &opts,
    )
    .unwrap_err();
    assert!(matches!(want, Error::InvalidParameter { .. }));
    assert_eq!(
        cov_local_chained(&bad_ukf, &motion, 0.1, &sensor, &checked, &z_ok, &sod, &ts, &opts)
            .unwrap_err(),
        want
    );
    // the caller's estimate and trigger state are as they were
    assert_eq!(checked, checked_before);
    assert_eq!(ts, ts_before);
}

#[test]
fn chained_step_rejects_a_posterior_that_is_not_positive_definite() {
    // A position measured with a noise far below the rounding of its variance:
    // `P − K Pxzᵀ` cancels to an exact zero on the diagonal.
    let motion = RandomWalk::<f64>::new(0.0).unwrap();
    let sensor =
        LinearMeasurement::<f64, 2, 1>::new(Matrix1x2::new(1.0, 0.0), Matrix1::new(1e-20)).unwrap();
    let est = Gaussian::new(Vector2::new(0.0, 0.0), Matrix2::new(1e16, 0.0, 0.0, 1.0)).unwrap();
    let checked = CheckedGaussian::new(&est).unwrap();
    let trig = Trigger::Always;
    let ts = TriggerState::new(&trig);
    let z = Observation::Measured(Vector1::new(1.0));
    let want = Error::NotPositiveDefinite {
        what: "posterior covariance P",
    };
    for filter in [LocalFilter::Ekf, LocalFilter::Ckf] {
        let plain = cov_local(
            &filter,
            &motion,
            1.0,
            &sensor,
            &est,
            &z,
            &trig,
            &ts,
            &opts(),
        );
        assert_eq!(plain.unwrap_err(), want, "{filter:?}");
        let chained = cov_local_chained(
            &filter,
            &motion,
            1.0,
            &sensor,
            &checked,
            &z,
            &trig,
            &ts,
            &opts(),
        );
        assert_eq!(chained.unwrap_err(), want, "{filter:?}");
    }
    assert_eq!(checked.gaussian(), &est);
}

fn opts() -> EtOptions<f64> {
    EtOptions::default()
}
