//! Built-in models against independent computations.

use edccif_core::model::{finite_difference_jacobian, MeasurementModel, MotionModel};
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use nalgebra::SVector;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The geometric unit vectors of the range/pitch/azimuth override equal `sin_cos`
/// of the measured angles (tolerance 1e-14 absolute), including on the degenerate
/// points (target on the sensor, or straight above it).
#[test]
fn range_pitch_azimuth_trig_matches_sin_cos() {
    let s = RangePitchAzimuth::new([1.0, -2.0, 0.5], 0.1, 0.01).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut points: Vec<SVector<f64, 7>> = (0..500)
        .map(|_| SVector::<f64, 7>::from_fn(|_, _| rng.random_range(-20.0..20.0)))
        .collect();
    points.push(SVector::from([1.0, -2.0, 0.5, 0.0, 0.0, 0.0, 0.0])); // on the sensor
    points.push(SVector::from([1.0, -2.0, 4.0, 0.0, 0.0, 0.0, 0.0])); // straight above
    for x in points {
        let (z, c, si) = MeasurementModel::<f64, 7, 3>::measure_with_trig(&s, &x);
        assert_eq!(z, MeasurementModel::<f64, 7, 3>::measure(&s, &x));
        for k in [1, 2] {
            let (sk, ck) = z[k].sin_cos();
            assert!(
                (sk - si[k]).abs() < 1e-14 && (ck - c[k]).abs() < 1e-14,
                "{x:?} component {k}"
            );
        }
    }
}

/// The coordinated turn's analytic Jacobian matches central differences
/// (relative 1e-6), on both sides of the small-|ω| branch.
#[test]
fn coordinated_turn_jacobian_matches_finite_differences() {
    let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    for w in [0.3, -1.2, 1e-12, 0.0] {
        let x = SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.4, 1.5, 0.1, w]);
        let a = ct.jacobian(&x, 0.1);
        let fd = finite_difference_jacobian(|v| ct.transition(v, 0.1), &x, |_| false);
        assert!(
            (a - fd).norm() <= 1e-6 * (1.0 + a.norm()),
            "ω = {w}: {}",
            (a - fd).norm()
        );
    }
}
