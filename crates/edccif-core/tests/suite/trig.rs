//! The fast trigonometry kernel (`edccif_core::trig`) against the platform
//! libm's `atan2` and `sin_cos` (std's `f64` methods): a seeded sweep of
//! [`SWEEP`] = 10⁷ arguments per function (split over the ranges below; for
//! `sin_cos` both outputs are compared), plus every special case of `atan2`
//! (signed zeros, infinities, NaN) and of `sin_cos`.
//!
//! Asserted bounds (the worst case over the sweep): `atan2` within 2 ulp of
//! the libm (and 1e-15 absolute) over magnitudes 1e-300 to 1e300 in all four
//! quadrants; `sin_cos` within 3 ulp (and 3e-16 absolute) for `|x| ≤ 10⁶`.
//! Measured against x86-64 glibc 2.36: see `docs/performance.md`, "Fast
//! trigonometry"; the printout (`-- --nocapture`) gives each range. The
//! core's tests build with `opt-level = 2`, so the sweep takes about a second.

use edccif_core::trig::{atan2, sin_cos};

/// xorshift64*: reproducible, no dependency.
fn next(state: &mut u64) -> f64 {
    *state ^= *state >> 12;
    *state ^= *state << 25;
    *state ^= *state >> 27;
    let v = state.wrapping_mul(0x2545_f491_4f6c_dd1d);
    (v >> 11) as f64 / (1u64 << 53) as f64
}

/// Distance in units in the last place (the number of doubles between `a` and
/// `b`, across zero too).
fn ulps(a: f64, b: f64) -> u64 {
    fn key(v: f64) -> i64 {
        let bits = v.to_bits() as i64;
        if bits < 0 {
            i64::MIN - bits
        } else {
            bits
        }
    }
    key(a).abs_diff(key(b))
}

/// Worst (ulp, absolute) difference of `f` from `g` over `points`.
fn worst(
    points: impl Iterator<Item = (f64, f64)>,
    mut f: impl FnMut(f64, f64) -> [(f64, f64); 2],
) -> (u64, f64) {
    let mut w = (0u64, 0.0f64);
    for (a, b) in points {
        for (got, want) in f(a, b) {
            assert!(!got.is_nan(), "NaN at ({a:e}, {b:e})");
            w.0 = w.0.max(ulps(got, want));
            w.1 = w.1.max((got - want).abs());
        }
    }
    w
}

/// Arguments per function.
const SWEEP: usize = 10_000_000;

/// A generator of points `(y, x)` from the seeded state.
type Gen = fn(&mut u64) -> (f64, f64);

#[test]
fn atan2_is_within_2_ulp_of_std() {
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let ranges: [(&str, Gen); 4] = [
        ("unit square", |s| {
            (2.0 * next(s) - 1.0, 2.0 * next(s) - 1.0)
        }),
        ("log-uniform 1e-300..1e300, random signs", |s| {
            let m = |s: &mut u64| {
                let v = 10f64.powf(600.0 * next(s) - 300.0);
                if next(s) < 0.5 {
                    -v
                } else {
                    v
                }
            };
            (m(s), m(s))
        }),
        (
            "ratios near the reduction points 0.66 and tan(3π/8)",
            |s| {
                let x = 2.0 * next(s) - 1.0;
                let k = [0.66, 2.414_213_562_373_095, 1.0][(next(s) * 3.0) as usize % 3];
                (x * k * (1.0 + 1e-6 * (2.0 * next(s) - 1.0)), x)
            },
        ),
        ("near the axes", |s| {
            let big = 100.0 * (2.0 * next(s) - 1.0);
            let small = 1e-9 * (2.0 * next(s) - 1.0);
            if next(s) < 0.5 {
                (big, small)
            } else {
                (small, big)
            }
        }),
    ];
    let per_range = SWEEP / ranges.len();
    let mut all = (0u64, 0.0f64);
    for (name, gen) in ranges {
        let (u, a) = worst((0..per_range).map(|_| gen(&mut s)), |y, x| {
            [(atan2(y, x), y.atan2(x)), (0.0, 0.0)]
        });
        println!("atan2, {name} ({per_range} points): max {u} ulp, {a:e} absolute");
        assert!(u <= 2 && a <= 1e-15, "atan2 on {name}: {u} ulp, {a:e}");
        all = (all.0.max(u), all.1.max(a));
    }
    println!(
        "atan2, all {} points: max {} ulp, {:e} absolute",
        per_range * 4,
        all.0,
        all.1
    );
    assert!(per_range * 4 >= SWEEP);
}

#[test]
fn sin_cos_is_within_3_ulp_of_std() {
    let mut s = 0x2545_f491_4f6c_dd1du64;
    // Five ranges: four uniform ones and the tiny arguments.
    let per_range = SWEEP / 5;
    let both = |x: f64, _| {
        let ((fs, fc), (ss, sc)) = (sin_cos(x), x.sin_cos());
        [(fs, ss), (fc, sc)]
    };
    let mut all = (0u64, 0.0f64);
    for (name, half_width) in [
        ("|x| ≤ π/4", core::f64::consts::FRAC_PI_4),
        ("|x| ≤ 10", 10.0),
        ("|x| ≤ 1000", 1000.0),
        ("|x| ≤ 1e6", 1.0e6),
    ] {
        let pts = (0..per_range).map(|_| (half_width * (2.0 * next(&mut s) - 1.0), 0.0));
        let (u, a) = worst(pts, both);
        println!("sin_cos, {name} ({per_range} points): max {u} ulp, {a:e} absolute");
        assert!(u <= 3 && a <= 3e-16, "sin_cos on {name}: {u} ulp, {a:e}");
        all = (all.0.max(u), all.1.max(a));
    }
    // Tiny arguments, log-uniform 1e-300..1e-3 with both signs.
    let pts = (0..per_range).map(|i| {
        let v = 10f64.powf(297.0 * next(&mut s) - 300.0);
        (if i % 2 == 0 { v } else { -v }, 0.0)
    });
    let (u, a) = worst(pts, both);
    println!("sin_cos, tiny 1e-300..1e-3 ({per_range} points): max {u} ulp, {a:e} absolute");
    assert!(u <= 3, "sin_cos on tiny arguments: {u} ulp");
    all = (all.0.max(u), all.1.max(a));
    println!(
        "sin_cos, all {} points: max {} ulp, {:e} absolute",
        per_range * 5,
        all.0,
        all.1
    );
    assert!(per_range * 5 >= SWEEP);
}

/// Bit-identical to std on every special case: the signed zeros, the axes,
/// the infinities (C99 Annex F) and NaN in either argument.
#[test]
fn atan2_special_cases_are_those_of_libm() {
    let (inf, nan) = (f64::INFINITY, f64::NAN);
    let values = [0.0, -0.0, 1.0, -1.0, 3.5e-310, -2.0e300, inf, -inf, nan];
    for y in values {
        for x in values {
            let (got, want) = (atan2(y, x), y.atan2(x));
            if want.is_nan() {
                assert!(got.is_nan(), "atan2({y:e}, {x:e}) = {got:e}, want NaN");
            } else {
                assert_eq!(
                    got.to_bits(),
                    want.to_bits(),
                    "atan2({y:e}, {x:e}) = {got:e}, want {want:e}"
                );
            }
        }
    }
    let pi = core::f64::consts::PI;
    assert_eq!(atan2(0.0f64, 0.0).to_bits(), 0.0f64.to_bits());
    assert_eq!(atan2(-0.0f64, 0.0).to_bits(), (-0.0f64).to_bits());
    assert_eq!(atan2(0.0, -0.0), pi);
    assert_eq!(atan2(-0.0, -0.0), -pi);
    assert_eq!(atan2(inf, -inf), 3.0 * pi / 4.0);
    assert_eq!(atan2(-inf, inf), -pi / 4.0);
}

/// `sin_cos` keeps the sign of zero and returns NaN for NaN and ±∞, as std.
#[test]
fn sin_cos_special_cases_are_those_of_libm() {
    for x in [
        0.0f64,
        -0.0,
        f64::INFINITY,
        -f64::INFINITY,
        f64::NAN,
        2.0e6,
        -1.0e300,
    ] {
        let ((s, co), (s0, c0)) = (sin_cos(x), x.sin_cos());
        for (got, want) in [(s, s0), (co, c0)] {
            assert!(
                got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
                "sin_cos({x:e}): {got:e}, want {want:e}"
            );
        }
    }
}
