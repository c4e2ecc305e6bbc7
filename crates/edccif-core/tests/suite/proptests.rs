//! Property tests on random SPD matrices and vectors (proptest, 64 cases per
//! property, with a fixed runner seed so every run checks the same cases, and
//! no regression files written into the tree).
//!
//! Random covariances are `A Aᵀ + 0.1·I` with `A` uniform in [−1, 1]^(4×4):
//! eigenvalues in [0.1, ≈16.1], cond ≤ ≈ 161, so round-off stays ≲ 1e-13
//! and the tolerances below (≥ 1e-9) have wide margins.

use crate::common;

use common::{assert_close, psd_within};
use edccif_core::angles::wrap_angle;
use edccif_core::fusion::{adapt, ci_fuse_optimal, combine_ci, combine_convex, CiCriterion};
use edccif_core::linalg::sym;
use edccif_core::nalgebra::{Matrix2, Matrix2x4, Matrix4, Vector2, Vector4};
use edccif_core::sigma::MeasurementStats;
use edccif_core::{
    triggered_contribution, untriggered_contribution, Contribution, EtGain, EtOptions, EtPolicy,
    Gaussian, InfoPair,
};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: 64,
        rng_seed: RngSeed::Fixed(0xEDC_C1F),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

fn spd4() -> impl Strategy<Value = Matrix4<f64>> {
    prop::array::uniform16(-1.0f64..1.0).prop_map(|v| {
        let a = Matrix4::from_row_slice(&v);
        a * a.transpose() + Matrix4::identity() * 0.1
    })
}

fn spd2() -> impl Strategy<Value = Matrix2<f64>> {
    prop::array::uniform4(-1.0f64..1.0).prop_map(|v| {
        let a = Matrix2::from_row_slice(&v);
        a * a.transpose() + Matrix2::identity() * 0.1
    })
}

fn vec4() -> impl Strategy<Value = Vector4<f64>> {
    prop::array::uniform4(-10.0f64..10.0).prop_map(Vector4::from)
}

fn gaussian4() -> impl Strategy<Value = Gaussian<f64, 4>> {
    (vec4(), spd4()).prop_map(|(x, p)| Gaussian::new(x, p).unwrap())
}

/// Non-negative weights with a sum of at least 0.1.
fn weights3() -> impl Strategy<Value = [f64; 3]> {
    prop::array::uniform3(0.0f64..1.0).prop_filter("positive sum", |w| w.iter().sum::<f64>() > 0.1)
}

proptest! {
    #![proptest_config(config())]

    /// Covariance/information forms round-trip: rel 1e-10 on x and P.
    #[test]
    fn info_round_trip(g in gaussian4()) {
        let back = g.to_info().unwrap().to_gaussian().unwrap();
        assert_close(&back.x, &g.x, 1e-10, 1e-12, "x");
        assert_close(&back.p, &g.p, 1e-10, 0.0, "P");
        prop_assert_eq!(back.p, back.p.transpose());
    }

    /// CI with weights w: the output is PD, `P_ci⁻¹ = Σ w_j P_j⁻¹ / Σ w`
    /// (rel 1e-9) and `P_ci⁻¹ x_ci = Σ w_j P_j⁻¹ x_j / Σ w` (rel 1e-9 + 1e-9 abs).
    /// And CI is never larger than the convex combination of covariances:
    /// `Σ c_j P_j − P_ci ⪰ 0` (the matrix harmonic mean is below the arithmetic
    /// mean; PSD up to 1e-9 relative).
    #[test]
    fn ci_is_pd_and_its_information_is_the_weighted_sum(
        a in gaussian4(), b in gaussian4(), c in gaussian4(), w in weights3()
    ) {
        let gs = [a, b, c];
        let infos = [a.to_info().unwrap(), b.to_info().unwrap(), c.to_info().unwrap()];
        let ci = combine_ci(w.iter().copied().zip(&infos)).unwrap();
        prop_assert!(ci.p.cholesky().is_some(), "CI covariance not PD");
        let s: f64 = w.iter().sum();
        let y_sum = infos.iter().zip(w).fold(Matrix4::zeros(), |acc, (i, wj)| acc + i.ymat * wj) / s;
        let v_sum = infos.iter().zip(w).fold(Vector4::zeros(), |acc, (i, wj)| acc + i.y * wj) / s;
        let y_ci = ci.p.try_inverse().unwrap();
        assert_close(&y_ci, &y_sum, 1e-9, 0.0, "P_ci⁻¹");
        assert_close(&(y_ci * ci.x), &v_sum, 1e-9, 1e-9, "P_ci⁻¹ x_ci");

        let convex = combine_convex(w.iter().copied().zip(&gs)).unwrap();
        prop_assert!(psd_within(&(convex.p - ci.p), 1e-9), "Σ c P − P_ci not PSD");
    }

    /// Adaptation returns an exactly symmetric information matrix, even from
    /// slightly asymmetric contributions, and its value is sym(Y⁻ + ΣĪ).
    #[test]
    fn adapt_output_is_symmetric(
        p in spd4(), m1 in spd4(), m2 in spd4(), skew in prop::array::uniform16(-1e-6f64..1e-6),
        i1 in vec4(), i2 in vec4(), x in vec4()
    ) {
        let prior = Gaussian::new(x, p).unwrap().to_info().unwrap();
        let own = Contribution { i: i1, imat: m1 + Matrix4::from_row_slice(&skew) };
        let other = Contribution { i: i2, imat: m2 - Matrix4::identity() * 0.5 };
        let a = adapt(&prior, &own, [&other]);
        prop_assert_eq!(a.ymat, a.ymat.transpose());
        assert_close(&a.ymat, &sym(&(prior.ymat + own.imat + other.imat)), 1e-15, 0.0, "Y");
    }

    /// A triggered contribution on a linear sensor is `Ī = Hᵀ R⁻¹ H` (PSD), and
    /// the local posterior `Y⁻ + Ī` equals the Kalman posterior information;
    /// the vector part gives the Kalman mean. Tolerances rel 1e-9.
    #[test]
    fn triggered_contribution_is_linear_kalman_information(
        p in spd4(), r in spd2(), x in vec4(), h in prop::array::uniform8(-1.0f64..1.0),
        dz in prop::array::uniform2(-1.0f64..1.0)
    ) {
        let h = Matrix2x4::from_row_slice(&h);
        let dz = Vector2::from(dz);
        let y = p.try_inverse().unwrap();
        let stats = MeasurementStats { z_hat: h * x, pzz: sym(&(h * p * h.transpose() + r)), pxz: p * h.transpose() };
        let c = triggered_contribution(&y, &x, &stats, &dz).unwrap();
        let r_inv = r.try_inverse().unwrap();
        let info = h.transpose() * r_inv * h;
        assert_close(&c.imat, &info, 1e-9, 1e-9 * y.norm(), "Ī = HᵀR⁻¹H");
        prop_assert!(psd_within(&c.imat, 1e-9), "Ī not PSD");
        let s = h * p * h.transpose() + r;
        let k = p * h.transpose() * s.try_inverse().unwrap();
        let post = InfoPair { y: y * x + c.i, ymat: y + c.imat }.to_gaussian().unwrap();
        assert_close(&post.x, &(x + k * dz), 1e-9, 1e-9, "posterior mean");
        assert_close(&post.p, &((Matrix4::identity() - k * h) * p), 1e-9, 0.0, "posterior P");
    }

    /// The untriggered step never produces a non-PD local posterior:
    /// `Y⁻ + Ī = P̄⁻¹` with P̄ PD, for any σ1, σ2 > 0 and δ ≥ 0; and
    /// `(Y⁻ + Ī)⁻¹(ŷ⁻ + ī) = x̂⁻ + M Δz̄` (rel 1e-9; cond(P̄) grows like 1/σ1,
    /// hence σ ≥ 1e-4 here).
    #[test]
    fn untriggered_posterior_is_pd_and_is_the_gain_update(
        p in spd4(), r in spd2(), x in vec4(), g in prop::array::uniform8(-1.0f64..1.0),
        dz in prop::array::uniform2(-1.0f64..1.0), s1 in 1e-4f64..1.0, s2 in 1e-4f64..1.0,
        delta in 0.0f64..1.0
    ) {
        let g = Matrix2x4::from_row_slice(&g);
        let dz = Vector2::from(dz);
        let y = sym(&p.try_inverse().unwrap());
        let opts = EtOptions { policy: EtPolicy::Optimal, sigma1: s1, sigma2: s2, gate: None, untriggered_closed_form: false };
        let gain = EtGain::new(&p, &g, &r, delta, &opts).unwrap();
        prop_assert!(gain.p_bar.cholesky().is_some(), "P̄ not PD");
        let c = untriggered_contribution(&x, &y, &g, &gain, &dz).unwrap();
        let post = InfoPair { y: y * x + c.i, ymat: sym(&(y + c.imat)) }.to_gaussian().unwrap();
        assert_close(&post.x, &(x + gain.m * dz), 1e-9, 1e-9, "posterior mean");
        assert_close(&post.p, &gain.p_bar, 1e-9, 0.0, "posterior P");
    }

    /// Optimised CI is never worse than its starting weights, and its weights
    /// stay on the simplex (sum 1 to 1e-12, non-negative).
    #[test]
    fn optimised_ci_improves_on_its_start(
        a in gaussian4(), b in gaussian4(), c in gaussian4(), w0 in weights3(), det in any::<bool>()
    ) {
        let infos = [a.to_info().unwrap(), b.to_info().unwrap(), c.to_info().unwrap()];
        let crit = if det { CiCriterion::Determinant } else { CiCriterion::Trace };
        let cost = |g: &Gaussian<f64, 4>| match crit {
            CiCriterion::Trace => g.p.trace(),
            CiCriterion::Determinant => g.p.determinant(),
        };
        let start = combine_ci(w0.iter().copied().zip(&infos)).unwrap();
        let mut w = w0;
        let opt = ci_fuse_optimal(&infos, crit, &mut w).unwrap();
        prop_assert!(cost(&opt) <= cost(&start) * (1.0 + 1e-12));
        prop_assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        prop_assert!(w.iter().all(|v| *v >= 0.0));
    }

    /// CI is consistent whatever the (unknown) cross-correlation: for two
    /// estimates whose errors have any joint covariance `[[P1, C], [Cᵀ, P2]]`
    /// (random 8×8 SPD), the CI fused covariance bounds the actual covariance
    /// `A Σ Aᵀ` of the fused error (`A = P_ci [w1 Y1, w2 Y2]`): `P_ci − A Σ Aᵀ ⪰ 0`
    /// (to 1e-9 relative).
    #[test]
    fn ci_is_consistent_for_any_cross_correlation(
        v in prop::collection::vec(-1.0f64..1.0, 64), w1 in 0.01f64..0.99, x1 in vec4(), x2 in vec4()
    ) {
        use edccif_core::nalgebra::SMatrix;
        let l = SMatrix::<f64, 8, 8>::from_row_slice(&v);
        let joint = l * l.transpose() + SMatrix::<f64, 8, 8>::identity() * 0.1;
        let p1: Matrix4<f64> = joint.fixed_view::<4, 4>(0, 0).into_owned();
        let p2: Matrix4<f64> = joint.fixed_view::<4, 4>(4, 4).into_owned();
        let i1 = Gaussian::new(x1, sym(&p1)).unwrap().to_info().unwrap();
        let i2 = Gaussian::new(x2, sym(&p2)).unwrap().to_info().unwrap();
        let fused = combine_ci([(w1, &i1), (1.0 - w1, &i2)]).unwrap();
        let mut a = SMatrix::<f64, 4, 8>::zeros();
        a.fixed_view_mut::<4, 4>(0, 0).copy_from(&(fused.p * i1.ymat * w1));
        a.fixed_view_mut::<4, 4>(0, 4).copy_from(&(fused.p * i2.ymat * (1.0 - w1)));
        let actual = a * joint * a.transpose();
        let margin = sym(&(fused.p - actual));
        let min_eig = margin.symmetric_eigenvalues().min();
        prop_assert!(min_eig >= -1e-9 * fused.p.norm(), "CI not consistent: min eigenvalue {}", min_eig);
    }

    /// `wrap_angle` lands in [−π, π) and differs from its input by a multiple
    /// of 2π (to 1e-9 in units of 2π for |a| ≤ 1e3).
    #[test]
    fn wrap_angle_is_in_range_and_congruent(a in -1e3f64..1e3) {
        let w = wrap_angle(a);
        prop_assert!((-core::f64::consts::PI..core::f64::consts::PI).contains(&w), "{} -> {}", a, w);
        let turns = (a - w) / core::f64::consts::TAU;
        prop_assert!((turns - turns.round()).abs() < 1e-9);
    }
}
