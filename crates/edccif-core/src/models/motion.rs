//! Motion models of the catalogue.

use nalgebra::{RealField, SMatrix, SVector};

use super::undefined::{nan_matrix, nan_vector};
use crate::error::Result;
use crate::linalg::{c, validate_positive};
use crate::model::{transition_points_each, MotionModel};
use crate::trig::{sin_cos, sin_cos_if};

/// State dimension of [`CoordinatedTurn`]: `[px, py, pz, vx, vy, vz, ω]`.
pub const CT_DIM: usize = 7;

/// State dimension of [`CoordinatedTurn2`]: `[x, y, vx, vy, ω]`.
pub const CT2_DIM: usize = 5;

/// The piecewise white-acceleration block `q·[[dt³/3, dt²/2], [dt²/2, dt]]` placed on
/// axes `(p, v)` of `m`.
fn add_cv_block<T: RealField + Copy, const N: usize>(
    m: &mut SMatrix<T, N, N>,
    p: usize,
    v: usize,
    q: T,
    dt: T,
) {
    let dt2 = dt * dt;
    m[(p, p)] = q * dt2 * dt / c(3.0);
    m[(p, v)] = q * dt2 / c(2.0);
    m[(v, p)] = m[(p, v)];
    m[(v, v)] = q * dt;
}

/// `(S, C, dS/dω, dC/dω)` of the coordinated turn with the small-|ω| branch of
/// `docs/algorithm.md` §1, given `(sin ωdt, cos ωdt)` (computed once per call by the
/// callers).
#[inline]
fn turn_terms<T: RealField + Copy>(w: T, dt: T, sn: T, co: T) -> (T, T, T, T) {
    if w.abs() < c(1e-9) {
        (dt, w * dt * dt / c(2.0), T::zero(), dt * dt / c(2.0))
    } else {
        let sf = sn / w;
        let cf = (T::one() - co) / w;
        let ds = (dt * co * w - sn) / (w * w);
        let dc = (dt * sn * w - (T::one() - co)) / (w * w);
        (sf, cf, ds, dc)
    }
}

/// The planar turn of `(x, y, vx, vy)` at indices `(px, py, vx, vy)` of `out`, from
/// the same entries of `x`, with turn rate `w` (`sin_cos` by the kernel
/// [`crate::trig::sin_cos`] when `fast`).
#[inline]
fn turn_plane<T: RealField + Copy, const N: usize>(
    x: &SVector<T, N>,
    out: &mut SVector<T, N>,
    idx: (usize, usize, usize, usize),
    w: T,
    dt: T,
    fast: bool,
) {
    let (sn, cs) = sin_cos_if(fast, w * dt);
    turn_plane_trig(x, out, idx, w, dt, (sn, cs));
}

/// [`turn_plane`] given `(sin w dt, cos w dt)`.
#[inline]
fn turn_plane_trig<T: RealField + Copy, const N: usize>(
    x: &SVector<T, N>,
    out: &mut SVector<T, N>,
    (px, py, ivx, ivy): (usize, usize, usize, usize),
    w: T,
    dt: T,
    (sn, cs): (T, T),
) {
    let (s, cc, _, _) = turn_terms(w, dt, sn, cs);
    turn_plane_terms(x, out, (px, py, ivx, ivy), (sn, cs), (s, cc));
}

/// [`turn_plane_trig`] given also its turn terms `(sin w dt / w, (1 − cos w dt) / w)`
/// (the first two of [`turn_terms`]).
#[inline(always)]
fn turn_plane_terms<T: RealField + Copy, const N: usize>(
    x: &SVector<T, N>,
    out: &mut SVector<T, N>,
    (px, py, ivx, ivy): (usize, usize, usize, usize),
    (sn, cs): (T, T),
    (s, cc): (T, T),
) {
    let (vx, vy) = (x[ivx], x[ivy]);
    out[px] = x[px] + s * vx - cc * vy;
    out[py] = x[py] + cc * vx + s * vy;
    out[ivx] = cs * vx - sn * vy;
    out[ivy] = sn * vx + cs * vy;
}

/// `∂(planar turn)/∂x` written into `f` (which holds the identity on these rows),
/// given `(sin ω dt, cos ω dt)` of the turn rate `ω = x[iw]`.
#[inline]
fn turn_plane_jacobian<T: RealField + Copy, const N: usize>(
    x: &SVector<T, N>,
    f: &mut SMatrix<T, N, N>,
    (px, py, ivx, ivy, iw): (usize, usize, usize, usize, usize),
    dt: T,
    (sn, cs): (T, T),
) {
    let w = x[iw];
    let (s, cc, ds, dc) = turn_terms(w, dt, sn, cs);
    let (vx, vy) = (x[ivx], x[ivy]);
    f[(px, ivx)] = s;
    f[(px, ivy)] = -cc;
    f[(px, iw)] = ds * vx - dc * vy;
    f[(py, ivx)] = cc;
    f[(py, ivy)] = s;
    f[(py, iw)] = dc * vx + ds * vy;
    f[(ivx, ivx)] = cs;
    f[(ivx, ivy)] = -sn;
    f[(ivx, iw)] = dt * (-sn * vx - cs * vy);
    f[(ivy, ivx)] = sn;
    f[(ivy, ivy)] = cs;
    f[(ivy, iw)] = dt * (cs * vx - sn * vy);
}

/// `(sin θ, cos θ)` for `|θ| ≤ 1/8` from their Taylor series (to `θ¹¹` and
/// `θ¹⁰`; the next terms are below `3e-20`), the kernel [`crate::trig::sin_cos`]
/// otherwise.
#[inline]
fn sin_cos_small<T: RealField + Copy>(t: T) -> (T, T) {
    if !(t.abs() <= c(0.125)) {
        return sin_cos(t);
    }
    let t2 = t * t;
    let mut s: T = c(-1.0 / 39_916_800.0); // −1/11!
    let mut co: T = c(-1.0 / 3_628_800.0); // −1/10!
    for (fs, fc) in [
        (1.0 / 362_880.0, 1.0 / 40_320.0),
        (-1.0 / 5_040.0, -1.0 / 720.0),
        (1.0 / 120.0, 1.0 / 24.0),
        (-1.0 / 6.0, -1.0 / 2.0),
        (1.0, 1.0),
    ] {
        s = c::<T>(fs) + t2 * s;
        co = c::<T>(fc) + t2 * co;
    }
    (t * s, co)
}

/// The sigma points of a turn model with opt-in fast trigonometry:
/// `sin_cos(ω dt)` once at the centre's `ω` (by the kernel
/// [`crate::trig::sin_cos`]) and, per column, of the offset's
/// `a dt` (small: a short series, [`sin_cos_small`]), combined by the
/// angle-addition formulas for `ω ± a`, instead of one `sin_cos` per point.
/// `apply(x, (sin, cos), terms)` is the model's transition given the
/// trigonometry of its point's `ω dt` and its turn terms (the first two of
/// [`turn_terms`]).
///
/// The trigonometry and the turn terms of all points come first, then the
/// transitions: each point's terms end in two divisions by its `ω`, and the
/// points' divisions, independent of each other, then overlap instead of each
/// waiting in its point's chain. The same operations on the same values as
/// point by point.
#[inline]
#[allow(clippy::too_many_arguments)]
fn turn_points<T: RealField + Copy, const N: usize>(
    x: &SVector<T, N>,
    offsets: &SMatrix<T, N, N>,
    dt: T,
    iw: usize,
    plus: &mut SMatrix<T, N, N>,
    minus: &mut SMatrix<T, N, N>,
    centre: Option<&mut SVector<T, N>>,
    apply: impl Fn(&SVector<T, N>, (T, T), (T, T)) -> SVector<T, N>,
) {
    let (s0, c0) = sin_cos(x[iw] * dt);
    let zero = (T::zero(), T::zero());
    // Per column: the `+` point's and the `−` point's (trigonometry, terms).
    let mut pre = [[(zero, zero); 2]; N];
    for (j, pj) in pre.iter_mut().enumerate() {
        let a = offsets[(iw, j)];
        let (sa, ca) = sin_cos_small(a * dt);
        let (u, v) = (s0 * ca, c0 * sa);
        let (p, q) = (c0 * ca, s0 * sa);
        // `ω` of the points `x ± col`: `(x ± col)[iw]`.
        for (pk, (w, trig)) in pj
            .iter_mut()
            .zip([(x[iw] + a, (u + v, p - q)), (x[iw] - a, (u - v, p + q))])
        {
            let (sf, cf, _, _) = turn_terms(w, dt, trig.0, trig.1);
            *pk = (trig, (sf, cf));
        }
    }
    for (j, pj) in pre.iter().enumerate() {
        let col = offsets.column(j);
        plus.set_column(j, &apply(&(x + col), pj[0].0, pj[0].1));
        minus.set_column(j, &apply(&(x - col), pj[1].0, pj[1].1));
    }
    if let Some(c) = centre {
        let (sf, cf, _, _) = turn_terms(x[iw], dt, s0, c0);
        *c = apply(x, (s0, c0), (sf, cf));
    }
}

/// The coordinated turn of `x` given `(sin ω dt, cos ω dt)` and its turn terms.
#[inline]
fn ct_apply<T: RealField + Copy>(
    x: &SVector<T, CT_DIM>,
    dt: T,
    trig: (T, T),
    terms: (T, T),
) -> SVector<T, CT_DIM> {
    let mut y = SVector::<T, CT_DIM>::zeros();
    turn_plane_terms(x, &mut y, (0, 1, 3, 4), trig, terms);
    y[2] = x[2] + dt * x[5];
    y[5] = x[5];
    y[6] = x[6];
    y
}

/// The planar coordinated turn of `x` given `(sin ω dt, cos ω dt)` and its turn
/// terms.
#[inline]
fn ct2_apply<T: RealField + Copy>(
    x: &SVector<T, CT2_DIM>,
    trig: (T, T),
    terms: (T, T),
) -> SVector<T, CT2_DIM> {
    let mut y = SVector::<T, CT2_DIM>::zeros();
    turn_plane_terms(x, &mut y, (0, 1, 2, 3), trig, terms);
    y[4] = x[4];
    y
}

/// Coordinated turn in the xy plane with constant climb rate (`docs/algorithm.md` §1).
///
/// State `x = [px, py, pz, vx, vy, vz, ω]` (`N = 7`); the turn rate `ω` is a
/// random walk.
///
/// ```
/// use edccif_core::{models::CoordinatedTurn, model::MotionModel};
/// use nalgebra::SVector;
/// let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
/// let x = SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]);
/// let x1 = ct.transition(&x, 0.1);
/// // speed in the plane is preserved by the turn
/// assert!(((x1[3].powi(2) + x1[4].powi(2)).sqrt() - 1.5).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CoordinatedTurn<T: RealField + Copy> {
    q1: T,
    q2: T,
    /// Fast trigonometry of the sigma-point prediction (default on).
    #[cfg_attr(feature = "serde", serde(default = "super::yes"))]
    fast_trig: bool,
}

impl<T: RealField + Copy> CoordinatedTurn<T> {
    /// Builds the model; `q1 ≥ 0`, `q2 ≥ 0`, both finite. The time step is given
    /// at each call ([`MotionModel::transition`]).
    ///
    /// ```
    /// use edccif_core::{models::CoordinatedTurn, Error};
    /// assert!(CoordinatedTurn::new(0.5, 1e-4).is_ok());
    /// assert!(matches!(CoordinatedTurn::new(-1.0, 1e-4), Err(Error::InvalidParameter { what: "q1", .. })));
    /// ```
    pub fn new(q1: T, q2: T) -> Result<Self> {
        validate_positive(q1, "q1", true)?;
        validate_positive(q2, "q2", true)?;
        Ok(Self {
            q1,
            q2,
            fast_trig: true,
        })
    }
    /// Position/velocity noise intensity `q1`.
    ///
    /// ```
    /// assert_eq!(edccif_core::models::CoordinatedTurn::new(0.5, 1e-4).unwrap().q1(), 0.5);
    /// ```
    pub fn q1(&self) -> T {
        self.q1
    }
    /// Turn-rate noise intensity `q2`.
    ///
    /// ```
    /// assert_eq!(edccif_core::models::CoordinatedTurn::new(0.5, 1e-4).unwrap().q2(), 1e-4);
    /// ```
    pub fn q2(&self) -> T {
        self.q2
    }
    /// The same model with fast trigonometry switched on (the default) or off
    /// (off: the platform libm's `sin_cos`, the bit-exact reference path). When on, every `sin_cos(ω dt)` of the model
    /// is the kernel [`crate::trig::sin_cos`] (within 2 ulp of the
    /// library's, no libm call): in [`MotionModel::transition`], the Jacobian and
    /// [`MotionModel::transition_with_jacobian`] (the EKF), and in the
    /// sigma-point prediction ([`MotionModel::transition_points`]), which takes
    /// one `sin_cos` per call, at the centre's turn rate, and reaches every
    /// point's `sin`/`cos` of `ω dt` by angle addition with a short series for
    /// the offset (`|a dt| ≤ 1/8`; the kernel otherwise). The results then
    /// differ from the reference path in the last bits (see `docs/guide.md` §7
    /// and `docs/performance.md`, "Fast trigonometry").
    ///
    /// ```
    /// use edccif_core::{model::MotionModel, models::CoordinatedTurn};
    /// use nalgebra::{SMatrix, SVector};
    /// assert!(CoordinatedTurn::new(0.5, 1e-4)?.fast_trig()); // the default
    /// let ct = CoordinatedTurn::new(0.5, 1e-4)?.with_fast_trig(false);
    /// let fast = ct.with_fast_trig(true);
    /// assert!(fast.fast_trig() && !ct.fast_trig());
    /// let x = SVector::<f64, 7>::from_fn(|i, _| 0.1 + i as f64);
    /// let l = SMatrix::<f64, 7, 7>::identity() * 0.05;
    /// let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
    /// let (mut c, mut d) = (SMatrix::zeros(), SMatrix::zeros());
    /// ct.transition_points(&x, &l, 0.1, &mut a, &mut b, None);
    /// fast.transition_points(&x, &l, 0.1, &mut c, &mut d, None);
    /// assert!((a - c).abs().max() < 1e-12 && (b - d).abs().max() < 1e-12);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    #[must_use]
    pub fn with_fast_trig(mut self, on: bool) -> Self {
        self.fast_trig = on;
        self
    }
    /// Whether fast trigonometry is on ([`with_fast_trig`](Self::with_fast_trig)).
    pub fn fast_trig(&self) -> bool {
        self.fast_trig
    }
}

impl<T: RealField + Copy> MotionModel<T, CT_DIM> for CoordinatedTurn<T> {
    #[inline]
    fn transition(&self, x: &SVector<T, CT_DIM>, dt: T) -> SVector<T, CT_DIM> {
        let mut y = SVector::<T, CT_DIM>::zeros();
        turn_plane(x, &mut y, (0, 1, 3, 4), x[6], dt, self.fast_trig);
        y[2] = x[2] + dt * x[5];
        y[5] = x[5];
        y[6] = x[6];
        y
    }

    /// With fast trigonometry, one `sin_cos` per call and a short series per
    /// column ([`with_fast_trig`](Self::with_fast_trig)); otherwise
    /// [`transition`](Self::transition) point by point.
    #[inline]
    fn transition_points(
        &self,
        x: &SVector<T, CT_DIM>,
        offsets: &SMatrix<T, CT_DIM, CT_DIM>,
        dt: T,
        plus: &mut SMatrix<T, CT_DIM, CT_DIM>,
        minus: &mut SMatrix<T, CT_DIM, CT_DIM>,
        centre: Option<&mut SVector<T, CT_DIM>>,
    ) {
        if self.fast_trig {
            turn_points(x, offsets, dt, 6, plus, minus, centre, |p, trig, terms| {
                ct_apply(p, dt, trig, terms)
            });
        } else {
            transition_points_each(self, x, offsets, dt, plus, minus, centre);
        }
    }

    #[inline]
    fn process_noise(&self, dt: T) -> SMatrix<T, CT_DIM, CT_DIM> {
        let mut q = SMatrix::<T, CT_DIM, CT_DIM>::zeros();
        for a in 0..3 {
            add_cv_block(&mut q, a, a + 3, self.q1, dt);
        }
        q[(6, 6)] = self.q2 * dt;
        q
    }

    fn jacobian(&self, x: &SVector<T, CT_DIM>, dt: T) -> SMatrix<T, CT_DIM, CT_DIM> {
        ct_jacobian(x, dt, sin_cos_if(self.fast_trig, x[6] * dt))
    }

    /// One `sin_cos` for both.
    #[inline]
    fn transition_with_jacobian(
        &self,
        x: &SVector<T, CT_DIM>,
        dt: T,
    ) -> (SVector<T, CT_DIM>, SMatrix<T, CT_DIM, CT_DIM>) {
        let trig = sin_cos_if(self.fast_trig, x[6] * dt);
        let mut y = SVector::<T, CT_DIM>::zeros();
        turn_plane_trig(x, &mut y, (0, 1, 3, 4), x[6], dt, trig);
        y[2] = x[2] + dt * x[5];
        y[5] = x[5];
        y[6] = x[6];
        (y, ct_jacobian(x, dt, trig))
    }

    /// `F P Fᵀ` without the Jacobian's structural zeros (`CT_JACOBIAN_PATTERN`):
    /// 126 + 126 multiplications instead of 343 + 343, the same bits
    /// (`ct_congruence`, the unrolled form of
    /// [`congruence_sparse`](crate::linalg::congruence_sparse)).
    #[inline(always)]
    fn jacobian_congruence(
        &self,
        f: &SMatrix<T, CT_DIM, CT_DIM>,
        p: &SMatrix<T, CT_DIM, CT_DIM>,
    ) -> SMatrix<T, CT_DIM, CT_DIM> {
        ct_congruence(f, p)
    }
}

/// `F P Fᵀ` for an `F` that is zero outside [`CT_JACOBIAN_PATTERN`]: what
/// [`congruence_sparse`](crate::linalg::congruence_sparse)`(f, p, &CT_JACOBIAN_PATTERN)` computes, the same sums
/// in the same order (`k` ascending; `a + b + c` is `(a + b) + c`), written out
/// so that the compiler sees the whole pattern: no index lists, and the second
/// product runs down contiguous columns.
#[inline(always)]
fn ct_congruence<T: RealField + Copy>(
    f: &SMatrix<T, CT_DIM, CT_DIM>,
    p: &SMatrix<T, CT_DIM, CT_DIM>,
) -> SMatrix<T, CT_DIM, CT_DIM> {
    // F P: row i of F (its pattern) against column j of P.
    let mut fp = SMatrix::<T, CT_DIM, CT_DIM>::zeros();
    for j in 0..CT_DIM {
        let q = |k: usize| p[(k, j)];
        fp[(0, j)] = f[(0, 0)] * q(0) + f[(0, 3)] * q(3) + f[(0, 4)] * q(4) + f[(0, 6)] * q(6);
        fp[(1, j)] = f[(1, 1)] * q(1) + f[(1, 3)] * q(3) + f[(1, 4)] * q(4) + f[(1, 6)] * q(6);
        fp[(2, j)] = f[(2, 2)] * q(2) + f[(2, 5)] * q(5);
        fp[(3, j)] = f[(3, 3)] * q(3) + f[(3, 4)] * q(4) + f[(3, 6)] * q(6);
        fp[(4, j)] = f[(4, 3)] * q(3) + f[(4, 4)] * q(4) + f[(4, 6)] * q(6);
        fp[(5, j)] = f[(5, 5)] * q(5);
        fp[(6, j)] = f[(6, 6)] * q(6);
    }
    // (F P) Fᵀ: entry (i, j) is row i of F P against row j of F (its pattern).
    let mut out = SMatrix::<T, CT_DIM, CT_DIM>::zeros();
    for i in 0..CT_DIM {
        let q = |k: usize| fp[(i, k)];
        out[(i, 0)] = q(0) * f[(0, 0)] + q(3) * f[(0, 3)] + q(4) * f[(0, 4)] + q(6) * f[(0, 6)];
        out[(i, 1)] = q(1) * f[(1, 1)] + q(3) * f[(1, 3)] + q(4) * f[(1, 4)] + q(6) * f[(1, 6)];
        out[(i, 2)] = q(2) * f[(2, 2)] + q(5) * f[(2, 5)];
        out[(i, 3)] = q(3) * f[(3, 3)] + q(4) * f[(3, 4)] + q(6) * f[(3, 6)];
        out[(i, 4)] = q(3) * f[(4, 3)] + q(4) * f[(4, 4)] + q(6) * f[(4, 6)];
        out[(i, 5)] = q(5) * f[(5, 5)];
        out[(i, 6)] = q(6) * f[(6, 6)];
    }
    out
}

/// The columns of each row of [`CoordinatedTurn`]'s Jacobian that may be non-zero
/// (what `ct_jacobian` writes on top of the identity); every other entry is
/// exactly zero. [`ct_congruence`] is written out from it; the tests check the
/// Jacobian against it and both products against the general ones.
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) const CT_JACOBIAN_PATTERN: [&[usize]; CT_DIM] = [
    &[0, 3, 4, 6],
    &[1, 3, 4, 6],
    &[2, 5],
    &[3, 4, 6],
    &[3, 4, 6],
    &[5],
    &[6],
];

/// The coordinated turn's Jacobian given `(sin ω dt, cos ω dt)`.
#[inline]
fn ct_jacobian<T: RealField + Copy>(
    x: &SVector<T, CT_DIM>,
    dt: T,
    trig: (T, T),
) -> SMatrix<T, CT_DIM, CT_DIM> {
    let mut f = SMatrix::<T, CT_DIM, CT_DIM>::identity();
    turn_plane_jacobian(x, &mut f, (0, 1, 3, 4, 6), dt, trig);
    f[(2, 5)] = dt;
    f
}

/// Coordinated turn in the plane, state `x = [x, y, vx, vy, ω]` (`N = 5`), the
/// turn rate a random walk: the planar part of [`CoordinatedTurn`] with the same
/// small-|ω| branch, white-acceleration noise `q1` on each axis and `q2·dt` on `ω`.
///
/// ```
/// use edccif_core::{models::CoordinatedTurn2, model::MotionModel};
/// use nalgebra::SVector;
/// let ct = CoordinatedTurn2::new(0.5, 1e-4).unwrap();
/// // a quarter turn at 1 rad/s takes π/2 s
/// let x = ct.transition(&SVector::<f64, 5>::from([0.0, 0.0, 1.0, 0.0, 1.0]), core::f64::consts::FRAC_PI_2);
/// assert!((x[0] - 1.0).abs() < 1e-12 && (x[1] - 1.0).abs() < 1e-12 && (x[3] - 1.0).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CoordinatedTurn2<T: RealField + Copy> {
    q1: T,
    q2: T,
    /// Fast trigonometry of the sigma-point prediction (default on).
    #[cfg_attr(feature = "serde", serde(default = "super::yes"))]
    fast_trig: bool,
}

impl<T: RealField + Copy> CoordinatedTurn2<T> {
    /// Builds the model; `q1 ≥ 0`, `q2 ≥ 0`, both finite.
    ///
    /// ```
    /// use edccif_core::{models::CoordinatedTurn2, Error};
    /// assert!(matches!(CoordinatedTurn2::new(0.5, f64::NAN), Err(Error::InvalidParameter { what: "q2", .. })));
    /// ```
    pub fn new(q1: T, q2: T) -> Result<Self> {
        validate_positive(q1, "q1", true)?;
        validate_positive(q2, "q2", true)?;
        Ok(Self {
            q1,
            q2,
            fast_trig: true,
        })
    }
    /// Position/velocity noise intensity `q1`.
    ///
    /// ```
    /// assert_eq!(edccif_core::models::CoordinatedTurn2::new(0.5, 1e-4).unwrap().q1(), 0.5);
    /// ```
    pub fn q1(&self) -> T {
        self.q1
    }
    /// Turn-rate noise intensity `q2`.
    ///
    /// ```
    /// assert_eq!(edccif_core::models::CoordinatedTurn2::new(0.5, 1e-4).unwrap().q2(), 1e-4);
    /// ```
    pub fn q2(&self) -> T {
        self.q2
    }
    /// The same model with fast trigonometry switched on (the default) or off
    /// (off: the platform libm's `sin_cos`, the bit-exact reference path). When on, every `sin_cos(ω dt)` of the model
    /// is the kernel [`crate::trig::sin_cos`] (within 2 ulp of the
    /// library's, no libm call): in [`MotionModel::transition`], the Jacobian and
    /// [`MotionModel::transition_with_jacobian`] (the EKF), and in the
    /// sigma-point prediction ([`MotionModel::transition_points`]), which takes
    /// one `sin_cos` per call, at the centre's turn rate, and reaches every
    /// point's `sin`/`cos` of `ω dt` by angle addition with a short series for
    /// the offset (`|a dt| ≤ 1/8`; the kernel otherwise). The results then
    /// differ from the reference path in the last bits (see `docs/guide.md` §7
    /// and `docs/performance.md`, "Fast trigonometry").
    ///
    /// ```
    /// use edccif_core::{model::MotionModel, models::CoordinatedTurn2};
    /// use nalgebra::{SMatrix, SVector};
    /// assert!(CoordinatedTurn2::new(0.5, 1e-4)?.fast_trig()); // the default
    /// let ct = CoordinatedTurn2::new(0.5, 1e-4)?.with_fast_trig(false);
    /// let fast = ct.with_fast_trig(true);
    /// assert!(fast.fast_trig() && !ct.fast_trig());
    /// let x = SVector::<f64, 5>::from_fn(|i, _| 0.1 + i as f64);
    /// let l = SMatrix::<f64, 5, 5>::identity() * 0.05;
    /// let (mut a, mut b) = (SMatrix::zeros(), SMatrix::zeros());
    /// let (mut c, mut d) = (SMatrix::zeros(), SMatrix::zeros());
    /// ct.transition_points(&x, &l, 0.1, &mut a, &mut b, None);
    /// fast.transition_points(&x, &l, 0.1, &mut c, &mut d, None);
    /// assert!((a - c).abs().max() < 1e-12 && (b - d).abs().max() < 1e-12);
    /// # Ok::<(), edccif_core::Error>(())
    /// ```
    #[must_use]
    pub fn with_fast_trig(mut self, on: bool) -> Self {
        self.fast_trig = on;
        self
    }
    /// Whether fast trigonometry is on ([`with_fast_trig`](Self::with_fast_trig)).
    pub fn fast_trig(&self) -> bool {
        self.fast_trig
    }
}

impl<T: RealField + Copy> MotionModel<T, CT2_DIM> for CoordinatedTurn2<T> {
    #[inline]
    fn transition(&self, x: &SVector<T, CT2_DIM>, dt: T) -> SVector<T, CT2_DIM> {
        let mut y = SVector::<T, CT2_DIM>::zeros();
        turn_plane(x, &mut y, (0, 1, 2, 3), x[4], dt, self.fast_trig);
        y[4] = x[4];
        y
    }

    /// With fast trigonometry, one `sin_cos` per call and a short series per
    /// column ([`with_fast_trig`](Self::with_fast_trig)); otherwise
    /// [`transition`](Self::transition) point by point.
    #[inline]
    fn transition_points(
        &self,
        x: &SVector<T, CT2_DIM>,
        offsets: &SMatrix<T, CT2_DIM, CT2_DIM>,
        dt: T,
        plus: &mut SMatrix<T, CT2_DIM, CT2_DIM>,
        minus: &mut SMatrix<T, CT2_DIM, CT2_DIM>,
        centre: Option<&mut SVector<T, CT2_DIM>>,
    ) {
        if self.fast_trig {
            turn_points(x, offsets, dt, 4, plus, minus, centre, |p, trig, terms| {
                ct2_apply(p, trig, terms)
            });
        } else {
            transition_points_each(self, x, offsets, dt, plus, minus, centre);
        }
    }

    #[inline]
    fn process_noise(&self, dt: T) -> SMatrix<T, CT2_DIM, CT2_DIM> {
        let mut q = SMatrix::<T, CT2_DIM, CT2_DIM>::zeros();
        for a in 0..2 {
            add_cv_block(&mut q, a, a + 2, self.q1, dt);
        }
        q[(4, 4)] = self.q2 * dt;
        q
    }

    fn jacobian(&self, x: &SVector<T, CT2_DIM>, dt: T) -> SMatrix<T, CT2_DIM, CT2_DIM> {
        let mut f = SMatrix::<T, CT2_DIM, CT2_DIM>::identity();
        turn_plane_jacobian(
            x,
            &mut f,
            (0, 1, 2, 3, 4),
            dt,
            sin_cos_if(self.fast_trig, x[4] * dt),
        );
        f
    }

    /// One `sin_cos` for both.
    #[inline]
    fn transition_with_jacobian(
        &self,
        x: &SVector<T, CT2_DIM>,
        dt: T,
    ) -> (SVector<T, CT2_DIM>, SMatrix<T, CT2_DIM, CT2_DIM>) {
        let trig = sin_cos_if(self.fast_trig, x[4] * dt);
        let mut y = SVector::<T, CT2_DIM>::zeros();
        turn_plane_trig(x, &mut y, (0, 1, 2, 3), x[4], dt, trig);
        y[4] = x[4];
        let mut f = SMatrix::<T, CT2_DIM, CT2_DIM>::identity();
        turn_plane_jacobian(x, &mut f, (0, 1, 2, 3, 4), dt, trig);
        (y, f)
    }
}

/// Constant velocity in `d` axes, state `[p(d), v(d)]` (`N = 2d`: 1-D `[x, vx]`,
/// 2-D `[x, y, vx, vy]`, 3-D `[px, py, pz, vx, vy, vz]`), white-acceleration noise
/// of intensity `q` on each axis: per axis `Q = q·[[dt³/3, dt²/2], [dt²/2, dt]]`.
/// It implements [`MotionModel`] for every `N` so that code generic over the
/// dimension can hold it; an odd `N` gives NaN, which any filter reports as
/// [`Error::NonFinite`](crate::Error::NonFinite).
///
/// ```
/// use edccif_core::{models::ConstantVelocity, model::MotionModel};
/// use nalgebra::{SVector, Vector4};
/// let cv = ConstantVelocity::new(1.0).unwrap();
/// let x = cv.transition(&SVector::<f64, 6>::from([0.0, 0.0, 0.0, 1.0, 2.0, 3.0]), 0.5);
/// assert_eq!(x[2], 1.5);
/// let x2 = cv.transition(&Vector4::new(0.0, 0.0, 1.0, 2.0), 0.5); // 2-D
/// assert_eq!(x2, Vector4::new(0.5, 1.0, 1.0, 2.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ConstantVelocity<T: RealField + Copy> {
    q: T,
}

impl<T: RealField + Copy> ConstantVelocity<T> {
    /// Builds the model; `q ≥ 0`, finite. The time step is given at each call.
    ///
    /// ```
    /// use edccif_core::{models::ConstantVelocity, Error};
    /// assert!(matches!(ConstantVelocity::new(f64::INFINITY), Err(Error::InvalidParameter { what: "q", .. })));
    /// ```
    pub fn new(q: T) -> Result<Self> {
        validate_positive(q, "q", true)?;
        Ok(Self { q })
    }
    /// White-acceleration noise intensity `q`.
    ///
    /// ```
    /// assert_eq!(edccif_core::models::ConstantVelocity::new(0.7).unwrap().q(), 0.7);
    /// ```
    pub fn q(&self) -> T {
        self.q
    }
    /// Whether the model is defined for state dimension `n` (even, `≥ 2`).
    ///
    /// ```
    /// use edccif_core::models::ConstantVelocity;
    /// assert!(ConstantVelocity::<f64>::supports(4) && !ConstantVelocity::<f64>::supports(3));
    /// ```
    pub const fn supports(n: usize) -> bool {
        n >= 2 && n.is_multiple_of(2)
    }
}

impl<T: RealField + Copy, const N: usize> MotionModel<T, N> for ConstantVelocity<T> {
    #[inline]
    fn transition(&self, x: &SVector<T, N>, dt: T) -> SVector<T, N> {
        if !Self::supports(N) {
            return nan_vector();
        }
        let d = N / 2;
        let mut y = *x;
        for a in 0..d {
            y[a] += dt * x[a + d];
        }
        y
    }
    #[inline]
    fn process_noise(&self, dt: T) -> SMatrix<T, N, N> {
        if !Self::supports(N) {
            return nan_matrix();
        }
        let d = N / 2;
        let mut m = SMatrix::<T, N, N>::zeros();
        for a in 0..d {
            add_cv_block(&mut m, a, a + d, self.q, dt);
        }
        m
    }
    fn jacobian(&self, _x: &SVector<T, N>, dt: T) -> SMatrix<T, N, N> {
        if !Self::supports(N) {
            return nan_matrix();
        }
        let d = N / 2;
        let mut f = SMatrix::<T, N, N>::identity();
        for a in 0..d {
            f[(a, a + d)] = dt;
        }
        f
    }
}

/// Constant acceleration in `d` axes, state `[p(d), v(d), a(d)]` (`N = 3d`: 3, 6
/// or 9), white-jerk noise of intensity `q` on each axis: per axis
/// `Q = q·[[dt⁵/20, dt⁴/8, dt³/6], [dt⁴/8, dt³/3, dt²/2], [dt³/6, dt²/2, dt]]`.
/// An `N` not a multiple of 3 gives NaN (see [`ConstantVelocity`]).
///
/// ```
/// use edccif_core::{models::ConstantAcceleration, model::MotionModel};
/// use nalgebra::Vector3;
/// let ca = ConstantAcceleration::new(0.1).unwrap();
/// // 1-D: p = 0 + 1·2 + 2·2²/2, v = 1 + 2·2
/// assert_eq!(ca.transition(&Vector3::new(0.0, 1.0, 2.0), 2.0), Vector3::new(6.0, 5.0, 2.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ConstantAcceleration<T: RealField + Copy> {
    q: T,
}

impl<T: RealField + Copy> ConstantAcceleration<T> {
    /// Builds the model; `q ≥ 0`, finite.
    ///
    /// ```
    /// use edccif_core::{models::ConstantAcceleration, Error};
    /// assert!(matches!(ConstantAcceleration::new(-0.1), Err(Error::InvalidParameter { what: "q", .. })));
    /// ```
    pub fn new(q: T) -> Result<Self> {
        validate_positive(q, "q", true)?;
        Ok(Self { q })
    }
    /// White-jerk noise intensity `q`.
    ///
    /// ```
    /// assert_eq!(edccif_core::models::ConstantAcceleration::new(0.1).unwrap().q(), 0.1);
    /// ```
    pub fn q(&self) -> T {
        self.q
    }
    /// Whether the model is defined for state dimension `n` (a multiple of 3, `≥ 3`).
    ///
    /// ```
    /// use edccif_core::models::ConstantAcceleration;
    /// assert!(ConstantAcceleration::<f64>::supports(9) && !ConstantAcceleration::<f64>::supports(4));
    /// ```
    pub const fn supports(n: usize) -> bool {
        n >= 3 && n.is_multiple_of(3)
    }
}

impl<T: RealField + Copy, const N: usize> MotionModel<T, N> for ConstantAcceleration<T> {
    #[inline]
    fn transition(&self, x: &SVector<T, N>, dt: T) -> SVector<T, N> {
        if !Self::supports(N) {
            return nan_vector();
        }
        let d = N / 3;
        let half_dt2 = dt * dt / c(2.0);
        let mut y = *x;
        for a in 0..d {
            y[a] += dt * x[a + d] + half_dt2 * x[a + 2 * d];
            y[a + d] += dt * x[a + 2 * d];
        }
        y
    }
    #[inline]
    fn process_noise(&self, dt: T) -> SMatrix<T, N, N> {
        if !Self::supports(N) {
            return nan_matrix();
        }
        let d = N / 3;
        let q = self.q;
        let dt2 = dt * dt;
        let dt3 = dt2 * dt;
        let block = [
            [
                q * dt3 * dt2 / c(20.0),
                q * dt2 * dt2 / c(8.0),
                q * dt3 / c(6.0),
            ],
            [q * dt2 * dt2 / c(8.0), q * dt3 / c(3.0), q * dt2 / c(2.0)],
            [q * dt3 / c(6.0), q * dt2 / c(2.0), q * dt],
        ];
        let mut m = SMatrix::<T, N, N>::zeros();
        for a in 0..d {
            for (i, row) in block.iter().enumerate() {
                for (j, v) in row.iter().enumerate() {
                    m[(a + i * d, a + j * d)] = *v;
                }
            }
        }
        m
    }
    fn jacobian(&self, _x: &SVector<T, N>, dt: T) -> SMatrix<T, N, N> {
        if !Self::supports(N) {
            return nan_matrix();
        }
        let d = N / 3;
        let mut f = SMatrix::<T, N, N>::identity();
        for a in 0..d {
            f[(a, a + d)] = dt;
            f[(a, a + 2 * d)] = dt * dt / c(2.0);
            f[(a + d, a + 2 * d)] = dt;
        }
        f
    }
}

/// Random walk in any dimension: `f(x) = x`, `Q(dt) = q·dt·I`.
///
/// ```
/// use edccif_core::{models::RandomWalk, model::MotionModel};
/// use nalgebra::{Matrix3, Vector3};
/// let rw = RandomWalk::new(0.5).unwrap();
/// let x = Vector3::new(1.0, 2.0, 3.0);
/// assert_eq!(rw.transition(&x, 0.1), x);
/// assert_eq!(MotionModel::<f64, 3>::process_noise(&rw, 2.0), Matrix3::identity());
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RandomWalk<T: RealField + Copy> {
    q: T,
}

impl<T: RealField + Copy> RandomWalk<T> {
    /// Builds the model; `q ≥ 0`, finite.
    ///
    /// ```
    /// use edccif_core::{models::RandomWalk, Error};
    /// assert!(matches!(RandomWalk::new(f64::NAN), Err(Error::InvalidParameter { what: "q", .. })));
    /// ```
    pub fn new(q: T) -> Result<Self> {
        validate_positive(q, "q", true)?;
        Ok(Self { q })
    }
    /// Noise intensity `q` (variance per unit time of each component).
    ///
    /// ```
    /// assert_eq!(edccif_core::models::RandomWalk::new(0.5).unwrap().q(), 0.5);
    /// ```
    pub fn q(&self) -> T {
        self.q
    }
}

impl<T: RealField + Copy, const N: usize> MotionModel<T, N> for RandomWalk<T> {
    #[inline]
    fn transition(&self, x: &SVector<T, N>, _dt: T) -> SVector<T, N> {
        *x
    }
    #[inline]
    fn process_noise(&self, dt: T) -> SMatrix<T, N, N> {
        SMatrix::<T, N, N>::identity() * (self.q * dt)
    }
    #[inline]
    fn jacobian(&self, _x: &SVector<T, N>, _dt: T) -> SMatrix<T, N, N> {
        SMatrix::<T, N, N>::identity()
    }
}

/// Linear motion `x' = F x + w`, `w ~ N(0, Q)`, with a fixed `F` and `Q`: one
/// step of a discrete-time model whatever `dt` is passed (useful as an oracle and
/// for models already discretised at one rate).
///
/// ```
/// use edccif_core::{models::LinearMotion, model::MotionModel};
/// use nalgebra::{Matrix2, Vector2};
/// let m = LinearMotion::new(Matrix2::new(1.0, 1.0, 0.0, 1.0), Matrix2::identity()).unwrap();
/// assert_eq!(m.transition(&Vector2::new(1.0, 2.0), 1.0), Vector2::new(3.0, 2.0));
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LinearMotion<T: RealField + Copy, const N: usize> {
    f: SMatrix<T, N, N>,
    q: SMatrix<T, N, N>,
}

impl<T: RealField + Copy, const N: usize> LinearMotion<T, N> {
    /// `F` finite, `Q` finite and symmetric.
    ///
    /// ```
    /// use edccif_core::{models::LinearMotion, Error};
    /// use nalgebra::Matrix2;
    /// let e = LinearMotion::new(Matrix2::new(1.0, f64::NAN, 0.0, 1.0), Matrix2::identity()).unwrap_err();
    /// assert_eq!(e, Error::NonFinite { what: "transition matrix F" });
    /// ```
    pub fn new(f: SMatrix<T, N, N>, q: SMatrix<T, N, N>) -> Result<Self> {
        crate::linalg::check_finite(&f, "transition matrix F")?;
        crate::linalg::check_finite(&q, "process noise Q")?;
        Ok(Self { f, q })
    }
}

impl<T: RealField + Copy, const N: usize> MotionModel<T, N> for LinearMotion<T, N> {
    #[inline]
    fn transition(&self, x: &SVector<T, N>, _dt: T) -> SVector<T, N> {
        self.f * x
    }
    #[inline]
    fn process_noise(&self, _dt: T) -> SMatrix<T, N, N> {
        self.q
    }
    #[inline]
    fn jacobian(&self, _x: &SVector<T, N>, _dt: T) -> SMatrix<T, N, N> {
        self.f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `turn_points` as it was written point by point (each point's turn terms
    /// formed inside its own transition): the reference for the batched form.
    fn turn_points_each<const N: usize>(
        x: &SVector<f64, N>,
        offsets: &SMatrix<f64, N, N>,
        dt: f64,
        iw: usize,
        apply: impl Fn(&SVector<f64, N>, (f64, f64)) -> SVector<f64, N>,
    ) -> (SMatrix<f64, N, N>, SMatrix<f64, N, N>, SVector<f64, N>) {
        let (mut plus, mut minus) = (SMatrix::<f64, N, N>::zeros(), SMatrix::<f64, N, N>::zeros());
        let (s0, c0) = sin_cos(x[iw] * dt);
        for j in 0..N {
            let col = offsets.column(j);
            let (sa, ca) = sin_cos_small(col[iw] * dt);
            let (u, v) = (s0 * ca, c0 * sa);
            let (p, q) = (c0 * ca, s0 * sa);
            plus.set_column(j, &apply(&(x + col), (u + v, p - q)));
            minus.set_column(j, &apply(&(x - col), (u - v, p + q)));
        }
        (plus, minus, apply(x, (s0, c0)))
    }

    fn same_bits<const R: usize, const C: usize>(
        a: &SMatrix<f64, R, C>,
        b: &SMatrix<f64, R, C>,
    ) -> bool {
        a.iter()
            .zip(b.iter())
            .all(|(u, v)| u.to_bits() == v.to_bits())
    }

    /// The batched `turn_points` (every point's terms first) gives the point-by-
    /// point form's bits, for both turn models, on lower-triangular offsets with
    /// turn rates on both sides of the `|ω| < 1e-9` branch, offsets past the
    /// short series' `1/8`, and exact zeros.
    #[test]
    fn turn_points_equal_the_point_by_point_form_bit_for_bit() {
        let mut seed = 0x5eed_u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for case in 0..2000 {
            let scale = [1e-12, 1e-3, 0.1, 1.0, 30.0][case % 5];
            let w = [0.0, 1e-10, -0.4, 0.9, 5e-10][case % 4 + usize::from(case % 7 == 0)];
            let dt = [0.1, 0.05, 1.0][case % 3];
            let x7 = SVector::<f64, 7>::from_fn(|i, _| if i == 6 { w } else { 10.0 * next() });
            let off7 =
                SMatrix::<f64, 7, 7>::from_fn(|i, j| match (i >= j, case % 11 == 0 && i == 6) {
                    (false, _) | (_, true) => 0.0,
                    _ => scale * next(),
                });
            let ref7 = turn_points_each(&x7, &off7, dt, 6, |p, trig| {
                let mut y = SVector::<f64, 7>::zeros();
                turn_plane_trig(p, &mut y, (0, 1, 3, 4), p[6], dt, trig);
                y[2] = p[2] + dt * p[5];
                y[5] = p[5];
                y[6] = p[6];
                y
            });
            let (mut plus, mut minus, mut centre) =
                (SMatrix::zeros(), SMatrix::zeros(), SVector::zeros());
            turn_points(
                &x7,
                &off7,
                dt,
                6,
                &mut plus,
                &mut minus,
                Some(&mut centre),
                |p, t, f| ct_apply(p, dt, t, f),
            );
            assert!(same_bits(&plus, &ref7.0), "CT plus, case {case}");
            assert!(same_bits(&minus, &ref7.1), "CT minus, case {case}");
            assert!(same_bits(&centre, &ref7.2), "CT centre, case {case}");

            let x5 = SVector::<f64, 5>::from_fn(|i, _| if i == 4 { w } else { 10.0 * next() });
            let off5 =
                SMatrix::<f64, 5, 5>::from_fn(|i, j| if i >= j { scale * next() } else { 0.0 });
            let ref5 = turn_points_each(&x5, &off5, dt, 4, |p, trig| {
                let mut y = SVector::<f64, 5>::zeros();
                turn_plane_trig(p, &mut y, (0, 1, 2, 3), p[4], dt, trig);
                y[4] = p[4];
                y
            });
            let (mut plus, mut minus, mut centre) =
                (SMatrix::zeros(), SMatrix::zeros(), SVector::zeros());
            turn_points(
                &x5,
                &off5,
                dt,
                4,
                &mut plus,
                &mut minus,
                Some(&mut centre),
                ct2_apply,
            );
            assert!(same_bits(&plus, &ref5.0), "CT2 plus, case {case}");
            assert!(same_bits(&minus, &ref5.1), "CT2 minus, case {case}");
            assert!(same_bits(&centre, &ref5.2), "CT2 centre, case {case}");
        }
    }

    /// The pattern covers every entry the Jacobian can make non-zero, on both
    /// branches of the turn (|ω| below and above 1e-9), so leaving the others out
    /// of `F P Fᵀ` is exact.
    #[test]
    fn ct_jacobian_is_zero_outside_its_pattern() {
        let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
        for (k, w) in [0.0, 1e-12, -0.3, 0.7, 2.5].into_iter().enumerate() {
            let v = k as f64;
            let x = SVector::<f64, 7>::from([1.0 + v, -2.0, 0.5, 1.5 - v, 0.3 + v, -0.2, w]);
            let f = ct.jacobian(&x, 0.1);
            for i in 0..CT_DIM {
                for j in 0..CT_DIM {
                    if !CT_JACOBIAN_PATTERN[i].contains(&j) {
                        assert_eq!(f[(i, j)], 0.0, "F[{i},{j}] at ω = {w}");
                    }
                }
            }
            let p = SMatrix::<f64, 7, 7>::from_fn(|i, j| {
                if i == j {
                    2.0 + v
                } else {
                    0.1 * (i as f64 - j as f64).cos()
                }
            });
            assert_eq!(ct.jacobian_congruence(&f, &p), f * p * f.transpose());
        }
    }

    /// The unrolled `F P Fᵀ` equals the general products and `congruence_sparse`
    /// on 400 seeded pairs: the model's own Jacobians (both branches of the
    /// turn) and random `F` zeroed outside the pattern, against random finite `P`.
    #[test]
    fn ct_congruence_matches_the_general_products_bit_for_bit() {
        let ct = CoordinatedTurn::new(0.5, 1e-4).unwrap();
        let mut seed = 5u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
            u * 10f64.powi((seed % 7) as i32 - 3)
        };
        for round in 0..400u32 {
            let f = if round.is_multiple_of(2) {
                let mut x = SVector::<f64, 7>::from_fn(|_, _| next() * 10.0);
                if round.is_multiple_of(4) {
                    x[6] = 1e-12 * next(); // the small-|ω| branch
                }
                ct.jacobian(&x, 0.05 + next().abs())
            } else {
                let mut f = SMatrix::<f64, 7, 7>::from_fn(|_, _| next());
                for i in 0..7 {
                    for k in 0..7 {
                        if !CT_JACOBIAN_PATTERN[i].contains(&k) {
                            f[(i, k)] = 0.0;
                        }
                    }
                }
                f
            };
            let p = SMatrix::<f64, 7, 7>::from_fn(|_, _| next());
            let want = f * p * f.transpose();
            assert_eq!(ct.jacobian_congruence(&f, &p), want, "round {round}");
            assert_eq!(
                crate::linalg::congruence_sparse(&f, &p, &CT_JACOBIAN_PATTERN),
                want
            );
        }
    }
}
