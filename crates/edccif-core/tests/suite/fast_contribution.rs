//! The triggered contribution from the prior's Cholesky factor
//! (`triggered_contribution_factored`, the fast path of `cif_update`) against
//! `triggered_contribution` with `Y⁻ = P⁻⁻¹`: the same `(ī, Ī)` within 1e-12
//! relative to the largest entry on random priors and statistics, the same
//! errors on bad input, and the same `cif_update` step with and without fast
//! trigonometry up to the sigma points' rounding.

use crate::common;

use common::{lcg_next, lower_factor, rel};
use edccif_core::linalg::lower_inverse;
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::sigma::{sigma_measure, SigmaRule};
use edccif_core::{
    cif_predict, cif_update, triggered_contribution, triggered_contribution_factored, Contribution,
    Error, EtOptions, Gaussian, MeasurementStats, Observation, Trigger, TriggerState,
};
use nalgebra::{SMatrix, SVector};

/// This file's random factors: well conditioned (the reference inverts
/// `P = L Lᵀ`, and its rounding grows with the condition number).
fn factor<const D: usize>(seed: &mut u64, s: f64) -> SMatrix<f64, D, D> {
    lower_factor(seed, s, 0.3, 1.5)
}

/// Worst relative difference of `(ī, Ī)`.
fn worst<const N: usize>(a: &Contribution<f64, N>, b: &Contribution<f64, N>) -> f64 {
    rel(&a.i, &b.i).max(rel(&a.imat, &b.imat))
}

/// Random statistics at the prior with factor `l`: a random `Pxz` and
/// `Pzz = Pxzᵀ Y⁻ Pxz + R`, `R` symmetric positive definite, so `D = R`.
fn random_stats<const N: usize, const M: usize>(
    seed: &mut u64,
    l: &SMatrix<f64, N, N>,
) -> MeasurementStats<f64, N, M> {
    let pxz = SMatrix::<f64, N, M>::from_fn(|_, _| lcg_next(seed)) * 4.0;
    let y = lower_inverse(l);
    let rf = factor::<M>(seed, 0.3);
    let r = rf * rf.transpose() + SMatrix::<f64, M, M>::identity() * 0.01;
    let pzz = pxz.transpose() * y * pxz + r;
    MeasurementStats {
        z_hat: SVector::zeros(),
        pzz: (pzz + pzz.transpose()) * 0.5,
        pxz,
    }
}

/// One random case of shape `(N, M)` (unit-scale factor, state and innovation):
/// the worst relative difference of the factored contribution from the reference.
fn random_case<const N: usize, const M: usize>(seed: &mut u64) -> f64 {
    let l = factor::<N>(seed, 1.0);
    let stats = random_stats::<N, M>(seed, &l);
    let (x, dz) = (
        SVector::from_fn(|_, _| lcg_next(seed)),
        SVector::from_fn(|_, _| lcg_next(seed)),
    );
    let fast = triggered_contribution_factored(&l, &x, &stats, &dz).unwrap();
    let reference = triggered_contribution(&lower_inverse(&l), &x, &stats, &dz).unwrap();
    worst(&fast, &reference)
}

#[test]
fn factored_contribution_matches_the_reference_on_random_statistics() {
    let mut seed = 11;
    let mut worst_seen = 0.0f64;
    for round in 0..500 {
        let s = if round % 4 == 0 { 3.0 } else { 0.2 };
        let l = factor::<7>(&mut seed, s);
        let stats = random_stats::<7, 3>(&mut seed, &l);
        let x = SVector::<f64, 7>::from_fn(|_, _| 20.0 * lcg_next(&mut seed));
        let dz = SVector::<f64, 3>::from_fn(|_, _| lcg_next(&mut seed));
        let fast = triggered_contribution_factored(&l, &x, &stats, &dz).unwrap();
        let reference = triggered_contribution(&lower_inverse(&l), &x, &stats, &dz).unwrap();
        assert_eq!(fast.imat, fast.imat.transpose(), "Ī is exactly symmetric");
        worst_seen = worst_seen.max(worst(&fast, &reference));
    }
    println!("random statistics: worst relative difference {worst_seen:e}");
    assert!(
        worst_seen < 1e-12,
        "worst relative difference {worst_seen:e}"
    );
    // The other shapes of the generic code: N = 4, M = 2 and N = 2, M = 1.
    for _ in 0..200 {
        assert!(random_case::<4, 2>(&mut seed) < 1e-12);
        assert!(random_case::<2, 1>(&mut seed) < 1e-12);
    }
}

#[test]
fn factored_contribution_matches_the_reference_on_cubature_statistics() {
    // The statistics the fast path meets: range/pitch/azimuth under the
    // cubature rule at random priors (fast trigonometry on, as in `cif_update`).
    let sensor = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(true);
    let rule = SigmaRule::<f64>::cubature(7);
    let mut seed = 5;
    let mut worst_seen = 0.0f64;
    for round in 0..300 {
        let s = if round % 3 == 0 { 1.0 } else { 0.1 };
        let l0 = factor::<7>(&mut seed, s);
        let x = SVector::<f64, 7>::from_fn(|i, _| {
            if i == 6 {
                lcg_next(&mut seed)
            } else {
                20.0 * lcg_next(&mut seed)
            }
        });
        let stats = sigma_measure(&rule, &sensor, &x, &(l0 * rule.scale)).unwrap();
        let dz = SVector::<f64, 3>::from_fn(|_, _| 0.1 * lcg_next(&mut seed));
        let fast = triggered_contribution_factored(&l0, &x, &stats, &dz).unwrap();
        let reference = triggered_contribution(&lower_inverse(&l0), &x, &stats, &dz).unwrap();
        worst_seen = worst_seen.max(worst(&fast, &reference));
    }
    println!("cubature statistics: worst relative difference {worst_seen:e}");
    assert!(
        worst_seen < 1e-12,
        "worst relative difference {worst_seen:e}"
    );
}

#[test]
fn factored_contribution_fails_like_the_reference() {
    let mut seed = 7;
    let l = factor::<7>(&mut seed, 1.0);
    let y = lower_inverse(&l);
    let x = SVector::<f64, 7>::from_fn(|_, _| lcg_next(&mut seed));
    let dz = SVector::<f64, 3>::from_fn(|_, _| lcg_next(&mut seed));
    let both = |stats: &MeasurementStats<f64, 7, 3>, dz: &SVector<f64, 3>| {
        (
            triggered_contribution_factored(&l, &x, stats, dz),
            triggered_contribution(&y, &x, stats, dz),
        )
    };
    // D = Pzz − Pxzᵀ Y⁻ Pxz not positive definite: R with a negative eigenvalue.
    let mut stats = random_stats::<7, 3>(&mut seed, &l);
    stats.pzz[(1, 1)] -= 10.0;
    let (fast, reference) = both(&stats, &dz);
    let want = Error::NotPositiveDefinite {
        what: "pseudo-measurement noise D",
    };
    assert_eq!(fast.unwrap_err(), want);
    assert_eq!(reference.unwrap_err(), want);
    // D exactly singular (Pzz = Pxzᵀ Y⁻ Pxz with a rank-deficient Pxz).
    let mut singular = random_stats::<7, 3>(&mut seed, &l);
    singular.pxz = SMatrix::zeros();
    singular.pzz = SMatrix::zeros();
    let (fast, reference) = both(&singular, &dz);
    assert_eq!(fast.unwrap_err(), want);
    assert_eq!(reference.unwrap_err(), want);
    // A non-finite cross covariance makes D non-finite.
    let mut nan = random_stats::<7, 3>(&mut seed, &l);
    nan.pxz[(3, 2)] = f64::NAN;
    let (fast, reference) = both(&nan, &dz);
    let want = Error::NonFinite {
        what: "pseudo-measurement noise D",
    };
    assert_eq!(fast.unwrap_err(), want);
    assert_eq!(reference.unwrap_err(), want);
    // A non-finite innovation.
    let ok = random_stats::<7, 3>(&mut seed, &l);
    let bad_dz = SVector::<f64, 3>::new(0.0, f64::INFINITY, 0.0);
    let (fast, reference) = both(&ok, &bad_dz);
    let want = Error::NonFinite {
        what: "innovation Δz",
    };
    assert_eq!(fast.unwrap_err(), want);
    assert_eq!(reference.unwrap_err(), want);
    // A result that overflows: an enormous state.
    let big = SVector::<f64, 7>::repeat(1e308);
    let fast = triggered_contribution_factored(&l, &big, &ok, &dz);
    let reference = triggered_contribution(&y, &big, &ok, &dz);
    assert_eq!(fast.unwrap_err(), reference.unwrap_err());
}

#[test]
fn fast_cif_update_matches_the_reference_step() {
    // One triggered ET-CIF step of the paper's models, reference and fast.
    let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    let sensor = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01).unwrap();
    let est = Gaussian::new(
        SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]),
        SMatrix::<f64, 7, 7>::identity() * 0.01,
    )
    .unwrap();
    let trig = Trigger::SendOnDelta { delta: 0.04 };
    let ts = TriggerState::new(&trig);
    let z = Observation::Measured(SVector::<f64, 3>::new(5.0, 0.02, 3.1));
    let prior = cif_predict(&ct, 0.1, &est).unwrap();
    let opts = EtOptions::default();
    let reference = cif_update(&sensor, &prior, &z, &trig, &ts, &opts).unwrap();
    let fast = cif_update(&sensor.with_fast_trig(true), &prior, &z, &trig, &ts, &opts).unwrap();
    assert_eq!(reference.triggered, Some(true));
    assert_eq!(fast.triggered, Some(true));
    assert_eq!(fast.prior, reference.prior);
    let d = worst(&fast.contribution, &reference.contribution);
    println!("one step: relative difference {d:e}");
    assert!(d < 1e-12, "relative difference {d:e}");
    assert!(fast.contribution.imat != reference.contribution.imat || d == 0.0);
}
