//! Symmetric sigma-point rules and the transforms shared by the cubature and
//! unscented filters. Points are generated on the fly from the Cholesky factor
//! and stored column-wise in stack matrices: `X_j± = x̂ ± scale·L e_j`.

use nalgebra::{Cholesky, Const, RealField, SMatrix, SVector};

use crate::angles::{angle_deviations, wrap_angle};
use crate::error::{Error, Result};
use crate::linalg::{c, check_finite, cholesky, sym, sym_rank2k, validate_positive};
use crate::model::{MeasurementModel, MotionModel, PointImages};
use crate::trig::atan2_if;

/// A symmetric sigma-point rule: `2N` points `x̂ ± scale·L e_j` with weight `w`,
/// plus, when `centre` is set, the point `x̂` with weights `w0_mean`, `w0_cov`.
///
/// ```
/// use edccif_core::sigma::SigmaRule;
/// let ckf = SigmaRule::<f64>::cubature(7);
/// assert!((ckf.scale - 7f64.sqrt()).abs() < 1e-15 && (ckf.w - 1.0 / 14.0).abs() < 1e-15);
/// let ukf = SigmaRule::<f64>::unscented(7, 1.0, 2.0, 0.0).unwrap();
/// assert_eq!(ukf.w0_mean, 0.0);
/// assert_eq!(ukf.w0_cov, 2.0);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SigmaRule<T> {
    /// Spread of the points along each Cholesky column.
    pub scale: T,
    /// Weight of each of the `2N` symmetric points.
    pub w: T,
    /// Mean weight of the centre point.
    pub w0_mean: T,
    /// Covariance weight of the centre point.
    pub w0_cov: T,
    /// Whether the centre point is used.
    pub centre: bool,
}

impl<T: RealField + Copy> SigmaRule<T> {
    /// The third-degree spherical-radial cubature rule: `ξ = ±√n e_j`, weights `1/2n`.
    pub fn cubature(n: usize) -> Self {
        let nf: T = c(n as f64);
        Self {
            scale: nf.sqrt(),
            w: T::one() / (c::<T>(2.0) * nf),
            w0_mean: T::zero(),
            w0_cov: T::zero(),
            centre: false,
        }
    }

    /// The scaled unscented transform with parameters `(α, β, κ)`:
    /// `λ = α²(n+κ) − n`, spread `√(n+λ)`, `W0m = λ/(n+λ)`,
    /// `W0c = W0m + 1 − α² + β`, `Wi = 1/(2(n+λ))`. Requires `n + λ > 0`.
    pub fn unscented(n: usize, alpha: T, beta: T, kappa: T) -> Result<Self> {
        let nf: T = c(n as f64);
        let lambda = alpha * alpha * (nf + kappa) - nf;
        let s = nf + lambda;
        if !(s > T::zero()) || !alpha.is_finite() || !beta.is_finite() || !kappa.is_finite() {
            return Err(Error::InvalidParameter {
                what: "unscented (alpha, beta, kappa)",
                expected: "finite, with alpha^2 (n + kappa) > 0",
            });
        }
        let w0 = lambda / s;
        Ok(Self {
            scale: s.sqrt(),
            w: T::one() / (c::<T>(2.0) * s),
            w0_mean: w0,
            w0_cov: w0 + T::one() - alpha * alpha + beta,
            centre: true,
        })
    }
}

/// The scaled square-root factor `scale·chol(P)` whose columns are the point offsets.
#[inline]
pub fn point_offsets<T: RealField + Copy, const N: usize>(
    chol: &Cholesky<T, Const<N>>,
    rule: &SigmaRule<T>,
) -> SMatrix<T, N, N> {
    chol.l() * rule.scale
}

/// Propagates `(x̂, P)` through the motion model over `dt` with the given rule:
/// `x̂⁻ = Σ W f(X)`, `P⁻ = sym(Σ W (f(X) − x̂⁻)(f(X) − x̂⁻)ᵀ + Q)` (centred form).
///
/// ```
/// use edccif_core::{sigma::{SigmaRule, sigma_predict}, models::LinearMotion};
/// use nalgebra::{Matrix2, Vector2};
/// let m = LinearMotion::new(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity() * 0.1).unwrap();
/// let (x, p) = sigma_predict(&SigmaRule::cubature(2), &m, 0.1, &Vector2::new(0.0, 1.0), &Matrix2::identity()).unwrap();
/// assert!((x - Vector2::new(1.0, 1.0)).norm() < 1e-12);
/// assert!((p - Matrix2::new(2.1, 1.0, 1.0, 1.1)).norm() < 1e-12);
/// ```
pub fn sigma_predict<T, F, const N: usize>(
    rule: &SigmaRule<T>,
    motion: &F,
    dt: T,
    x: &SVector<T, N>,
    p: &SMatrix<T, N, N>,
) -> Result<(SVector<T, N>, SMatrix<T, N, N>)>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    sigma_predict_checked(rule, motion, dt, x, p, None, true)
}

/// [`sigma_predict`]; with `check_cov` false, `P⁻` is returned unchecked, for a
/// caller that factorises it next with [`cholesky`] under the name
/// `"predicted covariance P⁻"` (whose finiteness check then fails with the
/// same error, [`Error::NonFinite`] naming `P⁻`, so the check is not made twice).
///
/// `factor`: the lower Cholesky factor of `P` (strict upper triangle zero), when
/// the caller has it: the factor [`cholesky`] gives for `P`, which has then
/// succeeded (`P` finite and positive definite). The step's checks and their
/// order are those of the factorisation here.
#[inline]
#[allow(clippy::too_many_arguments)]
pub(crate) fn sigma_predict_checked<T, F, const N: usize>(
    rule: &SigmaRule<T>,
    motion: &F,
    dt: T,
    x: &SVector<T, N>,
    p: &SMatrix<T, N, N>,
    factor: Option<&SMatrix<T, N, N>>,
    check_cov: bool,
) -> Result<(SVector<T, N>, SMatrix<T, N, N>)>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    validate_positive(dt, "time step dt", false)?;
    check_finite(x, "state estimate x")?;
    let l = match factor {
        Some(f) => f * rule.scale,
        None => point_offsets(&cholesky(p, "covariance P")?, rule),
    };
    let mut xp = SMatrix::<T, N, N>::zeros();
    let mut xm = SMatrix::<T, N, N>::zeros();
    let mut x0 = SVector::<T, N>::zeros();
    // One call for every point (the model's batch hook).
    motion.transition_points(
        x,
        &l,
        dt,
        &mut xp,
        &mut xm,
        if rule.centre { Some(&mut x0) } else { None },
    );
    let mut mean = (xp.column_sum() + xm.column_sum()) * rule.w;
    let x0 = if rule.centre {
        mean += x0 * rule.w0_mean;
        Some(x0)
    } else {
        None
    };
    for j in 0..N {
        let mut cp = xp.column_mut(j);
        cp -= mean;
        let mut cm = xm.column_mut(j);
        cm -= mean;
    }
    let mut cov = sym_rank2k(&xp, &xm) * rule.w;
    if let Some(x0) = x0 {
        let d = x0 - mean;
        cov += d * d.transpose() * rule.w0_cov;
    }
    let cov = sym(&(cov + motion.process_noise(dt)));
    check_finite(&mean, "predicted state x⁻")?;
    if check_cov {
        check_finite(&cov, "predicted covariance P⁻")?;
    }
    Ok((mean, cov))
}

/// Predicted-measurement statistics of a sigma-point rule at `(x̂⁻, P⁻)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasurementStats<T: RealField + Copy, const N: usize, const M: usize> {
    /// Predicted measurement `ẑ` (circular mean for angle components).
    pub z_hat: SVector<T, M>,
    /// Innovation covariance `Pzz` (including `R`).
    pub pzz: SMatrix<T, M, M>,
    /// Cross covariance `Pxz`.
    pub pxz: SMatrix<T, N, M>,
}

/// The measurement images of the points, with the sums a circular mean needs.
struct MeasuredPoints<T: RealField + Copy, const N: usize, const M: usize> {
    plus: PointImages<T, M, N>,
    minus: PointImages<T, M, N>,
    centre: PointImages<T, M, 1>,
    /// Σ cos over the 2N symmetric points (angle components).
    cos_sum: SVector<T, M>,
    /// Σ sin over the 2N symmetric points (angle components).
    sin_sum: SVector<T, M>,
}

impl<T: RealField + Copy, const N: usize, const M: usize> MeasuredPoints<T, N, M> {
    fn zeros() -> Self {
        Self {
            plus: PointImages::zeros(),
            minus: PointImages::zeros(),
            centre: PointImages::zeros(),
            cos_sum: SVector::zeros(),
            sin_sum: SVector::zeros(),
        }
    }
}

/// Fills `pts` (zeroed by the caller, who owns it: no large return value).
#[inline]
fn image_points<T, H, const N: usize, const M: usize>(
    rule: &SigmaRule<T>,
    sensor: &H,
    x: &SVector<T, N>,
    l: &SMatrix<T, N, N>,
    mean_only: bool,
    pts: &mut MeasuredPoints<T, N, M>,
) where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let MeasuredPoints {
        plus,
        minus,
        centre,
        cos_sum,
        sin_sum,
    } = pts;
    let c0 = if rule.centre { Some(centre) } else { None };
    // One call for every point (the model's batch hook). The mean needs the
    // angles' unit vectors only, not the angles.
    if mean_only {
        sensor.measure_points_trig(x, l, plus, minus, c0);
    } else {
        sensor.measure_points(x, l, plus, minus, c0);
    }
    for j in 0..N {
        *cos_sum += plus.cos.column(j) + minus.cos.column(j);
        *sin_sum += plus.sin.column(j) + minus.sin.column(j);
    }
}

/// The weighted sums `(Σ W sin, Σ W cos)` of angle component `k` over the points.
#[inline]
fn trig_sums<T: RealField + Copy, const N: usize, const M: usize>(
    rule: &SigmaRule<T>,
    pts: &MeasuredPoints<T, N, M>,
    k: usize,
) -> (T, T) {
    let mut s = pts.sin_sum[k] * rule.w;
    let mut co = pts.cos_sum[k] * rule.w;
    if rule.centre {
        s += pts.centre.sin[(k, 0)] * rule.w0_mean;
        co += pts.centre.cos[(k, 0)] * rule.w0_mean;
    }
    (s, co)
}

/// Weighted mean of the measurement points: `atan2(Σ W sin, Σ W cos)` for angle
/// components (the kernel [`crate::trig::atan2`] for a model with
/// [`MeasurementModel::fast_trig`], the library's otherwise), the plain weighted
/// mean otherwise.
#[inline]
fn points_mean<T, H, const N: usize, const M: usize>(
    rule: &SigmaRule<T>,
    sensor: &H,
    pts: &MeasuredPoints<T, N, M>,
) -> SVector<T, M>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let mut z_hat = SVector::<T, M>::zeros();
    let fast = sensor.fast_trig();
    for k in 0..M {
        if sensor.is_angle(k) {
            let (s, co) = trig_sums(rule, pts, k);
            z_hat[k] = atan2_if(fast, s, co);
        } else {
            let mut m = (pts.plus.z.row(k).sum() + pts.minus.z.row(k).sum()) * rule.w;
            if rule.centre {
                m += pts.centre.z[(k, 0)] * rule.w0_mean;
            }
            z_hat[k] = m;
        }
    }
    z_hat
}

/// Every `z` the model wrote is finite (an angle's mean is read from the unit
/// vectors alone: a model that failed to evaluate its points writes NaN into
/// `z`, which must not pass unnoticed).
///
/// `v·0` is `±0` for a finite `v` and NaN for NaN or ±∞, and a sum of `±0`
/// terms is `±0` while one NaN term makes it NaN: so the sum of `v·0` over
/// every entry is zero exactly when all are finite. Elementwise products and
/// sums of the two halves (which vectorise) and one short reduction, in place
/// of a test per entry.
#[inline]
fn points_finite<T: RealField + Copy, const N: usize, const M: usize>(
    pts: &MeasuredPoints<T, N, M>,
) -> bool {
    let zero = T::zero();
    let both = pts.plus.z * zero + pts.minus.z * zero;
    let mut s = (pts.centre.z * zero).sum();
    for v in both.iter() {
        s += *v;
    }
    s == zero
}

/// The unit vector `(cos ẑ, sin ẑ)` of each angle component's circular mean,
/// from the weighted sums (`(1, 0)` when both vanish, as `atan2(0, 0) = 0`).
#[inline]
fn mean_directions<T, H, const N: usize, const M: usize>(
    rule: &SigmaRule<T>,
    sensor: &H,
    pts: &MeasuredPoints<T, N, M>,
) -> [SVector<T, M>; 2]
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let mut mean_cos = SVector::<T, M>::zeros();
    let mut mean_sin = SVector::<T, M>::zeros();
    for k in 0..M {
        if sensor.is_angle(k) {
            let (s, co) = trig_sums(rule, pts, k);
            let norm = (co * co + s * s).sqrt();
            if norm > T::zero() {
                mean_cos[k] = co / norm;
                mean_sin[k] = s / norm;
            } else {
                mean_cos[k] = T::one();
            }
        }
    }
    [mean_cos, mean_sin]
}

/// The deviations of the points of `imgs` from the mean `ẑ` on the fast path:
/// `z − ẑ`, and for angle components `wrap(θ − ẑ)` from the points' unit vectors
/// ([`angle_deviation`](crate::angles::angle_deviation)).
#[inline]
fn fast_deviations<T, H, const N: usize, const M: usize, const K: usize>(
    sensor: &H,
    imgs: &PointImages<T, M, K>,
    z_hat: &SVector<T, M>,
    [mean_cos, mean_sin]: &[SVector<T, M>; 2],
) -> SMatrix<T, M, K>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let mut d = SMatrix::<T, M, K>::zeros();
    for k in 0..M {
        if sensor.is_angle(k) {
            let row = angle_deviations::<T, K>(
                &imgs.cos.row(k).transpose(),
                &imgs.sin.row(k).transpose(),
                (mean_cos[k], mean_sin[k]),
            );
            d.set_row(k, &row.transpose());
        } else {
            for j in 0..K {
                d[(k, j)] = imgs.z[(k, j)] - z_hat[k];
            }
        }
    }
    d
}

/// [`sigma_measure`] for a model that opted into fast trigonometry
/// ([`MeasurementModel::fast_trig`]): `ẑ` from the same weighted sums (its
/// angles by the kernel [`crate::trig::atan2`], a few ulp from the library's),
/// and `Pzz`, `Pxz` from deviations taken from the points' unit vectors instead
/// of an `atan2` per point.
///
/// With `whitened`, the `pxz` field holds `A = L⁻¹ Pxz = w·scale·(Z⁺ − Z⁻)ᵀ`
/// instead, where `l = scale·L` (the cross covariance in the coordinates of the
/// prior's factor `L`, what [`crate::filters`]'s fast contribution needs; no
/// product with `l`).
fn sigma_measure_fast<T, H, const N: usize, const M: usize>(
    rule: &SigmaRule<T>,
    sensor: &H,
    x: &SVector<T, N>,
    l: &SMatrix<T, N, N>,
    whitened: bool,
) -> Result<MeasurementStats<T, N, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let mut pts = MeasuredPoints::zeros();
    image_points(rule, sensor, x, l, true, &mut pts);
    let z_hat = points_mean(rule, sensor, &pts);
    let dir = mean_directions(rule, sensor, &pts);
    let zp = fast_deviations(sensor, &pts.plus, &z_hat, &dir);
    let zm = fast_deviations(sensor, &pts.minus, &z_hat, &dir);
    let mut pzz = sym_rank2k(&zp, &zm) * rule.w;
    if rule.centre {
        let d = fast_deviations(sensor, &pts.centre, &z_hat, &dir);
        pzz += d * d.transpose() * rule.w0_cov;
    }
    let pzz = sym(&(pzz + sensor.noise()));
    // Centre point deviates by zero in x, so it adds nothing to Pxz.
    let pxz = if whitened {
        (zp - zm).transpose() * (rule.w * rule.scale)
    } else {
        // Pxz = w·l·(Z⁺ − Z⁻)ᵀ from the lower triangle of `l` (a Cholesky
        // factor), column by column: half the multiplications of the full product.
        let e = (zp - zm) * rule.w;
        let mut pxz = SMatrix::<T, N, M>::zeros();
        for m in 0..M {
            for k in 0..N {
                let emk = e[(m, k)];
                for i in k..N {
                    pxz[(i, m)] += l[(i, k)] * emk;
                }
            }
        }
        pxz
    };
    check_finite(&z_hat, "predicted measurement ẑ")?;
    // No separate check of the points: every point's deviation, from its `z` or
    // its unit vector, enters the diagonal of `Pzz` squared, so a point the
    // model could not evaluate (NaN or ∞) fails the check of `Pzz`.
    check_finite(&pzz, "innovation covariance Pzz")?;
    // The whitened `A = w·scale·(Z⁺ − Z⁻)ᵀ` needs no check of its own when
    // `w·scale ≤ 1` (the cubature rule's `1/(2√N)`): a finite `Pzz` has
    // finite squares of every deviation on its diagonal, so every deviation
    // is below √(max) in magnitude, their differences below 2√(max), and
    // `A` finite.
    if !whitened || !(rule.w * rule.scale <= T::one()) {
        check_finite(&pxz, "cross covariance Pxz")?;
    }
    Ok(MeasurementStats { z_hat, pzz, pxz })
}

/// The statistics of [`sigma_measure`] for a model with
/// [`MeasurementModel::fast_trig`], with the `pxz` field holding the whitened
/// cross covariance `A = L⁻¹ Pxz = w·scale·(Z⁺ − Z⁻)ᵀ` (for `l = scale·L`, `L`
/// lower triangular) instead of `Pxz`: the fast path of `cif_update`, whose
/// contribution needs only `A` (no product with `l`, no triangular solve).
pub(crate) fn sigma_measure_whitened<T, H, const N: usize, const M: usize>(
    rule: &SigmaRule<T>,
    sensor: &H,
    x: &SVector<T, N>,
    l: &SMatrix<T, N, N>,
) -> Result<MeasurementStats<T, N, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    sigma_measure_fast(rule, sensor, x, l, true)
}

/// Only the predicted measurement `ẑ` (what an untriggered step needs).
pub fn sigma_measure_mean<T, H, const N: usize, const M: usize>(
    rule: &SigmaRule<T>,
    sensor: &H,
    x: &SVector<T, N>,
    l: &SMatrix<T, N, N>,
) -> Result<SVector<T, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let mut pts = MeasuredPoints::zeros();
    image_points(rule, sensor, x, l, true, &mut pts);
    let z_hat = points_mean(rule, sensor, &pts);
    check_finite(&z_hat, "predicted measurement ẑ")?;
    // An angle's mean is taken from the cosines and sines alone: a model that
    // failed to evaluate its points (NaN in `z`) must not pass unnoticed.
    if !points_finite(&pts) {
        return Err(Error::NonFinite {
            what: "predicted measurement ẑ",
        });
    }
    Ok(z_hat)
}

/// Points redrawn at `(x̂⁻, l = scale·chol(P⁻))` through `h`: `ẑ`, `Pzz` (with `R`)
/// and `Pxz` (`docs/algorithm.md` §3 step 2). Deviations of angle components are wrapped.
/// `l` is lower triangular; a model with [`MeasurementModel::fast_trig`] reads
/// only its lower triangle for `Pxz`.
pub fn sigma_measure<T, H, const N: usize, const M: usize>(
    rule: &SigmaRule<T>,
    sensor: &H,
    x: &SVector<T, N>,
    l: &SMatrix<T, N, N>,
) -> Result<MeasurementStats<T, N, M>>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    if sensor.fast_trig() {
        return sigma_measure_fast(rule, sensor, x, l, false);
    }
    let mut pts = MeasuredPoints::zeros();
    image_points(rule, sensor, x, l, false, &mut pts);
    let z_hat = points_mean(rule, sensor, &pts);
    let (mut zp, mut zm, z0) = (pts.plus.z, pts.minus.z, pts.centre.z.column(0).into_owned());
    for j in 0..N {
        for k in 0..M {
            zp[(k, j)] -= z_hat[k];
            zm[(k, j)] -= z_hat[k];
            if sensor.is_angle(k) {
                zp[(k, j)] = wrap_angle(zp[(k, j)]);
                zm[(k, j)] = wrap_angle(zm[(k, j)]);
            }
        }
    }
    let mut pzz = sym_rank2k(&zp, &zm) * rule.w;
    if rule.centre {
        let mut d = z0 - z_hat;
        for k in 0..M {
            if sensor.is_angle(k) {
                d[k] = wrap_angle(d[k]);
            }
        }
        pzz += d * d.transpose() * rule.w0_cov;
    }
    let pzz = sym(&(pzz + sensor.noise()));
    // Centre point deviates by zero in x, so it adds nothing to Pxz.
    let pxz = l * (zp - zm).transpose() * rule.w;
    check_finite(&z_hat, "predicted measurement ẑ")?;
    check_finite(&pzz, "innovation covariance Pzz")?;
    check_finite(&pxz, "cross covariance Pxz")?;
    Ok(MeasurementStats { z_hat, pzz, pxz })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::cholesky_lower;
    use crate::models::RangePitchAzimuth;

    /// Deterministic values in [−0.5, 0.5).
    fn next(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    }

    #[test]
    fn whitened_statistics_are_the_factor_solved_cross_covariance() {
        // `sigma_measure_whitened` returns `ẑ`, `Pzz` bit for bit as the fast
        // `sigma_measure`, and `A` with `L A = Pxz` within 1e-13 relative.
        let sensor = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)
            .unwrap()
            .with_fast_trig(true);
        let mut seed = 9;
        for (round, rule) in [
            SigmaRule::<f64>::cubature(7),
            SigmaRule::unscented(7, 1.0, 2.0, 0.0).unwrap(),
        ]
        .iter()
        .cycle()
        .take(200)
        .enumerate()
        {
            let b = SMatrix::<f64, 7, 7>::from_fn(|_, _| next(&mut seed));
            let s = if round % 3 == 0 { 1.0 } else { 0.05 };
            let p = (b * b.transpose() + SMatrix::identity()) * s;
            let l0 = cholesky_lower(&p, "P").unwrap();
            let x = SVector::<f64, 7>::from_fn(|_, _| 20.0 * next(&mut seed));
            let l = l0 * rule.scale;
            let full = sigma_measure(rule, &sensor, &x, &l).unwrap();
            let white = sigma_measure_whitened(rule, &sensor, &x, &l).unwrap();
            assert_eq!(white.z_hat, full.z_hat);
            assert_eq!(white.pzz, full.pzz);
            let back = l0 * white.pxz;
            let err = (back - full.pxz).abs().max() / full.pxz.abs().max();
            assert!(err < 1e-13, "relative difference {err:e}");
        }
    }
}
