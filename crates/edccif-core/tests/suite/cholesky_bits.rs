//! `linalg::cholesky` is a hand-written replacement for nalgebra's
//! `Cholesky::new` (and the checks around it); it must give the same factor bit
//! for bit, and so the same solves and inverses (the paper rows' results depend
//! on it), and the same Ok/Err outcomes. Compared here on the f64 bit patterns, no tolerance, over
//! seeded random matrices of every dimension 1..=9: well and badly conditioned
//! SPD matrices (condition numbers up to ~1e16), entries spanning ~200 decades,
//! signed zeros and garbage upper triangles, plus indefinite, singular,
//! non-finite, subnormal, underflowing and overflowing ones.

use edccif_core::linalg::{chol_inverse, cholesky};
use edccif_core::nalgebra::{Cholesky, Const, SMatrix};
use edccif_core::Error;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Random matrices per dimension for each family below.
const CASES: usize = 10_000;

/// The old `linalg::cholesky`: finiteness check, nalgebra's factorisation, and
/// the check that the factor's diagonal is finite and positive.
fn reference<const D: usize>(a: &SMatrix<f64, D, D>) -> Result<Cholesky<f64, Const<D>>, Error> {
    let what = "A";
    if !a.iter().all(|v| v.is_finite()) {
        return Err(Error::NonFinite { what });
    }
    let ch = Cholesky::new(*a).ok_or(Error::NotPositiveDefinite { what })?;
    let l = ch.l_dirty();
    if (0..D).all(|i| l[(i, i)].is_finite() && l[(i, i)] > 0.0) {
        Ok(ch)
    } else {
        Err(Error::NotPositiveDefinite { what })
    }
}

fn bits<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Vec<u64> {
    m.iter().map(|v| v.to_bits()).collect()
}

/// Same outcome; on success the same factor (whole stored matrix and `l()`)
/// and the same solves, all compared on the bits. Returns whether it factorised.
fn check<const D: usize>(a: &SMatrix<f64, D, D>, rng: &mut ChaCha8Rng) -> bool {
    let want = reference(a);
    let got = cholesky(a, "A");
    match (&want, &got) {
        (Ok(w), Ok(g)) => {
            assert_eq!(bits(g.l_dirty()), bits(w.l_dirty()), "factor of {a}");
            assert_eq!(bits(&g.l()), bits(&w.l()), "l() of {a}");
            let v = SMatrix::<f64, D, 1>::from_fn(|_, _| wide(rng));
            assert_eq!(bits(&g.solve(&v)), bits(&w.solve(&v)), "solve of {a}");
            let b = SMatrix::<f64, D, 3>::from_fn(|_, _| wide(rng));
            assert_eq!(bits(&g.solve(&b)), bits(&w.solve(&b)), "solve of {a}");
            assert_eq!(bits(&g.inverse()), bits(&w.inverse()), "inverse of {a}");
            assert_eq!(bits(&chol_inverse(g)), bits(&chol_inverse(w)), "{a}");
            true
        }
        (Err(w), Err(g)) => {
            assert_eq!(g, w, "error for {a}");
            false
        }
        _ => panic!("outcome differs for {a}: nalgebra {want:?}, here {got:?}"),
    }
}

/// A normal-ish value times a power of ten in [-e, e].
fn scaled(rng: &mut ChaCha8Rng, e: i32) -> f64 {
    let u: f64 = rng.random_range(-1.0..1.0);
    u * 10f64.powi(rng.random_range(-e..=e))
}

/// Values over many magnitudes, with some exact and signed zeros.
fn wide(rng: &mut ChaCha8Rng) -> f64 {
    match rng.random_range(0..20) {
        0 => 0.0,
        1 => -0.0,
        _ => scaled(rng, 30),
    }
}

/// `B Bᵀ + δ I` with `B`'s columns scaled by powers of ten, optionally then
/// congruence-scaled `S A S` by a diagonal spanning up to 200 decades; some
/// entries of `B` are exact (signed) zeros, which leaves zero products in the
/// factorisation. The strict upper triangle is replaced by garbage half the
/// time: only the lower one is read.
fn spd<const D: usize>(rng: &mut ChaCha8Rng) -> SMatrix<f64, D, D> {
    let spread = rng.random_range(0..=6);
    let mut b = SMatrix::<f64, D, D>::from_fn(|_, _| scaled(rng, spread));
    if rng.random_bool(0.3) {
        for v in b.iter_mut() {
            if rng.random_bool(0.3) {
                *v = if rng.random_bool(0.5) { 0.0 } else { -0.0 };
            }
        }
    }
    // condition: δ from 1e-12 of the scale up to 10 times it; tiny δ with a
    // rank-deficient B gives condition numbers around 1e12 and beyond
    let scale = b.iter().fold(0f64, |m, v| m.max(v.abs())).max(1e-300);
    let delta = scale * scale * 10f64.powi(rng.random_range(-12..=1));
    if rng.random_bool(0.3) && D > 1 {
        let r = rng.random_range(0..D);
        for k in 0..D {
            b[(k, r)] = 0.0;
        }
    }
    let mut a = b * b.transpose() + SMatrix::<f64, D, D>::identity() * delta;
    if rng.random_bool(0.5) {
        let e = rng.random_range(0..=100);
        let s: Vec<f64> = (0..D)
            .map(|_| 10f64.powi(rng.random_range(-e..=e)))
            .collect();
        a = SMatrix::from_fn(|i, j| a[(i, j)] * s[i] * s[j]);
    }
    garbage_upper(&mut a, rng);
    a
}

fn garbage_upper<const D: usize>(a: &mut SMatrix<f64, D, D>, rng: &mut ChaCha8Rng) {
    if rng.random_bool(0.5) {
        for j in 1..D {
            for i in 0..j {
                a[(i, j)] = wide(rng);
            }
        }
    }
}

/// Symmetric matrices that are mostly not positive definite: random symmetric,
/// negative or zero pivots, exactly singular, rank-deficient products.
fn not_pd<const D: usize>(rng: &mut ChaCha8Rng) -> SMatrix<f64, D, D> {
    let mut a = SMatrix::<f64, D, D>::from_fn(|_, _| wide(rng));
    a = (a + a.transpose()) * 0.5;
    match rng.random_range(0..5) {
        0 => {}
        1 => {
            // SPD except one pivot made negative or zero
            a = spd::<D>(rng);
            let k = rng.random_range(0..D);
            a[(k, k)] = [-a[(k, k)], 0.0, -0.0][rng.random_range(0..3)];
        }
        2 => {
            // exactly singular: a zero row and column
            a = spd::<D>(rng);
            let k = rng.random_range(0..D);
            for i in 0..D {
                a[(i, k)] = 0.0;
                a[(k, i)] = 0.0;
            }
        }
        3 => {
            // rank one, or two equal columns: singular in exact arithmetic,
            // rounding decides the sign of the last pivots
            let v = SMatrix::<f64, D, 1>::from_fn(|_, _| scaled(rng, 3));
            a = v * v.transpose();
        }
        _ => {
            // a multiple of the identity minus a large rank-one term
            let v = SMatrix::<f64, D, 1>::from_fn(|_, _| scaled(rng, 1));
            a = SMatrix::<f64, D, D>::identity() - v * v.transpose() * 10.0;
        }
    }
    garbage_upper(&mut a, rng);
    a
}

/// Entries at the edges of the range: subnormal, underflowing products,
/// overflowing products and factors, non-finite entries (in either triangle).
fn extreme<const D: usize>(rng: &mut ChaCha8Rng) -> SMatrix<f64, D, D> {
    let mut a = spd::<D>(rng);
    let norm = a
        .iter()
        .fold(0f64, |m, v| m.max(v.abs()))
        .max(f64::MIN_POSITIVE);
    match rng.random_range(0..7) {
        0 => a *= 1e-310 / norm,                                    // subnormal
        1 => a *= 10f64.powi(rng.random_range(-320..=-290)) / norm, // underflow
        2 => a *= 10f64.powi(rng.random_range(290..=307)) / norm,   // overflow
        3 => {
            // a subnormal pivot under ordinary off-diagonal entries
            let k = rng.random_range(0..D);
            a[(k, k)] = 4.9e-324 * rng.random_range(1.0..1e6);
        }
        _ => {
            let bad = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -f64::NAN];
            let (i, j) = (rng.random_range(0..D), rng.random_range(0..D));
            a[(i, j)] = bad[rng.random_range(0..bad.len())];
        }
    }
    a
}

fn run<const D: usize>(seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let spd_ok = (0..CASES)
        .filter(|_| check(&spd::<D>(&mut rng), &mut rng))
        .count();
    // nearly all of them factorise (rounding may break the worst conditioned)
    assert!(spd_ok > CASES * 9 / 10, "D = {D}: {spd_ok} of {CASES}");
    let not_pd_ok = (0..CASES / 4)
        .filter(|_| check(&not_pd::<D>(&mut rng), &mut rng))
        .count();
    let extreme_ok = (0..CASES / 4)
        .filter(|_| check(&extreme::<D>(&mut rng), &mut rng))
        .count();
    // failures occur in the failure-prone families, and successes among the
    // extreme ones
    assert!(not_pd_ok < CASES / 4, "D = {D}: {not_pd_ok}");
    assert!(
        extreme_ok > 0 && extreme_ok < CASES / 4,
        "D = {D}: {extreme_ok}"
    );
}

#[test]
fn cholesky_and_solves_match_nalgebra_bit_for_bit_in_every_dimension() {
    run::<1>(1);
    run::<2>(2);
    run::<3>(3);
    run::<4>(4);
    run::<5>(5);
    run::<6>(6);
    run::<7>(7);
    run::<8>(8);
    run::<9>(9);
}

#[test]
fn named_edge_cases_keep_their_outcomes() {
    type M3 = SMatrix<f64, 3, 3>;
    let npd = Err(Error::NotPositiveDefinite { what: "A" });
    let nf = Err(Error::NonFinite { what: "A" });
    let outcome = |a: &M3| cholesky(a, "A").map(|ch| ch.l());
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let cases: [(M3, Result<(), Error>); 9] = [
        (M3::identity(), Ok(())),
        (M3::zeros(), npd),
        (M3::identity() * -1.0, npd),
        (M3::identity() * -0.0, npd),
        (M3::identity() * 5e-324, Ok(())),
        (M3::identity() * f64::MAX, Ok(())),
        // the second pivot overflows to -∞ (l₁₀² = ∞)
        (
            M3::new(1e-300, 0.0, 0.0, 1e10, 1.0, 0.0, 0.0, 0.0, 1.0),
            npd,
        ),
        (M3::from_element(f64::NAN), nf),
        // non-finite in the unread upper triangle still fails the finiteness check
        (
            M3::new(1.0, f64::INFINITY, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
            nf,
        ),
    ];
    for (a, want) in cases {
        assert_eq!(outcome(&a).map(|_| ()), want, "{a}");
        check(&a, &mut rng);
    }
}
