//! Opt-in fast trigonometry (`with_fast_trig`) against the reference path, per
//! call: the coordinated turns' sigma points and the sigma measurement statistics
//! (`ẑ` bit for bit, `Pzz`, `Pxz`) within 1e-12 relative to the largest entry
//! (measured: 6.2e-14 and 2.8e-14), and a model that fails to evaluate a point
//! still fails the step.

mod common;

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
    let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    let ct2 = CoordinatedTurn2::new(0.5, 1e-4).unwrap();
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
        assert_eq!(c, fc, "the centre takes the library's sin_cos");
        worst = worst.max(rel(&a, &fa)).max(rel(&b, &fb));
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
    assert_eq!(a.z_hat, b.z_hat, "ẑ is the same circular mean");
    rel(&a.pzz, &b.pzz).max(rel(&a.pxz, &b.pxz))
}

#[test]
fn sigma_measure_matches_the_reference_within_1e_12() {
    let rpa = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01).unwrap();
    let rb = RangeBearing::new([1.0, -2.0], 0.1, 0.01).unwrap();
    let bo = BearingOnly::new([-3.0, 0.5], 0.01).unwrap();
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
