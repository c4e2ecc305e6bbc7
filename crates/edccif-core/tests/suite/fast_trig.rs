//! The fast trigonometry (`with_fast_trig`, on by default) against the reference path, per
//! call: the coordinated turns' sigma points and the sigma measurement statistics
//! (`Pzz`, `Pxz`) within 1e-12 relative to the largest entry (measured: 6.2e-14
//! and 2.8e-14), `ẑ`'s angles within 1e-15 absolute, the EKF's model calls
//! (`h`, `f`, `F`) within 1e-14 relative (measured: 2.2e-16 and 9.9e-16), a
//! seeded 200-step EKF run within 1e-13 relative (measured: 1.9e-15), and a
//! model that fails to evaluate a point still fails the step.

use crate::common;

use common::{lcg_next, lower_factor, rel};
use edccif_core::model::MotionModel;
use edccif_core::models::{
    BearingOnly, CoordinatedTurn, CoordinatedTurn2, RangeBearing, RangePitchAzimuth,
};
use edccif_core::sigma::{sigma_measure, SigmaRule};
use edccif_core::{Error, MeasurementModel};
use nalgebra::{SMatrix, SVector};

/// This file's random factors: a positive diagonal of scale `s`.
fn factor<const D: usize>(seed: &mut u64, s: f64) -> SMatrix<f64, D, D> {
    lower_factor(seed, s, 1.0, 1.0)
}

fn points<F: MotionModel<f64, N>, const N: usize>(
    m: &F,
    x: &SVector<f64, N>,
    l: &SMatrix<f64, N, N>,
) -> (SMatrix<f64, N, N>, SMatrix<f64, N, N>, SVector<f64, N>) {
    let (mut p, mut q, mut c) = (SMatrix::zeros(), SMatrix::zeros(), SVector::zeros());
    m.transition_points(x, l, 0.1, &mut p, &mut q, Some(&mut c));
    (p, q, c)
}

#[test]
fn turn_points_match_the_reference_within_1e_12() {
    let ct = CoordinatedTurn::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
    let ct2 = CoordinatedTurn2::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
    let mut seed = 3;
    let mut worst = 0.0f64;
    for round in 0..300 {
        // turn rates from 0 to ±3 rad/s; offsets small (series) and large (libm)
        let w = 6.0 * lcg_next(&mut seed) * f64::from(round % 3 != 0);
        let s = if round % 5 == 0 { 5.0 } else { 0.3 };
        let x = SVector::<f64, 7>::from_fn(|i, _| {
            if i == 6 {
                w
            } else {
                20.0 * lcg_next(&mut seed)
            }
        });
        let l = factor::<7>(&mut seed, s);
        let (a, b, c) = points(&ct, &x, &l);
        let (fa, fb, fc) = points(&ct.with_fast_trig(true), &x, &l);
        worst = worst.max(rel(&a, &fa)).max(rel(&b, &fb)).max(rel(&c, &fc));
        let x2 = SVector::<f64, 5>::from_fn(|i, _| {
            if i == 4 {
                w
            } else {
                20.0 * lcg_next(&mut seed)
            }
        });
        let l2 = factor::<5>(&mut seed, s);
        let (a, b, _) = points(&ct2, &x2, &l2);
        let (fa, fb, _) = points(&ct2.with_fast_trig(true), &x2, &l2);
        worst = worst.max(rel(&a, &fa)).max(rel(&b, &fb));
    }
    eprintln!("turn points: largest relative difference {worst:e}");
    // Not the reference path under another name, and within the bound.
    assert!(
        worst > 0.0 && worst < 1e-12,
        "largest relative difference {worst:e}"
    );
}

fn stats_close<H: MeasurementModel<f64, N, M>, const N: usize, const M: usize>(
    reference: &H,
    fast: &H,
    x: &SVector<f64, N>,
    l: &SMatrix<f64, N, N>,
    rule: &SigmaRule<f64>,
) -> f64 {
    let a = sigma_measure(rule, reference, x, l).unwrap();
    let b = sigma_measure(rule, fast, x, l).unwrap();
    // ẑ: the same weighted sums; the angles' atan2 by the kernel, within 1e-15
    // absolute (2 ulp of π), the other components bit for bit.
    for k in 0..M {
        if reference.is_angle(k) {
            let d = (a.z_hat[k] - b.z_hat[k]).abs();
            assert!(d <= 1e-15, "ẑ[{k}]: {} vs {}", a.z_hat[k], b.z_hat[k]);
        } else {
            assert_eq!(a.z_hat[k], b.z_hat[k], "ẑ[{k}] is not an angle");
        }
    }
    rel(&a.pzz, &b.pzz).max(rel(&a.pxz, &b.pxz))
}

#[test]
fn sigma_measure_matches_the_reference_within_1e_12() {
    let rpa = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false);
    let rb = RangeBearing::new([1.0, -2.0], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false);
    let bo = BearingOnly::new([-3.0, 0.5], 0.01)
        .unwrap()
        .with_fast_trig(false);
    let rules = [
        SigmaRule::cubature(7),
        SigmaRule::unscented(7, 1.0, 2.0, 0.0).unwrap(),
    ];
    let mut seed = 5;
    let mut worst = 0.0f64;
    for round in 0..300 {
        let rule = &rules[round % 2];
        // small spreads (series), and spreads wide enough for the atan2 branch
        let s = if round % 4 == 0 { 3.0 } else { 0.2 };
        let x = SVector::<f64, 7>::from_fn(|_, _| 20.0 * lcg_next(&mut seed));
        let l = factor::<7>(&mut seed, s);
        worst = worst.max(stats_close(&rpa, &rpa.with_fast_trig(true), &x, &l, rule));
        worst = worst.max(stats_close(&rb, &rb.with_fast_trig(true), &x, &l, rule));
        worst = worst.max(stats_close(&bo, &bo.with_fast_trig(true), &x, &l, rule));
    }
    eprintln!("Pzz, Pxz: largest relative difference {worst:e}");
    assert!(
        worst > 0.0 && worst < 1e-12,
        "largest relative difference {worst:e}"
    );
}

#[test]
fn fast_path_still_fails_on_a_point_it_cannot_evaluate() {
    let rpa = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(true);
    let mut x = SVector::<f64, 7>::from_element(1.0);
    x[0] = f64::NAN;
    let l = SMatrix::<f64, 7, 7>::identity();
    let r = sigma_measure(&SigmaRule::cubature(7), &rpa, &x, &l);
    assert!(matches!(r, Err(Error::NonFinite { .. })), "{r:?}");
}

/// The EKF's model calls with fast trigonometry on: the sensors' `h(x)` (its
/// angles by the kernel's `atan2`) and the turns' `f(x)`, `F(x)` (the kernel's
/// `sin_cos`) within 1e-14 relative to the largest entry of the reference's,
/// the sensors' Jacobians (no trigonometry) bit for bit.
#[test]
fn ekf_model_calls_match_the_reference_within_1e_14() {
    let rpa = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false);
    let rb = RangeBearing::new([1.0, -2.0], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false);
    let bo = BearingOnly::new([-3.0, 0.5], 0.01)
        .unwrap()
        .with_fast_trig(false);
    let ct = CoordinatedTurn::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
    let ct2 = CoordinatedTurn2::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
    let mut seed = 11;
    let (mut worst_h, mut worst_f) = (0.0f64, 0.0f64);
    for round in 0..2000 {
        let x = SVector::<f64, 7>::from_fn(|i, _| {
            let u = 2.0 * lcg_next(&mut seed) - 1.0;
            if i == 6 {
                // turn rates up to ±40 rad/s: ω dt beyond π/4 (reduced)
                u * if round % 4 == 0 { 40.0 } else { 3.0 }
            } else {
                30.0 * u
            }
        });
        let (z, g) = rpa.measure_with_jacobian(&x);
        let (zf, gf) = rpa.with_fast_trig(true).measure_with_jacobian(&x);
        assert_eq!(g, gf, "the Jacobian has no trigonometry");
        assert_eq!(
            zf,
            rpa.with_fast_trig(true).measure(&x),
            "h and (h, G) agree"
        );
        worst_h = worst_h.max(rel(&z, &zf));
        let (z2, z2f) = (
            MeasurementModel::<f64, 7, 2>::measure(&rb, &x),
            MeasurementModel::<f64, 7, 2>::measure(&rb.with_fast_trig(true), &x),
        );
        worst_h = worst_h.max(rel(&z2, &z2f));
        let (z1, z1f) = (
            MeasurementModel::<f64, 7, 1>::measure(&bo, &x),
            MeasurementModel::<f64, 7, 1>::measure(&bo.with_fast_trig(true), &x),
        );
        worst_h = worst_h.max(rel(&z1, &z1f));
        let fast = ct.with_fast_trig(true);
        let (y, f) = ct.transition_with_jacobian(&x, 0.1);
        let (yf, ff) = fast.transition_with_jacobian(&x, 0.1);
        assert_eq!(yf, fast.transition(&x, 0.1), "f and (f, F) agree");
        assert_eq!(ff, fast.jacobian(&x, 0.1), "F and (f, F) agree");
        worst_f = worst_f.max(rel(&y, &yf)).max(rel(&f, &ff));
        let x2 = SVector::<f64, 5>::from_fn(|i, _| x[i + 2]);
        let fast2 = ct2.with_fast_trig(true);
        let (y2, f2) = ct2.transition_with_jacobian(&x2, 0.1);
        let (y2f, f2f) = fast2.transition_with_jacobian(&x2, 0.1);
        assert_eq!(y2f, fast2.transition(&x2, 0.1), "f and (f, F) agree");
        assert_eq!(f2f, fast2.jacobian(&x2, 0.1), "F and (f, F) agree");
        worst_f = worst_f.max(rel(&y2, &y2f)).max(rel(&f2, &f2f));
    }
    eprintln!("EKF calls: h largest relative difference {worst_h:e}, f/F {worst_f:e}");
    assert!(
        worst_h > 0.0 && worst_h < 1e-14,
        "h: largest relative difference {worst_h:e}"
    );
    assert!(
        worst_f > 0.0 && worst_f < 1e-14,
        "f, F: largest relative difference {worst_f:e}"
    );
}

/// A seeded 200-step local EKF run (`cov_local`, every measurement sent and
/// send-on-delta) with fast trigonometry on in both models against the
/// reference path: the same trigger decisions, every estimate entry within
/// 1e-13 relative to the largest entry of the reference's state or covariance
/// at that step (measured: at most 1.9e-15).
#[test]
fn ekf_run_with_fast_trig_stays_within_1e_13_of_the_reference() {
    use common::{ct, initial_estimate, rng, sensor_of, simulate};
    use edccif_core::{cov_local, EtOptions, LocalFilter, Trigger, TriggerState};
    let opts = EtOptions::default();
    let mut worst = 0.0f64;
    for (trigger, seed) in [
        (Trigger::Always, 71),
        (Trigger::SendOnDelta { delta: 0.04 }, 72),
    ] {
        let (motion, sensor) = (ct(), sensor_of(1, 4));
        let (fm, fs) = (motion.with_fast_trig(true), sensor.with_fast_trig(true));
        let mut r = rng(seed);
        let est0 = initial_estimate(&mut r);
        let (_, obs) = simulate(&mut r, &motion, &sensor, &est0.x, 200);
        let (mut a, mut b) = (est0, est0);
        let (mut ta, mut tb) = (TriggerState::new(&trigger), TriggerState::new(&trigger));
        for (t, o) in obs.iter().enumerate() {
            let sa = cov_local(
                &LocalFilter::Ekf,
                &motion,
                0.1,
                &sensor,
                &a,
                o,
                &trigger,
                &ta,
                &opts,
            )
            .unwrap();
            let sb = cov_local(
                &LocalFilter::Ekf,
                &fm,
                0.1,
                &fs,
                &b,
                o,
                &trigger,
                &tb,
                &opts,
            )
            .unwrap();
            assert_eq!(sa.triggered, sb.triggered, "step {t}: trigger decision");
            (a, b, ta, tb) = (
                sa.posterior,
                sb.posterior,
                sa.trigger_state,
                sb.trigger_state,
            );
            worst = worst.max(rel(&a.x, &b.x)).max(rel(&a.p, &b.p));
        }
    }
    eprintln!("EKF 200-step runs: largest relative difference {worst:e}");
    assert!(
        worst > 0.0 && worst < 1e-13,
        "largest relative difference {worst:e}"
    );
}
