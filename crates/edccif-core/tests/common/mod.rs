//! Shared helpers of the core's integration tests: the default scenario of
//! ALGORITHM.md §1/§6, a seeded simulator and matrix comparisons.
//!
//! Every test binary includes this module but uses only part of it.
#![allow(dead_code)]

use edccif_core::angles::wrap_angle;
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::nalgebra::{SMatrix, SVector};
use edccif_core::{Gaussian, MeasurementModel, MotionModel, Observation};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// State and measurement dimensions of the default scenario.
pub const N: usize = 7;
pub const M: usize = 3;

pub type Vec7 = SVector<f64, 7>;
pub type Mat7 = SMatrix<f64, 7, 7>;
pub type Vec3 = SVector<f64, 3>;

/// A reproducible generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Coordinated turn with the §6 constants: dt 0.1, q1 0.5, q2 1e-4.
pub fn ct() -> CoordinatedTurn<f64> {
    CoordinatedTurn::new(0.5, 1e-4)
        .unwrap()
        .with_fast_trig(false)
}

/// Range/pitch/azimuth sensor with the §6 noise: σr 0.1 m, σa 0.01 rad.
pub fn rpa(pos: [f64; 3]) -> RangePitchAzimuth<f64> {
    RangePitchAzimuth::new(pos, 0.1, 0.01)
        .unwrap()
        .with_fast_trig(false)
}

/// Sensor i of N nodes (§6): (10 cos(2πi/N), 10 sin(2πi/N), 0 if i even else 3).
pub fn sensor_of(i: usize, n: usize) -> RangePitchAzimuth<f64> {
    let a = core::f64::consts::TAU * i as f64 / n as f64;
    rpa([
        10.0 * a.cos(),
        10.0 * a.sin(),
        if i.is_multiple_of(2) { 0.0 } else { 3.0 },
    ])
}

/// Row-major ring adjacency (i ↔ i±1 mod n), n ≥ 3.
pub fn ring<const K: usize>() -> [bool; K] {
    let n = (K as f64).sqrt() as usize;
    assert_eq!(n * n, K);
    let mut a = [false; K];
    for i in 0..n {
        a[i * n + (i + 1) % n] = true;
        a[i * n + (i + n - 1) % n] = true;
    }
    a
}

/// True initial state of §6.
pub fn x0() -> Vec7 {
    Vec7::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3])
}

/// P0 = diag(0.1² ×6, 0.01²).
pub fn p0() -> Mat7 {
    Mat7::from_diagonal(&Vec7::from([0.01, 0.01, 0.01, 0.01, 0.01, 0.01, 1e-4]))
}

/// A standard-normal vector.
pub fn normal<const D: usize>(rng: &mut ChaCha8Rng) -> SVector<f64, D> {
    SVector::<f64, D>::from_fn(|_, _| rng.sample::<f64, _>(StandardNormal))
}

/// A sample of N(0, C) (C symmetric positive definite).
pub fn sample<const D: usize>(rng: &mut ChaCha8Rng, cov: &SMatrix<f64, D, D>) -> SVector<f64, D> {
    cov.cholesky().expect("sampling covariance must be PD").l() * normal::<D>(rng)
}

/// The initial estimate of a run (§6): x̂0 = x0 + chol(P0)·ξ, P0.
pub fn initial_estimate(rng: &mut ChaCha8Rng) -> Gaussian<f64, 7> {
    Gaussian::new(x0() + sample(rng, &p0()), p0()).unwrap()
}

/// One step of the truth: `x' = f(x) + w`, `w ~ N(0, Q)`.
pub fn propagate<F: MotionModel<f64, D>, const D: usize>(
    rng: &mut ChaCha8Rng,
    motion: &F,
    x: &SVector<f64, D>,
) -> SVector<f64, D> {
    motion.transition(x, 0.1) + sample(rng, &motion.process_noise(0.1))
}

/// A noisy measurement `h(x) + v`, angles wrapped to [−π, π) (§2).
pub fn measure<H: MeasurementModel<f64, D, K>, const D: usize, const K: usize>(
    rng: &mut ChaCha8Rng,
    sensor: &H,
    x: &SVector<f64, D>,
) -> SVector<f64, K> {
    let mut z = sensor.measure(x) + sample(rng, &sensor.noise());
    for k in 0..K {
        if sensor.is_angle(k) {
            z[k] = wrap_angle(z[k]);
        }
    }
    z
}

/// Truth `x_1..x_T` from `x_0` and one sensor's measurements `z_1..z_T` (§6 order).
pub fn simulate<F, H, const D: usize, const K: usize>(
    rng: &mut ChaCha8Rng,
    motion: &F,
    sensor: &H,
    x_start: &SVector<f64, D>,
    steps: usize,
) -> (Vec<SVector<f64, D>>, Vec<Observation<f64, K>>)
where
    F: MotionModel<f64, D>,
    H: MeasurementModel<f64, D, K>,
{
    let mut x = *x_start;
    let mut truth = Vec::with_capacity(steps);
    let mut obs = Vec::with_capacity(steps);
    for _ in 0..steps {
        x = propagate(rng, motion, &x);
        obs.push(Observation::Measured(measure(rng, sensor, &x)));
        truth.push(x);
    }
    (truth, obs)
}

/// `‖a − b‖_F ≤ rel·‖b‖_F + abs`, with a message naming the quantity.
#[track_caller]
pub fn assert_close<const R: usize, const C: usize>(
    a: &SMatrix<f64, R, C>,
    b: &SMatrix<f64, R, C>,
    rel: f64,
    abs: f64,
    what: &str,
) {
    let err = (a - b).norm();
    let tol = rel * b.norm() + abs;
    assert!(
        err <= tol,
        "{what}: ‖a − b‖ = {err:e} > tol {tol:e} (rel {rel:e}, abs {abs:e})\na = {a}\nb = {b}"
    );
}

/// Bitwise equality of two slices of floats (NaN-safe "unchanged" check).
pub fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// Relative symmetric difference `‖A − Aᵀ‖ / ‖A‖`.
pub fn asymmetry<const D: usize>(a: &SMatrix<f64, D, D>) -> f64 {
    (a - a.transpose()).norm() / a.norm().max(f64::MIN_POSITIVE)
}

/// Whether the symmetric matrix `a` is positive semi-definite up to `tol`
/// (relative to its norm): `a + tol·‖a‖·I` has a Cholesky factor.
pub fn psd_within<const D: usize>(a: &SMatrix<f64, D, D>, tol: f64) -> bool {
    let shift = tol * a.norm().max(f64::MIN_POSITIVE);
    (a + SMatrix::<f64, D, D>::identity() * shift)
        .cholesky()
        .is_some()
}

/// A small deterministic generator (64-bit LCG): values in [−0.5, 0.5), for
/// tests that draw many random matrices cheaply and reproducibly.
pub fn lcg_next(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
}

/// A random lower-triangular factor of scale `s`: entries below the diagonal
/// `off·s·u`, the diagonal `s·(base + u)` (`u` from [`lcg_next`]), zero above.
/// A larger `base` against `off` gives a better-conditioned `P = L Lᵀ`.
pub fn lower_factor<const D: usize>(
    seed: &mut u64,
    s: f64,
    off: f64,
    base: f64,
) -> SMatrix<f64, D, D> {
    SMatrix::from_fn(|i, j| match i.cmp(&j) {
        std::cmp::Ordering::Greater => off * s * lcg_next(seed),
        std::cmp::Ordering::Equal => s * (base + lcg_next(seed)),
        std::cmp::Ordering::Less => 0.0,
    })
}

/// The largest entry of `|a − b|` relative to the largest entry of `|b|`.
pub fn rel<const R: usize, const C: usize>(a: &SMatrix<f64, R, C>, b: &SMatrix<f64, R, C>) -> f64 {
    (a - b).abs().max() / b.abs().max().max(1e-300)
}
