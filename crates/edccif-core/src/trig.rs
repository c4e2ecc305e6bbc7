//! Elementary angle functions: [`wrap_angle`] to `[−π, π)`, which every path
//! uses (the model traits' finite differences, residuals, circular means), and
//! inline `atan2` and `sin_cos` for the opt-in fast trigonometry
//! ([`MeasurementModel::fast_trig`](crate::MeasurementModel::fast_trig),
//! [`CoordinatedTurn::with_fast_trig`](crate::models::CoordinatedTurn::with_fast_trig)):
//! a few ulp from the platform's libm in `f64`, in a few dozen instructions
//! (glibc's take 135–145 per `atan2`, 86–97 per `sin_cos` in the filters'
//! steps), with no table, no libm call and no `unsafe`.
//!
//! The default paths keep the library's (`RealField`'s) `atan2` and `sin_cos`;
//! only models that opt into fast trigonometry use these.
//!
//! Sources of the equations and coefficients:
//!
//! - [`atan2`]: the argument reduction and the rational approximation of
//!   S. L. Moshier's Cephes Math Library, `atan.c` (Release 2.8, 2000):
//!   reduction of `t = |y/x|` at `tan(3π/8) = 1 + √2` (to `−1/t`, adding `π/2`)
//!   and at `0.66` (to `(t − 1)/(t + 1)`, adding `π/4`), then
//!   `atan(t) ≈ t + t·z·P(z)/Q(z)`, `z = t²`, `P` of degree 4 and `Q` of degree 5
//!   (monic), with the low part of `π/2` (`MOREBITS = 6.123233995736765886130e-17`)
//!   added back. Cephes states a relative error of 1.8e-16 (IEEE double, ±10)
//!   for `atan`. Here the reduction works on `(|y|, |x|)` directly (no rounded
//!   quotient `y/x` and no `1/(y/x)`), and the quadrant, signed zeros,
//!   infinities and NaN follow C99 Annex F / IEEE 754 `atan2`.
//! - [`sin_cos`]: Cody–Waite reduction by `π/2` with the three-part `π/2` of
//!   Sun's fdlibm `e_rem_pio2.c` (`pio2_1`, `pio2_2`: 33 leading bits each,
//!   so `n·pio2_1` and `n·pio2_2` are exact for `|n| < 2²⁰`; `pio2_2t`: the
//!   next 53 bits), and the minimax polynomials of fdlibm `k_sin.c`
//!   (`S1..S6`, error below `2^-58` on `[−π/4, π/4]`) and `k_cos.c` (`C1..C6`,
//!   below `2^-58`), in the form of FreeBSD/musl's `__cos` that keeps
//!   `1 − z/2` accurate. Arguments with `|x| > 10⁶` and non-finite arguments
//!   go to the library's `sin_cos` (they never occur on the fast paths: the
//!   turn models take `sin_cos(ω·dt)`).
//!
//! Accuracy measured in `f64` against the platform libm (glibc) on 10⁶ seeded
//! points per range by `tests/suite/trig.rs`: see there and `docs/performance.md`.
//! The coefficients are `f64` literals; another `T` evaluates the same
//! expressions in its own precision.

// The constants are written digit for digit as their sources publish them, so
// that they can be checked against those sources (each rounds to the `f64`
// the source's own code uses).
#![allow(clippy::excessive_precision)]

use nalgebra::RealField;

use crate::linalg::c;

/// Wraps an angle to `[−π, π)`.
///
/// ```
/// use edccif_core::angles::wrap_angle;
/// use core::f64::consts::PI;
/// assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
/// assert_eq!(wrap_angle(PI), -PI);
/// ```
#[inline]
pub fn wrap_angle<T: RealField + Copy>(a: T) -> T {
    // Already inside: `(a + π)/2π` lies in (0.02, 0.98), whose floor is 0, so the
    // general formula below would return `a − 0 = a` exactly.
    if a.abs() < c(3.0) {
        return a;
    }
    let two_pi = T::two_pi();
    let w = a - two_pi * ((a + T::pi()) / two_pi).floor();
    // Guard against rounding at the upper edge.
    if w >= T::pi() {
        w - two_pi
    } else {
        w
    }
}

/// `tan(3π/8) = 1 + √2`, Cephes' `T3P8`.
const T3P8: f64 = 2.414_213_562_373_095_048_80;
/// The low part of `π/2`: `π/2 − (π/2 rounded to f64)`, Cephes' `MOREBITS`.
const MOREBITS: f64 = 6.123_233_995_736_765_886_130e-17;
/// `π/2` rounded to `f64`.
const PIO2: f64 = core::f64::consts::FRAC_PI_2;
/// `π/4` rounded to `f64`.
const PIO4: f64 = core::f64::consts::FRAC_PI_4;
/// `π` rounded to `f64`; its low part is `2·MOREBITS`.
const PI: f64 = core::f64::consts::PI;

/// Cephes `atan.c` `P[0..5]` (highest degree first).
const ATAN_P: [f64; 5] = [
    -8.750_608_600_031_904_122_785e-1,
    -1.615_753_718_733_365_076_637e1,
    -7.500_855_792_314_704_667_340e1,
    -1.228_866_684_490_136_173_410e2,
    -6.485_021_904_942_025_371_773e1,
];
/// Cephes `atan.c` `Q[0..5]` (highest degree first, leading `1` implied).
const ATAN_Q: [f64; 5] = [
    2.485_846_490_142_306_297_962e1,
    1.650_270_098_316_988_542_046e2,
    4.328_810_604_912_902_668_951e2,
    4.853_903_996_359_136_964_868e2,
    1.945_506_571_482_613_964_425e2,
];

/// `atan(ay/ax) ∈ [0, π/2]` for `ay > 0`, `ax ≥ 0` (not both infinite, no NaN),
/// as `base + tail` with `base ∈ {0, π/4, π/2}` (rounded to `T`) and a small
/// `tail` that carries the low part of `base`.
#[inline(always)]
fn atan_first_quadrant<T: RealField + Copy>(ay: T, ax: T) -> (T, T) {
    let (t, base, low) = if ay > ax * c(T3P8) {
        // atan(t) = π/2 − atan(1/t) = π/2 + atan(−ax/ay)
        (-(ax / ay), c::<T>(PIO2), c::<T>(MOREBITS))
    } else if ay <= ax * c(0.66) {
        (ay / ax, T::zero(), T::zero())
    } else {
        // atan(t) = π/4 + atan((t − 1)/(t + 1)); halve large operands so that
        // ay + ax cannot overflow (both > 0.66 there, so halving is exact).
        let (a, b) = if ax > T::one() {
            (ay * c(0.5), ax * c(0.5))
        } else {
            (ay, ax)
        };
        ((a - b) / (a + b), c::<T>(PIO4), c::<T>(0.5 * MOREBITS))
    };
    let z = t * t;
    let mut p: T = c(ATAN_P[0]);
    for k in ATAN_P.iter().skip(1) {
        p = p * z + c(*k);
    }
    let mut q: T = z + c(ATAN_Q[0]);
    for k in ATAN_Q.iter().skip(1) {
        q = q * z + c(*k);
    }
    (base, (t * (z * p / q) + low) + t)
}

/// The four-quadrant arctangent of `y/x` in `[−π, π]`, as the library's
/// `y.atan2(x)` to a few ulp in `f64` (measured at most 1 ulp, see the
/// module's documentation), with the same special cases: `atan2(±0, +0) = ±0`,
/// `atan2(±0, −0) = ±π`, `atan2(±y, ±∞)` and `atan2(±∞, x)` as C99 Annex F,
/// NaN in gives NaN out. The opt-in fast trigonometry's angle measurements and
/// circular means use it.
///
/// ```
/// use edccif_core::trig::atan2;
/// use core::f64::consts::PI;
/// for (y, x) in [(1.0f64, 2.0f64), (-3.0, -0.5), (1e-300, -1e300), (5.0, 0.0)] {
///     assert!((atan2(y, x) - y.atan2(x)).abs() <= 4.0 * f64::EPSILON * PI);
/// }
/// assert_eq!(atan2(0.0f64, -0.0), PI);
/// assert_eq!(atan2(-0.0f64, 0.0).to_bits(), (-0.0f64).to_bits());
/// assert!(atan2(f64::NAN, 1.0).is_nan());
/// ```
#[inline]
// `v != v` is true for NaN only, `v − v ≠ 0` for NaN and ±∞ only.
#[allow(clippy::eq_op)]
pub fn atan2<T: RealField + Copy>(y: T, x: T) -> T {
    if x != x || y != y {
        return x + y;
    }
    let (ax, ay) = (x.abs(), y.abs());
    let (base, tail) = if ay == T::zero() {
        (T::zero(), T::zero())
    } else if ax - ax != T::zero() && ay - ay != T::zero() {
        (c(PIO4), T::zero()) // both infinite
    } else {
        atan_first_quadrant(ay, ax)
    };
    // x < 0 or x = −0: the mirror image π − atan(ay/ax), π's low part
    // (2·MOREBITS) added back; π − base is exact for base ∈ {0, π/2}.
    let r = if x.is_sign_negative() {
        (c::<T>(PI) - base) + (c::<T>(2.0 * MOREBITS) - tail)
    } else {
        base + tail
    };
    r.copysign(y)
}

/// fdlibm `e_rem_pio2.c`: the first 33 bits of `π/2`.
const PIO2_1: f64 = 1.570_796_326_734_125_614_17e0;
/// fdlibm: the next 33 bits of `π/2`.
const PIO2_2: f64 = 6.077_100_506_303_965_976_60e-11;
/// fdlibm: `π/2 − (PIO2_1 + PIO2_2)`.
const PIO2_2T: f64 = 2.022_266_248_795_950_631_54e-21;
/// `2/π`.
const INV_PIO2: f64 = core::f64::consts::FRAC_2_PI;

/// fdlibm `k_sin.c` `S1..S6`.
const SIN_S: [f64; 6] = [
    -1.666_666_666_666_663_243_48e-1,
    8.333_333_333_322_489_461_24e-3,
    -1.984_126_982_985_794_931_34e-4,
    2.755_731_370_707_006_767_89e-6,
    -2.505_076_025_340_686_341_95e-8,
    1.589_690_995_211_550_102_21e-10,
];
/// fdlibm `k_cos.c` `C1..C6`.
const COS_C: [f64; 6] = [
    4.166_666_666_666_660_190_37e-2,
    -1.388_888_888_887_410_957_49e-3,
    2.480_158_728_947_672_941_78e-5,
    -2.755_731_435_139_066_330_35e-7,
    2.087_572_321_298_174_827_90e-9,
    -1.135_964_755_778_819_482_65e-11,
];

/// `(sin r, cos r)` for `|r| ≤ π/4` (fdlibm's kernels without the tail).
#[inline(always)]
fn sin_cos_kernel<T: RealField + Copy>(r: T) -> (T, T) {
    let z = r * r;
    let mut s: T = c(SIN_S[5]);
    for k in SIN_S[1..5].iter().rev() {
        s = s * z + c(*k);
    }
    let mut co: T = c(COS_C[5]);
    for k in COS_C[..5].iter().rev() {
        co = co * z + c(*k);
    }
    let v = z * r;
    let sin = r + v * (c::<T>(SIN_S[0]) + z * s);
    // cos r = 1 − z/2 + z²·C(z), with the rounding of 1 − z/2 recovered.
    let hz = z * c(0.5);
    let w = T::one() - hz;
    let cos = w + (((T::one() - w) - hz) + z * (z * co));
    (sin, cos)
}

/// `(sin x, cos x)`, as the library's `x.sin_cos()` to a few ulp in `f64`
/// (measured at most 2 ulp for `|x| ≤ 10⁶`, see the module's documentation):
/// Cody–Waite reduction by `π/2` and fdlibm's polynomials. `sin(±0) = ±0`;
/// `|x| > 10⁶`, `±∞` and NaN go to the library's `sin_cos`. The turn models'
/// opt-in fast trigonometry uses it.
///
/// ```
/// use edccif_core::trig::sin_cos;
/// for x in [0.3f64, -2.0, 100.0, 1e-9] {
///     let ((s, c), (s0, c0)) = (sin_cos(x), x.sin_cos());
///     assert!((s - s0).abs() <= 2.0 * f64::EPSILON && (c - c0).abs() <= 2.0 * f64::EPSILON);
/// }
/// assert_eq!(sin_cos(-0.0f64).0.to_bits(), (-0.0f64).to_bits());
/// ```
#[inline]
pub fn sin_cos<T: RealField + Copy>(x: T) -> (T, T) {
    if !(x.abs() <= c(1.0e6)) {
        return x.sin_cos(); // large, infinite or NaN
    }
    if x.abs() <= c(PIO4) {
        if x == T::zero() {
            return (x, T::one()); // keeps the sign of zero
        }
        return sin_cos_kernel(x);
    }
    // n = round(x·2/π) by the shifter 1.5/ε (1.5·2⁵² for f64): exact for
    // |x·2/π| < 2⁵¹, ties to even.
    let shift = c::<T>(1.5) / T::default_epsilon();
    let n = (x * c(INV_PIO2) + shift) - shift;
    let r = ((x - n * c(PIO2_1)) - n * c(PIO2_2)) - n * c(PIO2_2T);
    let (s, co) = sin_cos_kernel(r);
    let q = nalgebra::convert_unchecked::<T, f64>(n) as i64 & 3;
    match q {
        0 => (s, co),
        1 => (co, -s),
        2 => (-s, -co),
        _ => (-co, s),
    }
}

/// [`atan2`] when `fast`, the library's `y.atan2(x)` otherwise: the one switch
/// the models with opt-in fast trigonometry go through. The kernel is called
/// out of line here, so that the default path around the switch keeps its
/// inlining (inlined, the kernel's body changes the inlining of the callers'
/// default path and adds instructions to it).
#[inline]
pub(crate) fn atan2_if<T: RealField + Copy>(fast: bool, y: T, x: T) -> T {
    if fast {
        atan2_outlined(y, x)
    } else {
        y.atan2(x)
    }
}

/// [`sin_cos`] when `fast`, the library's `x.sin_cos()` otherwise (the kernel
/// out of line, as in [`atan2_if`]).
#[inline]
pub(crate) fn sin_cos_if<T: RealField + Copy>(fast: bool, x: T) -> (T, T) {
    if fast {
        sin_cos_outlined(x)
    } else {
        x.sin_cos()
    }
}

#[inline(never)]
fn atan2_outlined<T: RealField + Copy>(y: T, x: T) -> T {
    atan2(y, x)
}

#[inline(never)]
fn sin_cos_outlined<T: RealField + Copy>(x: T) -> (T, T) {
    sin_cos(x)
}
