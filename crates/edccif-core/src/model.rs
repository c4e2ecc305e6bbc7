//! Model traits: what a filter must know about the target's motion and about a
//! sensor. Models implement one or two methods; the filters are supplied by the
//! crate as free functions over these traits.

use nalgebra::{RealField, SMatrix, SVector};

use crate::linalg::c;
use crate::trig::wrap_angle;

/// Discrete-time motion model `x(t + dt) = f(x(t), dt) + w`, `w ~ N(0, Q(dt))`.
///
/// `N` is the state dimension. The time step `dt` is given at every call, so one
/// model serves sensors with their own timestamps and non-uniform steps; the
/// network step passes [`StepInputs::dt`](crate::StepInputs::dt). Only
/// [`transition`](Self::transition) and [`process_noise`](Self::process_noise) are
/// required; the Jacobian defaults to central finite differences (needed only by
/// the EKF).
///
/// ```
/// use edccif_core::model::MotionModel;
/// use nalgebra::{Matrix2, Vector2};
///
/// /// 1-D constant velocity with white-acceleration noise of intensity 0.01.
/// struct Cv;
/// impl MotionModel<f64, 2> for Cv {
///     fn transition(&self, x: &Vector2<f64>, dt: f64) -> Vector2<f64> {
///         Vector2::new(x[0] + dt * x[1], x[1])
///     }
///     fn process_noise(&self, dt: f64) -> Matrix2<f64> {
///         Matrix2::new(dt.powi(3) / 3.0, dt.powi(2) / 2.0, dt.powi(2) / 2.0, dt) * 0.01
///     }
/// }
/// let f = Cv.jacobian(&Vector2::new(0.0, 1.0), 0.5);
/// assert!((f - Matrix2::new(1.0, 0.5, 0.0, 1.0)).norm() < 1e-6);
/// ```
pub trait MotionModel<T: RealField + Copy, const N: usize> {
    /// `f(x, dt)`: the noise-free state `dt` later.
    fn transition(&self, x: &SVector<T, N>, dt: T) -> SVector<T, N>;
    /// The process-noise covariance `Q(dt)` accumulated over `dt` (symmetric
    /// positive semi-definite).
    fn process_noise(&self, dt: T) -> SMatrix<T, N, N>;
    /// `∂f/∂x` at `x` over `dt`. Default: central finite differences.
    fn jacobian(&self, x: &SVector<T, N>, dt: T) -> SMatrix<T, N, N> {
        finite_difference_jacobian(|v| self.transition(v, dt), x, |_| false)
    }
    /// `(f(x, dt), ∂f/∂x)` at once, what the EKF's prediction needs; a model whose
    /// two share work (the turn models' `sin_cos`) overrides it. Default:
    /// [`transition`](Self::transition) and [`jacobian`](Self::jacobian).
    ///
    /// ```
    /// use edccif_core::{model::MotionModel, models::CoordinatedTurn};
    /// use nalgebra::SVector;
    /// let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    /// let x = SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]);
    /// assert_eq!(ct.transition_with_jacobian(&x, 0.1), (ct.transition(&x, 0.1), ct.jacobian(&x, 0.1)));
    /// ```
    #[inline]
    fn transition_with_jacobian(
        &self,
        x: &SVector<T, N>,
        dt: T,
    ) -> (SVector<T, N>, SMatrix<T, N, N>) {
        (self.transition(x, dt), self.jacobian(x, dt))
    }
    /// `F P Fᵀ` for this model's Jacobian `F` (as
    /// [`transition_with_jacobian`](Self::transition_with_jacobian) returns it):
    /// the EKF's covariance prediction before `Q` is added. Default: the general
    /// products `(F P) Fᵀ`. A model whose Jacobian has exact structural zeros
    /// overrides it with [`congruence_sparse`](crate::linalg::congruence_sparse),
    /// which leaves out the `0·x` terms and gives the same bits.
    ///
    /// ```
    /// use edccif_core::{model::MotionModel, models::CoordinatedTurn};
    /// use nalgebra::{SMatrix, SVector};
    /// let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
    /// let x = SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]);
    /// let f = ct.jacobian(&x, 0.1);
    /// let p = SMatrix::<f64, 7, 7>::from_fn(|i, j| if i == j { 2.0 } else { 0.1 });
    /// assert_eq!(ct.jacobian_congruence(&f, &p), f * p * f.transpose());
    /// ```
    #[inline]
    fn jacobian_congruence(&self, f: &SMatrix<T, N, N>, p: &SMatrix<T, N, N>) -> SMatrix<T, N, N> {
        f * p * f.transpose()
    }
    /// Batch hook of the sigma-point prediction: column `j` of `plus` becomes
    /// `f(x + offsets[:, j], dt)`, column `j` of `minus` becomes
    /// `f(x − offsets[:, j], dt)`, and `centre`, when given, becomes `f(x, dt)`.
    ///
    /// [`sigma_predict`](crate::sigma::sigma_predict) calls it once per step, so a
    /// model whose evaluation has a per-call cost (a callable in another language,
    /// a SIMD kernel) evaluates all `2N (+1)` points at once. The default calls
    /// [`transition`](Self::transition) point by point. A model that cannot
    /// evaluate a point writes NaN: the filter's finiteness checks then fail the
    /// step with [`Error::NonFinite`](crate::Error::NonFinite) and nothing is
    /// committed.
    ///
    /// ```
    /// use edccif_core::model::MotionModel;
    /// use edccif_core::models::RandomWalk;
    /// use nalgebra::{Matrix2, Vector2};
    /// let rw = RandomWalk::new(0.1).unwrap();
    /// let (mut plus, mut minus, mut centre) = (Matrix2::zeros(), Matrix2::zeros(), Vector2::zeros());
    /// let x = Vector2::new(1.0, 2.0);
    /// rw.transition_points(&x, &Matrix2::identity(), 0.1, &mut plus, &mut minus, Some(&mut centre));
    /// assert_eq!(plus, Matrix2::new(2.0, 1.0, 2.0, 3.0));
    /// assert_eq!(minus, Matrix2::new(0.0, 1.0, 2.0, 1.0));
    /// assert_eq!(centre, x);
    /// ```
    fn transition_points(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        dt: T,
        plus: &mut SMatrix<T, N, N>,
        minus: &mut SMatrix<T, N, N>,
        centre: Option<&mut SVector<T, N>>,
    ) {
        transition_points_each(self, x, offsets, dt, plus, minus, centre);
    }
}

/// The default of [`MotionModel::transition_points`]: [`MotionModel::transition`]
/// point by point (also the reference path of a model whose override is opt-in).
#[inline]
pub(crate) fn transition_points_each<T, F, const N: usize>(
    model: &F,
    x: &SVector<T, N>,
    offsets: &SMatrix<T, N, N>,
    dt: T,
    plus: &mut SMatrix<T, N, N>,
    minus: &mut SMatrix<T, N, N>,
    centre: Option<&mut SVector<T, N>>,
) where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    for j in 0..N {
        let col = offsets.column(j);
        plus.set_column(j, &model.transition(&(x + col), dt));
        minus.set_column(j, &model.transition(&(x - col), dt));
    }
    if let Some(c0) = centre {
        *c0 = model.transition(x, dt);
    }
}

/// The images of `K` points through a measurement model: `z` column `j` is
/// `h(X_j)`; for angle components, `cos`/`sin` hold the cosine and sine of the
/// angle (entries of non-angle components are unspecified), as
/// [`MeasurementModel::measure_with_trig`] returns them. Filled by
/// [`MeasurementModel::measure_points`].
///
/// ```
/// use edccif_core::model::PointImages;
/// let imgs = PointImages::<f64, 2, 3>::zeros();
/// assert_eq!(imgs.z.ncols(), 3);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointImages<T: RealField + Copy, const M: usize, const K: usize> {
    /// `h` of each point, one column per point.
    pub z: SMatrix<T, M, K>,
    /// Cosine of the angle components.
    pub cos: SMatrix<T, M, K>,
    /// Sine of the angle components.
    pub sin: SMatrix<T, M, K>,
}

impl<T: RealField + Copy, const M: usize, const K: usize> PointImages<T, M, K> {
    /// All zeros.
    pub fn zeros() -> Self {
        Self {
            z: SMatrix::zeros(),
            cos: SMatrix::zeros(),
            sin: SMatrix::zeros(),
        }
    }
    /// Stores `(z, cos, sin)` (what [`MeasurementModel::measure_with_trig`]
    /// returns) as column `j`.
    ///
    /// ```
    /// use edccif_core::model::PointImages;
    /// use nalgebra::Vector1;
    /// let mut imgs = PointImages::<f64, 1, 2>::zeros();
    /// imgs.set(1, (Vector1::new(0.5), Vector1::new(1.0), Vector1::new(0.0)));
    /// assert_eq!(imgs.z[(0, 1)], 0.5);
    /// ```
    #[inline]
    pub fn set(&mut self, j: usize, zcs: (SVector<T, M>, SVector<T, M>, SVector<T, M>)) {
        self.z.set_column(j, &zcs.0);
        self.cos.set_column(j, &zcs.1);
        self.sin.set_column(j, &zcs.2);
    }
}

/// Measurement model `z = h(x) + v`, `v ~ N(0, R)`.
///
/// `N` is the state dimension, `M` the measurement dimension. Components for
/// which [`is_angle`](Self::is_angle) is true are wrapped to `[−π, π)` in every
/// difference and averaged circularly (`docs/algorithm.md` §2).
pub trait MeasurementModel<T: RealField + Copy, const N: usize, const M: usize> {
    /// `h(x)`: the noise-free measurement of state `x`.
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, M>;
    /// The measurement-noise covariance `R` (symmetric positive definite).
    fn noise(&self) -> SMatrix<T, M, M>;
    /// Whether measurement component `k` is an angle. Default: none are.
    #[inline]
    fn is_angle(&self, k: usize) -> bool {
        let _ = k;
        false
    }
    /// Fast trigonometry (the trait's default `false`, the reference path, for
    /// models without a fast path; the catalogue's angle sensors return `true`
    /// unless built `with_fast_trig(false)`). When true,
    /// the sigma-point transforms ([`sigma_measure`](crate::sigma::sigma_measure))
    /// read this model's points through
    /// [`measure_points_trig`](Self::measure_points_trig) (no `atan2` per point) and
    /// take each point's angle deviation from the circular mean from its unit
    /// vector ([`angle_deviation`](crate::angles::angle_deviation)), and the
    /// circular mean `ẑ = atan2(Σ W sin, Σ W cos)` takes the kernel
    /// [`trig::atan2`](crate::trig::atan2); the catalogue's angle sensors then
    /// also compute `h(x)` (the EKF's predicted measurement) with that kernel.
    /// The results differ from the reference path in the last bits (see
    /// `docs/guide.md` §7 and `docs/performance.md`, "Fast trigonometry"); the
    /// catalogue's angle sensors switch it through `with_fast_trig`.
    ///
    /// ```
    /// use edccif_core::{model::MeasurementModel, models::RangeBearing};
    /// let s = RangeBearing::new([0.0, 0.0], 0.1, 0.01).unwrap();
    /// assert!(MeasurementModel::<f64, 4, 2>::fast_trig(&s)); // the catalogue's default
    /// assert!(!MeasurementModel::<f64, 4, 2>::fast_trig(&s.with_fast_trig(false)));
    /// ```
    #[inline]
    fn fast_trig(&self) -> bool {
        false
    }
    /// `∂h/∂x` at `x`. Default: central finite differences (angle-wrapped).
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, M, N> {
        finite_difference_jacobian(|v| self.measure(v), x, |k| self.is_angle(k))
    }
    /// `(h(x), ∂h/∂x)` at once, what the EKF's update needs; a model whose two
    /// share work (the catalogue's sensors: the offset from the sensor and its
    /// norms) overrides it, with the same expressions so the same bits. Default:
    /// [`measure`](Self::measure) and [`jacobian`](Self::jacobian).
    ///
    /// ```
    /// use edccif_core::{model::MeasurementModel, models::RangePitchAzimuth};
    /// use nalgebra::SVector;
    /// let s = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01).unwrap();
    /// let x = SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]);
    /// assert_eq!(s.measure_with_jacobian(&x), (s.measure(&x), s.jacobian(&x)));
    /// ```
    #[inline]
    fn measure_with_jacobian(&self, x: &SVector<T, N>) -> (SVector<T, M>, SMatrix<T, M, N>) {
        (self.measure(x), self.jacobian(x))
    }
    /// `(P Gᵀ, G P Gᵀ)` for this model's Jacobian `G` (as
    /// [`jacobian`](Self::jacobian) returns it) and a finite covariance `P`: the
    /// EKF's cross covariance and innovation covariance before `R`, and the
    /// products of the untriggered steps' gain. Default: the general products
    /// `P Gᵀ` and `G (P Gᵀ)`. A model whose Jacobian has exact structural zeros
    /// overrides it: the catalogue's sensors read only the position, the first
    /// `D` state components, and use
    /// [`jacobian_products_leading`](crate::linalg::jacobian_products_leading),
    /// which leaves out the `0·x` terms and gives the same bits.
    ///
    /// ```
    /// use edccif_core::{model::MeasurementModel, models::RangePitchAzimuth};
    /// use nalgebra::{SMatrix, SVector};
    /// let s = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01).unwrap();
    /// let x = SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]);
    /// let g = s.jacobian(&x);
    /// let p = SMatrix::<f64, 7, 7>::from_fn(|i, j| if i == j { 2.0 } else { 0.1 });
    /// let pg = p * g.transpose();
    /// assert_eq!(s.jacobian_products(&g, &p), (pg, g * pg));
    /// ```
    #[inline]
    fn jacobian_products(
        &self,
        g: &SMatrix<T, M, N>,
        p: &SMatrix<T, N, N>,
    ) -> (SMatrix<T, N, M>, SMatrix<T, M, M>) {
        let pg = p * g.transpose();
        (pg, g * pg)
    }
    /// `h(x)` with the cosine and sine of every angle component (`(z, cos, sin)`;
    /// entries of non-angle components are unspecified). The circular means of the
    /// sigma-point transforms use them. Default: `sin_cos` of `h(x)`; a model that
    /// knows the unit vectors from its geometry overrides this to save the
    /// trigonometry.
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<T, N>,
    ) -> (SVector<T, M>, SVector<T, M>, SVector<T, M>) {
        let z = self.measure(x);
        let mut co = SVector::<T, M>::zeros();
        let mut si = SVector::<T, M>::zeros();
        for k in 0..M {
            if self.is_angle(k) {
                let (s, c) = z[k].sin_cos();
                si[k] = s;
                co[k] = c;
            }
        }
        (z, co, si)
    }
    /// Batch hook of the sigma-point measurement transforms: column `j` of `plus`
    /// becomes `measure_with_trig(x + offsets[:, j])`, of `minus`
    /// `measure_with_trig(x − offsets[:, j])`, and `centre`, when given,
    /// `measure_with_trig(x)`.
    ///
    /// The sigma measurement transforms ([`sigma_measure`](crate::sigma::sigma_measure),
    /// [`sigma_measure_mean`](crate::sigma::sigma_measure_mean)) call it once per
    /// transform, so a model with a per-call cost evaluates all points at once. The
    /// default calls [`measure_with_trig`](Self::measure_with_trig) point by point.
    /// A model that cannot evaluate a point writes NaN into its `z`: the filter
    /// then fails the step with [`Error::NonFinite`](crate::Error::NonFinite) and
    /// nothing is committed.
    ///
    /// ```
    /// use edccif_core::model::{MeasurementModel, PointImages};
    /// use edccif_core::models::BearingOnly;
    /// use nalgebra::{Matrix4, Vector4};
    /// let s = BearingOnly::new([0.0, 0.0], 0.01).unwrap();
    /// let (mut plus, mut minus) = (PointImages::zeros(), PointImages::zeros());
    /// let x = Vector4::new(1.0, 0.0, 0.0, 0.0);
    /// MeasurementModel::<f64, 4, 1>::measure_points(&s, &x, &Matrix4::identity(), &mut plus, &mut minus, None);
    /// assert!((plus.z[(0, 1)] - core::f64::consts::FRAC_PI_4).abs() < 1e-15); // towards (1, 1)
    /// assert_eq!(minus.z[(0, 0)], 0.0); // the point (0, 0) on the sensor: atan2(0, 0)
    /// ```
    fn measure_points(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        plus: &mut PointImages<T, M, N>,
        minus: &mut PointImages<T, M, N>,
        centre: Option<&mut PointImages<T, M, 1>>,
    ) {
        for j in 0..N {
            let col = offsets.column(j);
            plus.set(j, self.measure_with_trig(&(x + col)));
            minus.set(j, self.measure_with_trig(&(x - col)));
        }
        if let Some(c0) = centre {
            c0.set(0, self.measure_with_trig(x));
        }
    }
    /// Batch hook of the mean-only sigma transform
    /// ([`sigma_measure_mean`](crate::sigma::sigma_measure_mean), the predicted
    /// measurement of an untriggered step): as
    /// [`measure_points`](Self::measure_points), except that the angle components
    /// of `z` need not be written, since the circular mean reads an angle only
    /// through its cosine and sine. A model whose angles are `atan2` of its
    /// geometry overrides this to skip those `atan2`; the catalogue's angle sensors
    /// do. A model that cannot evaluate a point writes NaN into its `z` (or its
    /// unit vectors). Default: [`measure_points`](Self::measure_points).
    ///
    /// ```
    /// use edccif_core::model::{MeasurementModel, PointImages};
    /// use edccif_core::models::RangeBearing;
    /// use nalgebra::{Matrix4, Vector4};
    /// let s = RangeBearing::new([0.0, 0.0], 0.1, 0.01).unwrap();
    /// let (mut plus, mut minus) = (PointImages::zeros(), PointImages::zeros());
    /// let x = Vector4::new(1.0, 0.0, 0.0, 0.0);
    /// MeasurementModel::<f64, 4, 2>::measure_points_trig(&s, &x, &Matrix4::identity(), &mut plus, &mut minus, None);
    /// assert!((plus.z[(0, 1)] - 2f64.sqrt()).abs() < 1e-15); // the range towards (1, 1)
    /// assert!((plus.cos[(1, 1)] - 0.5f64.sqrt()).abs() < 1e-15); // its bearing's unit vector
    /// ```
    fn measure_points_trig(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        plus: &mut PointImages<T, M, N>,
        minus: &mut PointImages<T, M, N>,
        centre: Option<&mut PointImages<T, M, 1>>,
    ) {
        self.measure_points(x, offsets, plus, minus, centre)
    }
}

impl<T: RealField + Copy, const N: usize, F: MotionModel<T, N> + ?Sized> MotionModel<T, N> for &F {
    #[inline]
    fn transition(&self, x: &SVector<T, N>, dt: T) -> SVector<T, N> {
        (**self).transition(x, dt)
    }
    #[inline]
    fn process_noise(&self, dt: T) -> SMatrix<T, N, N> {
        (**self).process_noise(dt)
    }
    #[inline]
    fn jacobian(&self, x: &SVector<T, N>, dt: T) -> SMatrix<T, N, N> {
        (**self).jacobian(x, dt)
    }
    #[inline]
    fn transition_with_jacobian(
        &self,
        x: &SVector<T, N>,
        dt: T,
    ) -> (SVector<T, N>, SMatrix<T, N, N>) {
        (**self).transition_with_jacobian(x, dt)
    }
    #[inline]
    fn jacobian_congruence(&self, f: &SMatrix<T, N, N>, p: &SMatrix<T, N, N>) -> SMatrix<T, N, N> {
        (**self).jacobian_congruence(f, p)
    }
    #[inline]
    fn transition_points(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        dt: T,
        plus: &mut SMatrix<T, N, N>,
        minus: &mut SMatrix<T, N, N>,
        centre: Option<&mut SVector<T, N>>,
    ) {
        (**self).transition_points(x, offsets, dt, plus, minus, centre)
    }
}

impl<
        T: RealField + Copy,
        const N: usize,
        const M: usize,
        H: MeasurementModel<T, N, M> + ?Sized,
    > MeasurementModel<T, N, M> for &H
{
    #[inline]
    fn measure(&self, x: &SVector<T, N>) -> SVector<T, M> {
        (**self).measure(x)
    }
    #[inline]
    fn noise(&self) -> SMatrix<T, M, M> {
        (**self).noise()
    }
    #[inline]
    fn is_angle(&self, k: usize) -> bool {
        (**self).is_angle(k)
    }
    #[inline]
    fn jacobian(&self, x: &SVector<T, N>) -> SMatrix<T, M, N> {
        (**self).jacobian(x)
    }
    #[inline]
    fn measure_with_jacobian(&self, x: &SVector<T, N>) -> (SVector<T, M>, SMatrix<T, M, N>) {
        (**self).measure_with_jacobian(x)
    }
    #[inline]
    fn jacobian_products(
        &self,
        g: &SMatrix<T, M, N>,
        p: &SMatrix<T, N, N>,
    ) -> (SMatrix<T, N, M>, SMatrix<T, M, M>) {
        (**self).jacobian_products(g, p)
    }
    #[inline]
    fn measure_with_trig(
        &self,
        x: &SVector<T, N>,
    ) -> (SVector<T, M>, SVector<T, M>, SVector<T, M>) {
        (**self).measure_with_trig(x)
    }
    #[inline]
    fn measure_points(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        plus: &mut PointImages<T, M, N>,
        minus: &mut PointImages<T, M, N>,
        centre: Option<&mut PointImages<T, M, 1>>,
    ) {
        (**self).measure_points(x, offsets, plus, minus, centre)
    }
    #[inline]
    fn measure_points_trig(
        &self,
        x: &SVector<T, N>,
        offsets: &SMatrix<T, N, N>,
        plus: &mut PointImages<T, M, N>,
        minus: &mut PointImages<T, M, N>,
        centre: Option<&mut PointImages<T, M, 1>>,
    ) {
        (**self).measure_points_trig(x, offsets, plus, minus, centre)
    }
    #[inline]
    fn fast_trig(&self) -> bool {
        (**self).fast_trig()
    }
}

/// Central finite-difference Jacobian of `g` at `x`, step `ε^{1/3}·max(1, |x_j|)`.
/// Output components for which `is_angle(k)` holds are wrapped before dividing.
///
/// ```
/// use edccif_core::model::finite_difference_jacobian;
/// use nalgebra::{Vector1, Vector2, Matrix1x2};
/// let j = finite_difference_jacobian(|v: &Vector2<f64>| Vector1::new(v[0] * v[1]), &Vector2::new(2.0, 3.0), |_| false);
/// assert!((j - Matrix1x2::new(3.0, 2.0)).norm() < 1e-8);
/// ```
pub fn finite_difference_jacobian<T, const N: usize, const K: usize>(
    g: impl Fn(&SVector<T, N>) -> SVector<T, K>,
    x: &SVector<T, N>,
    is_angle: impl Fn(usize) -> bool,
) -> SMatrix<T, K, N>
where
    T: RealField + Copy,
{
    let base: T = c(6.055_454_452_393_343e-6); // f64::EPSILON^(1/3)
    let two: T = c(2.0);
    let mut j = SMatrix::<T, K, N>::zeros();
    for col in 0..N {
        let h = base * T::one().max(x[col].abs());
        let mut xp = *x;
        let mut xm = *x;
        xp[col] += h;
        xm[col] -= h;
        let mut d = g(&xp) - g(&xm);
        for k in 0..K {
            if is_angle(k) {
                d[k] = wrap_angle(d[k]);
            }
        }
        j.set_column(col, &(d / (two * h)));
    }
    j
}

/// The steps `ε^{1/3}·max(1, |x_j|)` of [`finite_difference_jacobian`] as the
/// diagonal of an offset matrix.
fn difference_steps<T: RealField + Copy, const N: usize>(x: &SVector<T, N>) -> SMatrix<T, N, N> {
    let base: T = c(6.055_454_452_393_343e-6); // f64::EPSILON^(1/3)
    SMatrix::<T, N, N>::from_diagonal(&x.map(|v| base * T::one().max(v.abs())))
}

/// [`finite_difference_jacobian`] of a motion model evaluated through its batch
/// hook [`MotionModel::transition_points`]: one call for all `2N` points. A model
/// whose evaluation has a per-call cost returns this from
/// [`MotionModel::jacobian`].
///
/// ```
/// use edccif_core::model::{motion_jacobian_batched, MotionModel};
/// use edccif_core::models::ConstantVelocity;
/// use nalgebra::Vector4;
/// let cv = ConstantVelocity::new(0.1).unwrap();
/// let x = Vector4::new(1.0, 2.0, 3.0, 4.0);
/// assert!((motion_jacobian_batched(&cv, &x, 0.5) - cv.jacobian(&x, 0.5)).norm() < 1e-9);
/// ```
pub fn motion_jacobian_batched<T, F, const N: usize>(
    motion: &F,
    x: &SVector<T, N>,
    dt: T,
) -> SMatrix<T, N, N>
where
    T: RealField + Copy,
    F: MotionModel<T, N> + ?Sized,
{
    let steps = difference_steps(x);
    let mut plus = SMatrix::<T, N, N>::zeros();
    let mut minus = SMatrix::<T, N, N>::zeros();
    motion.transition_points(x, &steps, dt, &mut plus, &mut minus, None);
    let two: T = c(2.0);
    let mut j = plus - minus;
    for col in 0..N {
        let h = steps[(col, col)];
        let mut cj = j.column_mut(col);
        cj /= two * h;
    }
    j
}

/// [`finite_difference_jacobian`] of a measurement model (angle components
/// wrapped) evaluated through its batch hook [`MeasurementModel::measure_points`]:
/// one call for all `2N` points. A model whose evaluation has a per-call cost
/// returns this from [`MeasurementModel::jacobian`] (the EKF and the untriggered
/// steps' gain use the Jacobian).
///
/// ```
/// use edccif_core::model::{measurement_jacobian_batched, MeasurementModel};
/// use edccif_core::models::RangeBearing;
/// use nalgebra::{SMatrix, Vector4};
/// let rb = RangeBearing::new([0.0, 0.0], 0.1, 0.01).unwrap();
/// let x = Vector4::new(3.0, 4.0, 0.0, 0.0);
/// let j: SMatrix<f64, 2, 4> = measurement_jacobian_batched(&rb, &x);
/// assert!((j - rb.jacobian(&x)).norm() < 1e-9);
/// ```
pub fn measurement_jacobian_batched<T, H, const N: usize, const M: usize>(
    sensor: &H,
    x: &SVector<T, N>,
) -> SMatrix<T, M, N>
where
    T: RealField + Copy,
    H: MeasurementModel<T, N, M> + ?Sized,
{
    let steps = difference_steps(x);
    let mut plus = PointImages::<T, M, N>::zeros();
    let mut minus = PointImages::<T, M, N>::zeros();
    sensor.measure_points(x, &steps, &mut plus, &mut minus, None);
    let two: T = c(2.0);
    let mut j = plus.z - minus.z;
    for col in 0..N {
        let h = steps[(col, col)];
        for k in 0..M {
            let d = if sensor.is_angle(k) {
                wrap_angle(j[(k, col)])
            } else {
                j[(k, col)]
            };
            j[(k, col)] = d / (two * h);
        }
    }
    j
}
