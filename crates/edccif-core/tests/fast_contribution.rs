//! The triggered contribution from the prior's Cholesky factor
//! (`triggered_contribution_factored`, the fast path of `cif_update`) against
//! `triggered_contribution` with `Y⁻ = P⁻⁻¹`: the same `(ī, Ī)` within 1e-12
//! relative to the largest entry on random priors and statistics, the same
//! errors on bad input, and the same `cif_update` step with and without fast
//! trigonometry up to the sigma points' rounding.

use edccif_core::linalg::lower_inverse;
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::sigma::{sigma_measure, SigmaRule};
use edccif_core::{
    cif_predict, cif_update, triggered_contribution, triggered_contribution_factored, Contribution,
    Error, EtOptions, Gaussian, MeasurementStats, Observation, Trigger, TriggerState,
};
use nalgebra::{SMatrix, SVector};

/// Deterministic values in [−0.5, 0.5).
fn next(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
}

/// A lower-triangular factor of scale `s` with a dominant positive diagonal
/// (a well-conditioned `P = L Lᵀ`: the reference inverts it, and its rounding
/// grows with the condition number).
fn factor<const N: usize>(seed: &mut u64, s: f64) -> SMatrix<f64, N, N> {
    SMatrix::from_fn(|i, j| match i.cmp(&j) {
        std::cmp::Ordering::Greater => 0.3 * s * next(seed),
        std::cmp::Ordering::Equal => s * (1.5 + next(seed)),
        std::cmp::Ordering::Less => 0.0,
    })
}

fn rel<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>) -> f64 {
    (a - b).abs().max() / b.abs().max().max(1e-300)
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
    let pxz = SMatrix::<f64, N, M>::from_fn(|_, _| next(seed)) * 4.0;
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

#[test]
fn factored_contribution_matches_the_reference_on_random_statistics() {
    let mut seed = 11;
    let mut worst_seen = 0.0f64;
    for round in 0..500 {
        let s = if round % 4 == 0 { 3.0 } else { 0.2 };
        let l = factor::<7>(&mut seed, s);
        let stats = random_stats::<7, 3>(&mut seed, &l);
        let x = SVector::<f64, 7>::from_fn(|_, _| 20.0 * next(&mut seed));
        let dz = SVector::<f64, 3>::from_fn(|_, _| next(&mut seed));
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
        let l = factor::<4>(&mut seed, 1.0);
        let stats = random_stats::<4, 2>(&mut seed, &l);
        let (x, dz) = (
            SVector::from_fn(|_, _| next(&mut seed)),
            SVector::from_fn(|_, _| next(&mut seed)),
        );
        let fast = triggered_contribution_factored(&l, &x, &stats, &dz).unwrap();
        let reference = triggered_contribution(&lower_inverse(&l), &x, &stats, &dz).unwrap();
        assert!(worst(&fast, &reference) < 1e-12);
        let l = factor::<2>(&mut seed, 1.0);
        let stats = random_stats::<2, 1>(&mut seed, &l);
        let (x, dz) = (
            SVector::from_fn(|_, _| next(&mut seed)),
            SVector::from_fn(|_, _| next(&mut seed)),
        );
        let fast = triggered_contribution_factored(&l, &x, &stats, &dz).unwrap();
        let reference = triggered_contribution(&lower_inverse(&l), &x, &stats, &dz).unwrap();
        assert!(worst(&fast, &reference) < 1e-12);
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
                next(&mut seed)
            } else {
                20.0 * next(&mut seed)
            }
        });
        let stats = sigma_measure(&rule, &sensor, &x, &(l0 * rule.scale)).unwrap();
        let dz = SVector::<f64, 3>::from_fn(|_, _| 0.1 * next(&mut seed));
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
    let x = SVector::<f64, 7>::from_fn(|_, _| next(&mut seed));
    let dz = SVector::<f64, 3>::from_fn(|_, _| next(&mut seed));
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
