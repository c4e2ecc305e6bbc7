//! Built-in models against independent computations.

use edccif_core::model::PointImages;
use edccif_core::model::{finite_difference_jacobian, MeasurementModel, MotionModel};
use edccif_core::models::{
    BearingOnly, ConstantAcceleration, ConstantVelocity, CoordinatedTurn2, LinearMeasurement,
    LinearMotion, Position2, Position3, RandomWalk, RangeBearing, RangeOnly,
};
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::Error;
use edccif_core::{
    cif_local, cif_predict, cif_update, cov_local, cov_predict, cov_update, EtOptions, Gaussian,
    LocalFilter, Observation, Trigger, TriggerState,
};
use nalgebra::SVector;
use nalgebra::{SMatrix, Vector1, Vector2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::cell::Cell;

/// The geometric unit vectors of the range/pitch/azimuth override equal `sin_cos`
/// of the measured angles (tolerance 1e-14 absolute), including on the degenerate
/// points (target on the sensor, or straight above it).
#[test]
fn range_pitch_azimuth_trig_matches_sin_cos() {
    let s = RangePitchAzimuth::new([1.0, -2.0, 0.5], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false);
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
    let ct = CoordinatedTurn::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
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

// ---------------------------------------------------------------------------
// The catalogue: analytic Jacobians, constructor errors, unsupported dimensions.
// ---------------------------------------------------------------------------

/// Relative tolerance of analytic Jacobians against central differences: the
/// difference step is ε^{1/3}·max(1, |x|) ≈ 6e-6, so truncation and rounding
/// errors are ~1e-10 relative; 1e-6 leaves room and still catches any wrong entry.
const JAC_TOL: f64 = 1e-6;

fn random_state<const N: usize>(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> SVector<f64, N> {
    SVector::<f64, N>::from_fn(|_, _| rng.random_range(lo..hi))
}

fn check_motion_jacobian<F: MotionModel<f64, N>, const N: usize>(m: &F, name: &str, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..50 {
        let x = random_state::<N>(&mut rng, -3.0, 3.0);
        for dt in [0.01, 0.1, 1.0] {
            let a = m.jacobian(&x, dt);
            let fd = finite_difference_jacobian(|v| m.transition(v, dt), &x, |_| false);
            assert!(
                (a - fd).norm() <= JAC_TOL * (1.0 + a.norm()),
                "{name}, dt = {dt}, x = {x:?}: |analytic − fd| = {}",
                (a - fd).norm()
            );
        }
    }
}

fn check_sensor_jacobian<H: MeasurementModel<f64, N, M>, const N: usize, const M: usize>(
    h: &H,
    name: &str,
    seed: u64,
) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..200 {
        // Sensors sit within 2 m of the origin; states are ≥ 1 m away from them
        // (away from the range's singularity at the sensor).
        let x = random_state::<N>(&mut rng, -10.0, 10.0);
        if x.rows(0, 2).norm() < 3.0 {
            continue;
        }
        let a = h.jacobian(&x);
        let fd = finite_difference_jacobian(|v| h.measure(v), &x, |k| h.is_angle(k));
        assert!(
            (a - fd).norm() <= JAC_TOL * (1.0 + a.norm()),
            "{name}, x = {x:?}: |analytic − fd| = {}",
            (a - fd).norm()
        );
    }
}

/// Every catalogue motion model's analytic Jacobian equals central differences
/// (relative tolerance [`JAC_TOL`]) at 50 random states × 3 time steps, in every
/// dimension the model defines.
#[test]
fn motion_jacobians_match_finite_differences() {
    let cv = ConstantVelocity::new(0.3).unwrap();
    check_motion_jacobian::<_, 2>(&cv, "CV 1-D", 1);
    check_motion_jacobian::<_, 4>(&cv, "CV 2-D", 2);
    check_motion_jacobian::<_, 6>(&cv, "CV 3-D", 3);
    let ca = ConstantAcceleration::new(0.3).unwrap();
    check_motion_jacobian::<_, 3>(&ca, "CA 1-D", 4);
    check_motion_jacobian::<_, 6>(&ca, "CA 2-D", 5);
    check_motion_jacobian::<_, 9>(&ca, "CA 3-D", 6);
    let ct2 = CoordinatedTurn2::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
    check_motion_jacobian::<_, 5>(&ct2, "CT2", 7);
    let ct = CoordinatedTurn::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
    check_motion_jacobian::<_, 7>(&ct, "CT", 8);
    let rw = RandomWalk::new(0.2).unwrap();
    check_motion_jacobian::<_, 1>(&rw, "RW 1", 9);
    check_motion_jacobian::<_, 5>(&rw, "RW 5", 10);
    let f = SMatrix::<f64, 3, 3>::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.1, 0.2, 0.0, 0.9);
    let lm = LinearMotion::new(f, SMatrix::identity()).unwrap();
    check_motion_jacobian::<_, 3>(&lm, "linear", 11);
}

/// The planar coordinated turn's Jacobian on both sides of the small-|ω| branch
/// (relative tolerance [`JAC_TOL`]), and its planar part equals the 3-D turn's.
#[test]
fn coordinated_turn2_matches_the_3d_turn() {
    let ct2 = CoordinatedTurn2::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
    let ct = CoordinatedTurn::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false);
    for w in [0.3, -1.2, 1e-12, 0.0] {
        let x = SVector::<f64, 5>::from([5.0, -1.0, 0.4, 1.5, w]);
        let a = ct2.jacobian(&x, 0.1);
        let fd = finite_difference_jacobian(|v| ct2.transition(v, 0.1), &x, |_| false);
        assert!((a - fd).norm() <= JAC_TOL * (1.0 + a.norm()), "ω = {w}");
        let x3 = SVector::<f64, 7>::from([5.0, -1.0, 2.0, 0.4, 1.5, 0.3, w]);
        let (y2, y3) = (ct2.transition(&x, 0.1), ct.transition(&x3, 0.1));
        assert_eq!(
            [y2[0], y2[1], y2[2], y2[3], y2[4]],
            [y3[0], y3[1], y3[3], y3[4], y3[6]]
        );
    }
}

/// Every catalogue sensor's analytic Jacobian equals central differences
/// (angle components wrapped; relative tolerance [`JAC_TOL`]) at random states at
/// least 1 m from the sensor.
#[test]
fn sensor_jacobians_match_finite_differences() {
    let rb = RangeBearing::new([1.0, -0.5], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false);
    check_sensor_jacobian::<_, 4, 2>(&rb, "range-bearing", 1);
    check_sensor_jacobian::<_, 5, 2>(&rb, "range-bearing (CT2)", 2);
    let bo = BearingOnly::new([-1.0, 0.5], 0.01)
        .unwrap()
        .with_fast_trig(false);
    check_sensor_jacobian::<_, 4, 1>(&bo, "bearing-only", 3);
    let r2 = RangeOnly::new([0.5, 0.5], 0.1).unwrap();
    check_sensor_jacobian::<_, 4, 1>(&r2, "range 2-D", 4);
    let r3 = RangeOnly::new([0.5, 0.5, -1.0], 0.1).unwrap();
    check_sensor_jacobian::<_, 6, 1>(&r3, "range 3-D", 5);
    let p2 = Position2::new([0.1, 0.2]).unwrap();
    check_sensor_jacobian::<_, 4, 2>(&p2, "position 2-D", 6);
    let p3 = Position3::new([0.1, 0.2, 0.3]).unwrap();
    check_sensor_jacobian::<_, 9, 3>(&p3, "position 3-D (CA)", 7);
    let rpa = RangePitchAzimuth::new([1.0, 1.0, 0.5], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false);
    check_sensor_jacobian::<_, 6, 3>(&rpa, "range-pitch-azimuth", 8);
    let lin = LinearMeasurement::new(
        SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.5, 0.0, 0.0, 1.0, 0.0, -0.5),
        SMatrix::<f64, 2, 2>::identity(),
    )
    .unwrap();
    check_sensor_jacobian::<_, 4, 2>(&lin, "linear", 9);
}

/// The geometric unit vectors of the planar angle sensors equal `sin_cos` of the
/// measured bearing (1e-14 absolute), on the sensor too.
#[test]
fn planar_bearing_trig_matches_sin_cos() {
    let rb = RangeBearing::new([1.0, -2.0], 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false);
    let bo = BearingOnly::new([1.0, -2.0], 0.01)
        .unwrap()
        .with_fast_trig(false);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut points: Vec<SVector<f64, 4>> = (0..500)
        .map(|_| random_state(&mut rng, -20.0, 20.0))
        .collect();
    points.push(SVector::from([1.0, -2.0, 0.0, 0.0])); // on the sensor
    for x in points {
        let (z, c, s) = MeasurementModel::<f64, 4, 2>::measure_with_trig(&rb, &x);
        assert_eq!(z, MeasurementModel::<f64, 4, 2>::measure(&rb, &x));
        let (sb, cb) = z[1].sin_cos();
        assert!(
            (sb - s[1]).abs() < 1e-14 && (cb - c[1]).abs() < 1e-14,
            "{x:?}"
        );
        let (z1, c1, s1) = MeasurementModel::<f64, 4, 1>::measure_with_trig(&bo, &x);
        assert_eq!(z1[0], z[1]);
        assert!(
            (sb - s1[0]).abs() < 1e-14 && (cb - c1[0]).abs() < 1e-14,
            "{x:?}"
        );
    }
}

/// Bad parameters are named errors from `new`.
#[test]
fn constructors_reject_bad_parameters() {
    let bad = |e: Error, what: &str| match e {
        Error::InvalidParameter { what: w, .. } | Error::NonFinite { what: w } => {
            assert_eq!(w, what)
        }
        other => panic!("unexpected {other:?}"),
    };
    bad(ConstantVelocity::new(-1.0).unwrap_err(), "q");
    bad(ConstantVelocity::new(f64::NAN).unwrap_err(), "q");
    bad(ConstantAcceleration::new(f64::INFINITY).unwrap_err(), "q");
    bad(RandomWalk::new(-0.0f64 - 1e-300).unwrap_err(), "q");
    bad(CoordinatedTurn2::new(-1.0, 0.0).unwrap_err(), "q1");
    bad(CoordinatedTurn2::new(1.0, f64::NAN).unwrap_err(), "q2");
    bad(Position2::new([0.1, 0.0]).unwrap_err(), "sigma");
    bad(Position3::new([0.1, 0.1, f64::NAN]).unwrap_err(), "sigma");
    bad(
        RangeBearing::new([0.0, f64::INFINITY], 0.1, 0.1).unwrap_err(),
        "sensor position",
    );
    bad(
        RangeBearing::new([0.0, 0.0], 0.0, 0.1).unwrap_err(),
        "sigma_r",
    );
    bad(
        RangeBearing::new([0.0, 0.0], 0.1, -0.1).unwrap_err(),
        "sigma_b",
    );
    bad(
        BearingOnly::new([0.0, 0.0], f64::NAN).unwrap_err(),
        "sigma_b",
    );
    bad(
        BearingOnly::new([f64::NAN, 0.0], 0.1).unwrap_err(),
        "sensor position",
    );
    bad(RangeOnly::new([0.0, 0.0], -1.0).unwrap_err(), "sigma_r");
    bad(
        RangeOnly::new([0.0, 0.0, f64::NAN], 1.0).unwrap_err(),
        "sensor position",
    );
    bad(
        RangeOnly::new([0.0], 1.0).unwrap_err(),
        "RangeOnly dimension D",
    );
    assert_eq!(
        Position2::with_covariance(SMatrix::<f64, 2, 2>::new(1.0, 0.5, 0.0, 1.0)).unwrap_err(),
        Error::NotSymmetric {
            what: "measurement noise R"
        }
    );
    // Zero process noise is allowed (a deterministic model).
    assert!(ConstantVelocity::new(0.0).is_ok() && RandomWalk::new(0.0).is_ok());
}

/// A model used at a dimension it does not define fails the step with a
/// NonFinite error instead of panicking; nothing else is touched.
#[test]
fn unsupported_dimensions_are_errors_not_panics() {
    let trig = Trigger::Always;
    let ts = TriggerState::new(&trig);
    let opts = EtOptions::default();
    // Constant velocity needs an even N.
    let est5 = Gaussian::new(SVector::<f64, 5>::zeros(), SMatrix::identity()).unwrap();
    let p2 = Position2::new([0.1, 0.1]).unwrap();
    let cv = ConstantVelocity::new(0.1).unwrap();
    let z = Observation::Measured(Vector2::new(0.0, 0.0));
    let e = cif_local(&cv, 0.1, &p2, &est5, &z, &trig, &ts, &opts).unwrap_err();
    assert!(matches!(e, Error::NonFinite { .. }), "{e:?}");
    // A 3-D position of a 2-state target.
    let est2 = Gaussian::new(SVector::<f64, 2>::new(0.0, 1.0), SMatrix::identity()).unwrap();
    let p3 = Position3::new([0.1; 3]).unwrap();
    let z3 = Observation::Measured(nalgebra::Vector3::new(0.0, 0.0, 0.0));
    let e = cov_local(
        &LocalFilter::Ckf,
        &cv,
        0.1,
        &p3,
        &est2,
        &z3,
        &trig,
        &TriggerState::new(&trig),
        &opts,
    )
    .unwrap_err();
    assert!(matches!(e, Error::NonFinite { .. }), "{e:?}");
    assert!(ConstantVelocity::<f64>::supports(2) && !ConstantVelocity::<f64>::supports(0));
    assert!(ConstantAcceleration::<f64>::supports(6) && !ConstantAcceleration::<f64>::supports(7));
}

// ---------------------------------------------------------------------------
// Batch hooks.
// ---------------------------------------------------------------------------

/// A motion model that evaluates every point in its batch hook and counts calls.
struct CountingMotion<F> {
    inner: F,
    batches: Cell<usize>,
    singles: Cell<usize>,
}

impl<F: MotionModel<f64, N>, const N: usize> MotionModel<f64, N> for CountingMotion<F> {
    fn transition(&self, x: &SVector<f64, N>, dt: f64) -> SVector<f64, N> {
        self.singles.set(self.singles.get() + 1);
        self.inner.transition(x, dt)
    }
    fn process_noise(&self, dt: f64) -> SMatrix<f64, N, N> {
        self.inner.process_noise(dt)
    }
    fn jacobian(&self, x: &SVector<f64, N>, dt: f64) -> SMatrix<f64, N, N> {
        self.inner.jacobian(x, dt)
    }
    fn transition_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        dt: f64,
        plus: &mut SMatrix<f64, N, N>,
        minus: &mut SMatrix<f64, N, N>,
        centre: Option<&mut SVector<f64, N>>,
    ) {
        self.batches.set(self.batches.get() + 1);
        // Column by column, in a different order from the default (last first):
        // the points are independent, so the numbers must not change.
        for j in (0..N).rev() {
            let col = offsets.column(j);
            minus.set_column(j, &self.inner.transition(&(x - col), dt));
            plus.set_column(j, &self.inner.transition(&(x + col), dt));
        }
        if let Some(c0) = centre {
            *c0 = self.inner.transition(x, dt);
        }
    }
}

/// A sensor that evaluates every point in its batch hook and counts calls.
struct CountingSensor<H> {
    inner: H,
    batches: Cell<usize>,
    singles: Cell<usize>,
}

impl<H: MeasurementModel<f64, N, M>, const N: usize, const M: usize> MeasurementModel<f64, N, M>
    for CountingSensor<H>
{
    fn measure(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        self.singles.set(self.singles.get() + 1);
        self.inner.measure(x)
    }
    fn noise(&self) -> SMatrix<f64, M, M> {
        self.inner.noise()
    }
    fn is_angle(&self, k: usize) -> bool {
        self.inner.is_angle(k)
    }
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        self.inner.jacobian(x)
    }
    fn measure_with_trig(
        &self,
        x: &SVector<f64, N>,
    ) -> (SVector<f64, M>, SVector<f64, M>, SVector<f64, M>) {
        self.singles.set(self.singles.get() + 1);
        self.inner.measure_with_trig(x)
    }
    fn measure_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.batches.set(self.batches.get() + 1);
        for j in (0..N).rev() {
            let col = offsets.column(j);
            minus.set(j, self.inner.measure_with_trig(&(x - col)));
            plus.set(j, self.inner.measure_with_trig(&(x + col)));
        }
        if let Some(c0) = centre {
            c0.set(0, self.inner.measure_with_trig(x));
        }
    }
}

fn counting<F>(inner: F) -> (CountingMotion<F>, CountingSensor<RangeBearing<f64>>) {
    (
        CountingMotion {
            inner,
            batches: Cell::new(0),
            singles: Cell::new(0),
        },
        CountingSensor {
            inner: RangeBearing::new([2.0, -1.0], 0.2, 0.02)
                .unwrap()
                .with_fast_trig(false),
            batches: Cell::new(0),
            singles: Cell::new(0),
        },
    )
}

/// Overriding the batch hooks: a CKF/UKF/CIF step calls each hook exactly once
/// (one prediction, one measurement transform), never the per-point methods, and
/// gives the same numbers bit for bit as the built-in per-point defaults.
#[test]
fn batch_hooks_are_called_once_per_step_with_identical_numbers() {
    let cv = ConstantVelocity::new(0.3).unwrap();
    let rb = RangeBearing::new([2.0, -1.0], 0.2, 0.02)
        .unwrap()
        .with_fast_trig(false);
    let est = Gaussian::new(
        SVector::<f64, 4>::new(5.0, 3.0, -0.5, 1.0),
        SMatrix::<f64, 4, 4>::identity() * 0.5,
    )
    .unwrap();
    let z = Observation::Measured(Vector2::new(5.2, 0.6));
    let opts = EtOptions::default();
    for trig in [Trigger::Always, Trigger::Innovation { delta: 0.5 }] {
        let ts = TriggerState::new(&trig);
        // Innovation trigger: the prediction is computed once and reused.
        let (m, s) = counting(cv);
        let hooked = cif_local(&m, 0.1, &s, &est, &z, &trig, &ts, &opts).unwrap();
        let plain = cif_local(&cv, 0.1, &rb, &est, &z, &trig, &ts, &opts).unwrap();
        assert_eq!(hooked, plain, "{trig:?}");
        assert_eq!((m.batches.get(), m.singles.get()), (1, 0), "{trig:?}");
        assert_eq!((s.batches.get(), s.singles.get()), (1, 0), "{trig:?}");
        for filter in [LocalFilter::Ckf, LocalFilter::ukf_default()] {
            let (m, s) = counting(cv);
            let hooked = cov_local(&filter, &m, 0.1, &s, &est, &z, &trig, &ts, &opts).unwrap();
            let plain = cov_local(&filter, &cv, 0.1, &rb, &est, &z, &trig, &ts, &opts).unwrap();
            assert_eq!(hooked, plain, "{filter:?} {trig:?}");
            assert_eq!((m.batches.get(), m.singles.get()), (1, 0), "{filter:?}");
            assert_eq!((s.batches.get(), s.singles.get()), (1, 0), "{filter:?}");
        }
    }
}

/// A batch hook that cannot evaluate its points (writes NaN) fails the step with
/// a NonFinite error.
#[test]
fn a_failing_batch_hook_is_a_non_finite_error() {
    struct Failing;
    impl MeasurementModel<f64, 2, 1> for Failing {
        fn measure(&self, x: &SVector<f64, 2>) -> SVector<f64, 1> {
            Vector1::new(x[0])
        }
        fn noise(&self) -> SMatrix<f64, 1, 1> {
            SMatrix::identity()
        }
        fn measure_points(
            &self,
            _x: &SVector<f64, 2>,
            _offsets: &SMatrix<f64, 2, 2>,
            plus: &mut PointImages<f64, 1, 2>,
            minus: &mut PointImages<f64, 1, 2>,
            _centre: Option<&mut PointImages<f64, 1, 1>>,
        ) {
            plus.z.fill(f64::NAN);
            minus.z.fill(f64::NAN);
        }
    }
    let rw = RandomWalk::new(0.1).unwrap();
    let est = Gaussian::new(SVector::<f64, 2>::new(1.0, 2.0), SMatrix::identity()).unwrap();
    let trig = Trigger::Always;
    let e = cif_local(
        &rw,
        0.1,
        &Failing,
        &est,
        &Observation::Measured(Vector1::new(1.0)),
        &trig,
        &TriggerState::new(&trig),
        &EtOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(e, Error::NonFinite { .. }), "{e:?}");
}

// ---------------------------------------------------------------------------
// Linear models: exact discretisation, Kalman-filter equivalence.
// ---------------------------------------------------------------------------

/// `F(h) Q(h) F(h)ᵀ + Q(h) = Q(2h)` and `f(f(x, h), h) = f(x, 2h)`: the constant
/// velocity, constant acceleration and random walk are exact discretisations of
/// their continuous-time models. Tolerance `1e-12·(1 + ‖Q(2h)‖)` (rounding only).
#[test]
fn process_noise_composes_over_half_steps() {
    fn check<F: MotionModel<f64, N>, const N: usize>(m: &F, name: &str) {
        let mut rng = ChaCha8Rng::seed_from_u64(N as u64);
        let x = random_state::<N>(&mut rng, -2.0, 2.0);
        for dt in [0.1f64, 0.37, 2.0] {
            let h = dt / 2.0;
            let f = m.jacobian(&x, h);
            let composed = f * m.process_noise(h) * f.transpose() + m.process_noise(h);
            let whole = m.process_noise(dt);
            assert!(
                (composed - whole).norm() <= 1e-12 * (1.0 + whole.norm()),
                "{name}, dt = {dt}: {}",
                (composed - whole).norm()
            );
            let halves = m.transition(&m.transition(&x, h), h);
            let once = m.transition(&x, dt);
            assert!(
                (halves - once).norm() <= 1e-12 * (1.0 + once.norm()),
                "{name}"
            );
            // Q(dt) is symmetric and positive definite.
            assert_eq!(whole, whole.transpose(), "{name}");
            assert!(
                whole.cholesky().is_some(),
                "{name}: Q(dt) not positive definite"
            );
        }
    }
    let cv = ConstantVelocity::new(0.7).unwrap();
    check::<_, 2>(&cv, "CV 1-D");
    check::<_, 4>(&cv, "CV 2-D");
    check::<_, 6>(&cv, "CV 3-D");
    let ca = ConstantAcceleration::new(0.3).unwrap();
    check::<_, 3>(&ca, "CA 1-D");
    check::<_, 6>(&ca, "CA 2-D");
    check::<_, 9>(&ca, "CA 3-D");
    check::<_, 5>(&RandomWalk::new(0.2).unwrap(), "RW");
    // The white-jerk block of one axis, entry by entry (q = 0.3, dt = 2).
    let q = MotionModel::<f64, 3>::process_noise(&ca, 2.0);
    let expected = SMatrix::<f64, 3, 3>::new(
        0.3 * 32.0 / 20.0,
        0.3 * 16.0 / 8.0,
        0.3 * 8.0 / 6.0,
        0.3 * 16.0 / 8.0,
        0.3 * 8.0 / 3.0,
        0.3 * 4.0 / 2.0,
        0.3 * 8.0 / 6.0,
        0.3 * 4.0 / 2.0,
        0.3 * 2.0,
    );
    assert!((q - expected).norm() < 1e-14);
}

/// The existing 3-D constant velocity is unchanged: its numbers for `N = 6` are
/// those of the per-axis formulas written out (bit for bit).
#[test]
fn constant_velocity_3d_numbers_are_unchanged() {
    let cv = ConstantVelocity::new(0.7).unwrap();
    let x = SVector::<f64, 6>::from([1.0, 2.0, 3.0, -0.5, 0.25, 2.0]);
    let dt = 0.37;
    let y = cv.transition(&x, dt);
    let q = MotionModel::<f64, 6>::process_noise(&cv, dt);
    for a in 0..3 {
        assert_eq!(y[a], x[a] + dt * x[a + 3]);
        assert_eq!(y[a + 3], x[a + 3]);
        assert_eq!(q[(a, a)], 0.7 * (dt * dt) * dt / 3.0);
        assert_eq!(q[(a, a + 3)], 0.7 * (dt * dt) / 2.0);
        assert_eq!(q[(a + 3, a + 3)], 0.7 * dt);
    }
}

/// Textbook Kalman filter (plain nalgebra, LU inverse, Joseph form) of a 2-D
/// constant velocity observed in position.
fn kalman_step(
    f: &SMatrix<f64, 4, 4>,
    q: &SMatrix<f64, 4, 4>,
    r: &SMatrix<f64, 2, 2>,
    g: &Gaussian<f64, 4>,
    z: Option<&Vector2<f64>>,
) -> Gaussian<f64, 4> {
    let h = SMatrix::<f64, 2, 4>::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
    let x = f * g.x;
    let p = f * g.p * f.transpose() + q;
    let Some(z) = z else { return Gaussian { x, p } };
    let s = h * p * h.transpose() + r;
    let k = p * h.transpose() * s.try_inverse().unwrap();
    let a = SMatrix::<f64, 4, 4>::identity() - k * h;
    Gaussian {
        x: x + k * (z - h * x),
        p: a * p * a.transpose() + k * r * k.transpose(),
    }
}

/// 2-D constant velocity observed by a 2-D position sensor with correlated noise,
/// 50 steps with non-uniform `dt` and every 6th measurement missing: the CKF, EKF,
/// UKF (predict + update) and the CIF (predict + update, local posterior) all equal
/// the textbook Kalman filter. Tolerance `‖x − x_kf‖ ≤ 1e-9·‖x_kf‖ + 1e-12`,
/// `‖P − P_kf‖_F ≤ 1e-9·‖P_kf‖_F` at every step (algebraically identical forms).
#[test]
fn constant_velocity_with_position_equals_kalman_filter() {
    let cv = ConstantVelocity::new(0.4).unwrap();
    let r = SMatrix::<f64, 2, 2>::new(0.04, 0.01, 0.01, 0.09);
    let cam = Position2::with_covariance(r).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let mut truth = SVector::<f64, 4>::new(0.0, 1.0, 1.0, -0.5);
    let p_start = SMatrix::<f64, 4, 4>::identity() * 0.5;
    let start = Gaussian::new(
        truth + SVector::<f64, 4>::new(0.3, -0.2, 0.1, 0.05),
        p_start,
    )
    .unwrap();
    let trig = Trigger::Always;
    let ts = TriggerState::new(&trig);
    let opts = EtOptions::default();
    let filters = [
        LocalFilter::Ckf,
        LocalFilter::Ekf,
        LocalFilter::ukf_default(),
    ];
    let (mut oracle, mut cif, mut cov) = (start, start, [start; 3]);
    let close = |a: &Gaussian<f64, 4>, b: &Gaussian<f64, 4>, what: &str| {
        assert!((a.x - b.x).norm() <= 1e-9 * b.x.norm() + 1e-12, "{what} x");
        assert!((a.p - b.p).norm() <= 1e-9 * b.p.norm(), "{what} P");
    };
    for k in 0..50 {
        let dt = 0.05 + 0.1 * rng.random::<f64>();
        truth = MotionModel::<f64, 4>::transition(&cv, &truth, dt);
        let z = if k % 6 == 5 {
            Observation::Missing
        } else {
            Observation::Measured(
                Vector2::new(truth[0], truth[1])
                    + Vector2::new(rng.random_range(-0.2..0.2), rng.random_range(-0.3..0.3)),
            )
        };
        let zv = match &z {
            Observation::Measured(v) => Some(v),
            Observation::Missing => None,
        };
        let f = MotionModel::<f64, 4>::jacobian(&cv, &truth, dt);
        oracle = kalman_step(
            &f,
            &MotionModel::<f64, 4>::process_noise(&cv, dt),
            &r,
            &oracle,
            zv,
        );
        for (filter, est) in filters.iter().zip(cov.iter_mut()) {
            let prior = cov_predict(filter, &cv, dt, est).unwrap();
            *est = cov_update(filter, &cam, &prior, &z, &trig, &ts, &opts)
                .unwrap()
                .posterior;
            close(est, &oracle, &format!("{filter:?} step {k}"));
        }
        let prior = cif_predict(&cv, dt, &cif).unwrap();
        let step = cif_update(&cam, &prior, &z, &trig, &ts, &opts).unwrap();
        cif = step.local_posterior().to_gaussian().unwrap();
        close(&cif, &oracle, &format!("CIF step {k}"));
    }
}

// ---------------------------------------------------------------------------
// Angles: bearing sensors across the ±π cut.
// ---------------------------------------------------------------------------

/// A target due "west" of a bearing sensor sits on the ±π cut: its sigma points'
/// bearings straddle it. The predicted bearing is the circular mean (near π in
/// magnitude, not near 0), the bearing's innovation variance is that of the
/// points' spread plus `R` (not ~π²), and a measurement on the other side of the
/// cut moves the estimate by a small amount (the innovation is wrapped). Checked
/// with range-bearing and bearing-only sensors, CKF, UKF and CIF, on both sides.
#[test]
fn bearing_sensors_wrap_across_the_cut() {
    let cv = ConstantVelocity::new(0.01).unwrap();
    let rb = RangeBearing::new([0.0, 0.0], 0.05, 0.01)
        .unwrap()
        .with_fast_trig(false);
    let bo = BearingOnly::new([0.0, 0.0], 0.01)
        .unwrap()
        .with_fast_trig(false);
    let trig = Trigger::Always;
    let opts = EtOptions::default();
    for side in [1.0, -1.0] {
        // Predicted position (−10, ±0.005): bearing ≈ ±(π − 0.0005).
        let est = Gaussian::new(
            SVector::<f64, 4>::new(-10.0, side * 0.005, 0.0, 0.0),
            SMatrix::<f64, 4, 4>::identity() * 0.01,
        )
        .unwrap();
        // The measured bearing is on the other side of the cut: ∓(π − 0.001).
        let b = -side * (std::f64::consts::PI - 0.001);
        let z2 = Observation::Measured(Vector2::new(10.0, b));
        let z1 = Observation::Measured(Vector1::new(b));
        for filter in [LocalFilter::Ckf, LocalFilter::ukf_default()] {
            let prior = cov_predict(&filter, &cv, 0.1, &est).unwrap();
            let post = cov_update(
                &filter,
                &rb,
                &prior,
                &z2,
                &trig,
                &TriggerState::new(&trig),
                &opts,
            )
            .unwrap()
            .posterior;
            // y moves towards the measured side by at most a few centimetres.
            assert!(
                (post.x[1] - prior.x[1]).abs() < 0.05,
                "{filter:?} {side}: {:?}",
                post.x
            );
            assert!(
                post.x[1] * side < prior.x[1] * side,
                "moved towards the measurement"
            );
            let post1 = cov_update(
                &filter,
                &bo,
                &prior,
                &z1,
                &trig,
                &TriggerState::new(&trig),
                &opts,
            )
            .unwrap()
            .posterior;
            assert!(
                (post1.x[1] - prior.x[1]).abs() < 0.05,
                "{filter:?} {side}: {:?}",
                post1.x
            );
        }
        let prior = cif_predict(&cv, 0.1, &est).unwrap();
        let step = cif_update(&rb, &prior, &z2, &trig, &TriggerState::new(&trig), &opts).unwrap();
        let post = step.local_posterior().to_gaussian().unwrap();
        assert!(
            (post.x[1] - prior.x()[1]).abs() < 0.05,
            "CIF {side}: {:?}",
            post.x
        );
        // The statistics themselves: circular mean and a small bearing variance.
        let rule = edccif_core::SigmaRule::cubature(4);
        let l = prior.p().cholesky().unwrap().l() * rule.scale;
        let stats =
            edccif_core::sigma::sigma_measure::<f64, _, 4, 2>(&rule, &rb, &prior.x(), &l).unwrap();
        assert!(stats.z_hat[1].abs() > 3.1, "ẑ bearing {}", stats.z_hat[1]);
        assert!(
            stats.pzz[(1, 1)] < 1e-3,
            "bearing variance {}",
            stats.pzz[(1, 1)]
        );
    }
}

/// The batched finite-difference Jacobians equal `finite_difference_jacobian`
/// (relative 1e-12: the same points, evaluated in one call) and make exactly one
/// hook call.
#[test]
fn batched_jacobians_equal_finite_differences_in_one_call() {
    use edccif_core::model::{measurement_jacobian_batched, motion_jacobian_batched};
    let (m, s) = counting(
        CoordinatedTurn2::new(0.5, 1e-4)
            .unwrap()
            .with_fast_trig(false),
    );
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for i in 0..20 {
        let x = random_state::<5>(&mut rng, -5.0, 5.0);
        let a = motion_jacobian_batched(&m, &x, 0.2);
        let fd = finite_difference_jacobian(|v| m.inner.transition(v, 0.2), &x, |_| false);
        assert!((a - fd).norm() <= 1e-12 * (1.0 + fd.norm()), "{x:?}");
        let a: SMatrix<f64, 2, 5> = measurement_jacobian_batched(&s, &x);
        let fd = finite_difference_jacobian(|v| s.inner.measure(v), &x, |k| k == 1);
        assert!((a - fd).norm() <= 1e-12 * (1.0 + fd.norm()), "{x:?}");
        assert_eq!((m.batches.get(), s.batches.get()), (i + 1, i + 1));
        assert_eq!((m.singles.get(), s.singles.get()), (0, 0));
    }
}

/// A batch hook that fails by writing NaN into `z` only (leaving the cosines and
/// sines of its angle component at zero) is caught by the mean-only transform of
/// the untriggered steps too, not only by the full transform.
#[test]
fn nan_points_of_an_angle_sensor_are_caught_by_the_mean_transform() {
    struct FailingBearing;
    impl MeasurementModel<f64, 2, 1> for FailingBearing {
        fn measure(&self, x: &SVector<f64, 2>) -> SVector<f64, 1> {
            Vector1::new(x[1].atan2(x[0]))
        }
        fn noise(&self) -> SMatrix<f64, 1, 1> {
            SMatrix::identity() * 1e-4
        }
        fn is_angle(&self, k: usize) -> bool {
            k == 0
        }
        fn measure_points(
            &self,
            _x: &SVector<f64, 2>,
            _offsets: &SMatrix<f64, 2, 2>,
            plus: &mut PointImages<f64, 1, 2>,
            minus: &mut PointImages<f64, 1, 2>,
            _centre: Option<&mut PointImages<f64, 1, 1>>,
        ) {
            plus.z.fill(f64::NAN);
            minus.z.fill(f64::NAN);
        }
    }
    let rule = edccif_core::SigmaRule::<f64>::cubature(2);
    let x = SVector::<f64, 2>::new(1.0, 1.0);
    let l = SMatrix::<f64, 2, 2>::identity() * 0.1;
    let mean = edccif_core::sigma::sigma_measure_mean(&rule, &FailingBearing, &x, &l);
    assert!(matches!(mean, Err(Error::NonFinite { .. })), "{mean:?}");
    let full = edccif_core::sigma::sigma_measure(&rule, &FailingBearing, &x, &l);
    assert!(matches!(full, Err(Error::NonFinite { .. })), "{full:?}");
}
