//! The EKF's structural-sparsity hooks give the same bits as the general
//! products: `MeasurementModel::jacobian_products` (`P Gᵀ`, `G P Gᵀ`) and
//! `measure_with_jacobian` of every catalogue sensor against the dense default,
//! on seeded random states and covariances, and whole seeded EKF / ET-EKF /
//! ET-CKF runs with and without the hooks.

use crate::common;

use common::{ct, initial_estimate, lcg_next, lower_factor, rng, same_bits, sensor_of, simulate};
use edccif_core::model::PointImages;
use edccif_core::models::{
    BearingOnly, LinearMeasurement, Position2, Position3, RangeBearing, RangeOnly,
};
use edccif_core::nalgebra::{SMatrix, SVector};
use edccif_core::{
    cov_local, EtOptions, Gaussian, LocalFilter, MeasurementModel, Trigger, TriggerState,
};

/// A finite `N × N` matrix: alternately a random covariance `L Lᵀ` over several
/// scales and a general (non-symmetric) random matrix; the products must agree
/// for any finite `P`.
fn random_p<const N: usize>(seed: &mut u64, round: usize) -> SMatrix<f64, N, N> {
    let s = 10f64.powi((round % 5) as i32 - 2);
    if round.is_multiple_of(2) {
        let l = lower_factor::<N>(seed, s, 1.0, 0.6);
        l * l.transpose()
    } else {
        SMatrix::from_fn(|_, _| s * lcg_next(seed))
    }
}

/// A state whose position lies around the sensors (a few metres, both signs),
/// the other components of any size; every fourth round the position is on a
/// coordinate plane of the sensor at the origin (exact zeros in `G`).
fn random_x<const N: usize>(seed: &mut u64, round: usize) -> SVector<f64, N> {
    let mut x = SVector::from_fn(|i, _| match i {
        0..=2 => 20.0 * lcg_next(seed),
        _ => 4.0 * lcg_next(seed),
    });
    if round % 4 == 3 && N > 2 {
        x[round % 3] = 0.0;
    }
    x
}

/// Checks the hooks of `sensor` against the dense products and the separate
/// `measure`/`jacobian` on 400 seeded `(x, P)` (assert_eq on the values).
fn check_sensor<H, const N: usize, const M: usize>(sensor: &H, seed: u64, what: &str)
where
    H: MeasurementModel<f64, N, M>,
{
    let mut seed = seed;
    let mut finite = 0;
    for round in 0..400 {
        let x = random_x::<N>(&mut seed, round);
        let p = random_p::<N>(&mut seed, round);
        let (z, g) = sensor.measure_with_jacobian(&x);
        assert!(
            same_bits(z.as_slice(), sensor.measure(&x).as_slice()),
            "{what}: h(x), round {round}"
        );
        assert!(
            same_bits(g.as_slice(), sensor.jacobian(&x).as_slice()),
            "{what}: G, round {round}"
        );
        if !g.iter().all(|v| v.is_finite()) {
            continue; // the filters reject a non-finite G before the products
        }
        finite += 1;
        let pg = p * g.transpose();
        let (hook_pg, hook_gpg) = sensor.jacobian_products(&g, &p);
        assert_eq!(hook_pg, pg, "{what}: P Gᵀ, round {round}");
        assert_eq!(hook_gpg, g * pg, "{what}: G P Gᵀ, round {round}");
    }
    assert!(finite >= 390, "{what}: only {finite} finite Jacobians");
}

#[test]
fn catalogue_jacobian_products_equal_the_dense_products() {
    let rpa = sensor_of(1, 4);
    check_sensor::<_, 7, 3>(&rpa, 1, "RangePitchAzimuth, N = 7");
    check_sensor::<_, 9, 3>(&rpa, 2, "RangePitchAzimuth, N = 9");
    let rb = RangeBearing::new([1.0, -2.0], 0.1, 0.01).unwrap();
    check_sensor::<_, 4, 2>(&rb, 3, "RangeBearing, N = 4");
    check_sensor::<_, 5, 2>(&rb, 4, "RangeBearing, N = 5");
    let b = BearingOnly::new([0.0, 0.0], 0.01).unwrap();
    check_sensor::<_, 4, 1>(&b, 5, "BearingOnly, N = 4");
    let r2 = RangeOnly::new([0.5, 0.5], 0.1).unwrap();
    check_sensor::<_, 4, 1>(&r2, 6, "RangeOnly 2-D, N = 4");
    let r3 = RangeOnly::new([0.5, 0.5, -1.0], 0.1).unwrap();
    check_sensor::<_, 6, 1>(&r3, 7, "RangeOnly 3-D, N = 6");
    let p2 = Position2::new([0.1, 0.2]).unwrap();
    check_sensor::<_, 4, 2>(&p2, 8, "Position2, N = 4");
    let p3 = Position3::new([0.1, 0.2, 0.3]).unwrap();
    check_sensor::<_, 6, 3>(&p3, 9, "Position3, N = 6");
    check_sensor::<_, 7, 3>(&p3, 10, "Position3, N = 7");
    // the dense default itself (a general H)
    let mut seed = 12;
    let h = SMatrix::<f64, 2, 5>::from_fn(|_, _| lcg_next(&mut seed));
    let lin = LinearMeasurement::new(h, SMatrix::<f64, 2, 2>::identity()).unwrap();
    check_sensor::<_, 5, 2>(&lin, 13, "LinearMeasurement, N = 5");
}

/// The catalogue sensor with every method but the two hooks forwarded: the
/// traits' defaults for those (separate `measure` and `jacobian`, dense products).
struct Dense<H>(H);

impl<H: MeasurementModel<f64, N, M>, const N: usize, const M: usize> MeasurementModel<f64, N, M>
    for Dense<H>
{
    fn measure(&self, x: &SVector<f64, N>) -> SVector<f64, M> {
        self.0.measure(x)
    }
    fn noise(&self) -> SMatrix<f64, M, M> {
        self.0.noise()
    }
    fn is_angle(&self, k: usize) -> bool {
        self.0.is_angle(k)
    }
    fn jacobian(&self, x: &SVector<f64, N>) -> SMatrix<f64, M, N> {
        self.0.jacobian(x)
    }
    fn fast_trig(&self) -> bool {
        self.0.fast_trig()
    }
    fn measure_with_trig(
        &self,
        x: &SVector<f64, N>,
    ) -> (SVector<f64, M>, SVector<f64, M>, SVector<f64, M>) {
        self.0.measure_with_trig(x)
    }
    fn measure_points(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.0.measure_points(x, offsets, plus, minus, centre)
    }
    fn measure_points_trig(
        &self,
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        plus: &mut PointImages<f64, M, N>,
        minus: &mut PointImages<f64, M, N>,
        centre: Option<&mut PointImages<f64, M, 1>>,
    ) {
        self.0.measure_points_trig(x, offsets, plus, minus, centre)
    }
}

fn bits(g: &Gaussian<f64, 7>) -> Vec<u64> {
    g.x.iter().chain(g.p.iter()).map(|v| v.to_bits()).collect()
}

#[test]
fn ekf_steps_with_and_without_the_hooks_agree_bit_for_bit() {
    let motion = ct();
    let sensor = sensor_of(1, 4);
    let dense = Dense(sensor);
    let sod = Trigger::SendOnDelta { delta: 0.04 };
    let opts = EtOptions::default();
    for (filter, trigger, seed) in [
        (LocalFilter::Ekf, Trigger::Always, 21),
        (LocalFilter::Ekf, sod, 22),
        (LocalFilter::Ckf, sod, 23),
        (LocalFilter::ukf_default(), sod, 24),
    ] {
        let mut r = rng(seed);
        let est0 = initial_estimate(&mut r);
        let (_, obs) = simulate(&mut r, &motion, &sensor, &est0.x, 200);
        let (mut a, mut b) = (est0, est0);
        let (mut ta, mut tb) = (TriggerState::new(&trigger), TriggerState::new(&trigger));
        let mut quiet = 0;
        for (t, z) in obs.iter().enumerate() {
            let sa = cov_local(&filter, &motion, 0.1, &sensor, &a, z, &trigger, &ta, &opts);
            let sb = cov_local(&filter, &motion, 0.1, &dense, &b, z, &trigger, &tb, &opts);
            let (sa, sb) = (sa.unwrap(), sb.unwrap());
            assert_eq!(
                bits(&sa.posterior),
                bits(&sb.posterior),
                "{filter:?} {trigger:?}, step {t}"
            );
            assert_eq!(sa.triggered, sb.triggered);
            quiet += usize::from(sa.triggered == Some(false));
            (a, b, ta, tb) = (
                sa.posterior,
                sb.posterior,
                sa.trigger_state,
                sb.trigger_state,
            );
        }
        // the send-on-delta runs exercise the untriggered (error-minimised) step
        assert!(
            trigger == Trigger::Always || quiet > 20,
            "{quiet} quiet steps"
        );
    }
}

/// The general products `kalman_update` is written out from (its fallback for
/// `M > 8`).
fn kalman_reference<const N: usize, const M: usize>(
    x: &SVector<f64, N>,
    p: &SMatrix<f64, N, N>,
    pxz: &SMatrix<f64, N, M>,
    pzz: &SMatrix<f64, M, M>,
    dz: &SVector<f64, M>,
) -> (SVector<f64, N>, SMatrix<f64, N, N>) {
    let k = pzz.cholesky().unwrap().solve(&pxz.transpose()).transpose();
    let a = p - k * pxz.transpose();
    (x + k * dz, (a + a.transpose()) * 0.5)
}

fn check_kalman<const N: usize, const M: usize>(seed: u64) {
    let mut seed = seed;
    for round in 0..400 {
        let s = 10f64.powi(round % 5 - 2);
        let lp = lower_factor::<N>(&mut seed, s, 1.0, 0.6);
        let p = lp * lp.transpose();
        let g = SMatrix::<f64, M, N>::from_fn(|_, _| lcg_next(&mut seed));
        let pxz = p * g.transpose();
        let lr = lower_factor::<M>(&mut seed, s, 0.3, 0.6);
        let pzz = g * pxz + lr * lr.transpose();
        let x = SVector::<f64, N>::from_fn(|_, _| 10.0 * lcg_next(&mut seed));
        let dz = SVector::<f64, M>::from_fn(|_, _| s * lcg_next(&mut seed));
        let Ok(post) = edccif_core::kalman_update(&x, &p, &pxz, &pzz, &dz) else {
            continue; // a posterior that lost finiteness: nothing to compare
        };
        let (x_ref, p_ref) = kalman_reference(&x, &p, &pxz, &pzz, &dz);
        assert!(
            same_bits(post.x.as_slice(), x_ref.as_slice()),
            "x, round {round}"
        );
        assert!(
            same_bits(post.p.as_slice(), p_ref.as_slice()),
            "P, round {round}"
        );
    }
}

#[test]
fn kalman_update_equals_the_general_products_bit_for_bit() {
    check_kalman::<7, 3>(31);
    check_kalman::<7, 1>(32);
    check_kalman::<4, 2>(33);
    check_kalman::<9, 3>(34);
    check_kalman::<3, 9>(35); // the general path
}

/// `EtGain::new` (solve and `P̄` written out like `kalman_update`) against the
/// general expressions of the error-minimised gain, bit for bit.
fn check_gain<const N: usize, const M: usize>(seed: u64) {
    let mut seed = seed;
    let opts = EtOptions::default();
    for round in 0..400 {
        let s = 10f64.powi(round % 5 - 2);
        let lp = lower_factor::<N>(&mut seed, s, 1.0, 0.6);
        let p = lp * lp.transpose();
        let g = SMatrix::<f64, M, N>::from_fn(|_, _| lcg_next(&mut seed));
        let lr = lower_factor::<M>(&mut seed, s, 0.3, 0.6);
        let r = lr * lr.transpose();
        let delta = 0.04 * s;
        let Ok(gain) = edccif_core::EtGain::new(&p, &g, &r, delta, &opts) else {
            continue;
        };
        let (mu1, mu2) = (1.0 + opts.sigma1, 1.0 + opts.sigma2);
        let mu3 = 1.0 + 1.0 / opts.sigma1 + 1.0 / opts.sigma2;
        let pg = p * g.transpose();
        let sm = (g * pg) * mu1 + r * mu2 + SMatrix::<f64, M, M>::identity() * (mu3 * delta);
        let sm = (sm + sm.transpose()) * 0.5;
        let m = sm.cholesky().unwrap().solve(&pg.transpose()).transpose() * mu1;
        let a = (p - m * pg.transpose()) * mu1;
        let p_bar = (a + a.transpose()) * 0.5;
        assert!(
            same_bits(gain.m.as_slice(), m.as_slice()),
            "M, round {round}"
        );
        assert!(
            same_bits(gain.p_bar.as_slice(), p_bar.as_slice()),
            "P̄, round {round}"
        );
    }
}

#[test]
fn error_minimised_gain_equals_the_general_products_bit_for_bit() {
    check_gain::<7, 3>(41);
    check_gain::<7, 1>(42);
    check_gain::<4, 2>(43);
    check_gain::<3, 9>(44); // the general path
}
