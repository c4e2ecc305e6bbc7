//! The fusion rules beyond CI (`docs/fusion.md`): each rule's guarantee over
//! many random cases of its correlation class, and a case outside the class
//! where it ends.
//!
//! The fused mean of every rule is linear in the inputs' means for given
//! covariances (the weights, ICI's `ω` and EI's basis depend on the covariances
//! only), so its gains are read off by fusing unit vectors: `x_f = Σ_j K_j x_j
//! (+ G ŷ_ind)`. The true error covariance of the fused estimate is then
//! `E[e eᵀ] = Σ_jl K_j J_jl K_lᵀ (+ G Y_ind Gᵀ)`, `J` the inputs' joint error
//! covariance; "consistent" means `P_f − E[e eᵀ]` is positive semidefinite,
//! checked as its smallest eigenvalue `≥ −1e-9 · λmax(P_f)` (rounding of a few
//! inversions of matrices with condition numbers up to about 10⁴).

use crate::common;

use common::*;
use edccif_core::fusion::combine_ci;
use edccif_core::fusion_rules::{fuse_information, jacobi_eigen, FusionRule};
use edccif_core::nalgebra::{SMatrix, SVector};
use edccif_core::{Gaussian, InfoPair};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

const D: usize = 3;
type M = SMatrix<f64, D, D>;
type V = SVector<f64, D>;

/// A random SPD matrix with eigenvalues spread over `10^[-1.5, 1.5]`.
fn spd(rng: &mut ChaCha8Rng) -> M {
    let a = M::from_fn(|_, _| rng.random_range(-1.0..1.0));
    let (_, q) = jacobi_eigen(&(a + a.transpose()));
    let d = V::from_fn(|_, _| 10f64.powf(rng.random_range(-1.5..1.5)));
    q * M::from_diagonal(&d) * q.transpose()
}

fn inv(m: &M) -> M {
    m.try_inverse().unwrap()
}

/// The gains `K_j` of `rule` on inputs with covariances `ps` and weights `w`
/// (and `G` for the independent pair `(·, y_ind)` when given) by fusing unit
/// vectors; and the fused covariance.
fn gains(rule: FusionRule, ps: &[M], w: &[f64], y_ind: Option<&M>) -> (Vec<M>, Option<M>, M) {
    let info = |x: &V, p: &M| Gaussian { x: *x, p: *p }.to_info().unwrap();
    let fuse = |xs: &[V], ind: Option<InfoPair<f64, D>>| {
        let items: Vec<(f64, InfoPair<f64, D>)> = xs
            .iter()
            .zip(ps)
            .zip(w)
            .map(|((x, p), w)| (*w, info(x, p)))
            .collect();
        fuse_information(rule, items.iter().copied(), ind.as_ref()).unwrap()
    };
    let zero = vec![V::zeros(); ps.len()];
    let ind0 = y_ind.map(|y| InfoPair {
        y: V::zeros(),
        ymat: *y,
    });
    let base = fuse(&zero, ind0);
    let mut ks = vec![M::zeros(); ps.len()];
    for (j, k) in ks.iter_mut().enumerate() {
        for l in 0..D {
            let mut xs = zero.clone();
            xs[j][l] = 1.0;
            k.set_column(l, &(fuse(&xs, ind0).x - base.x));
        }
    }
    let g = y_ind.map(|y| {
        let mut g = M::zeros();
        for l in 0..D {
            let mut e = V::zeros();
            e[l] = 1.0;
            g.set_column(
                l,
                &(fuse(&zero, Some(InfoPair { y: e, ymat: *y })).x - base.x),
            );
        }
        g
    });
    (ks, g, base.p)
}

/// Smallest eigenvalue of `P_f − E[e eᵀ]` over the largest of `P_f`.
fn margin(rule: FusionRule, ps: &[M], joint: &[Vec<M>], w: &[f64], ind: Option<&M>) -> f64 {
    let (ks, g, pf) = gains(rule, ps, w, ind);
    let mut cov = M::zeros();
    for j in 0..ps.len() {
        for l in 0..ps.len() {
            cov += ks[j] * joint[j][l] * ks[l].transpose();
        }
    }
    if let (Some(g), Some(y)) = (g, ind) {
        cov += g * y * g.transpose();
    }
    let (dp, _) = jacobi_eigen(&pf);
    let (dd, _) = jacobi_eigen(&(pf - cov));
    dd.min() / dp.max()
}

/// A random joint covariance of `k ≤ 4` estimates (any correlation):
/// `J = A Aᵀ` with a random factor (rows scaled by `10^[-1, 1]`), blocks `J_jl`.
fn any_joint(rng: &mut ChaCha8Rng, k: usize) -> Vec<Vec<M>> {
    assert!(k * D <= 12);
    let scale: [f64; 12] = core::array::from_fn(|_| 10f64.powf(rng.random_range(-1.0..1.0)));
    let a = SMatrix::<f64, 12, 12>::from_fn(|r, _| rng.random_range(-1.0..1.0) * scale[r]);
    let j = a * a.transpose();
    (0..k)
        .map(|r| {
            (0..k)
                .map(|c| M::from_fn(|i, l| j[(r * D + i, c * D + l)]))
                .collect()
        })
        .collect()
}

/// Estimates built from independent information plus one common part `Γ`
/// (ICI's class, Noack et al. 2017): `A_j⁻¹ = A_Ij⁻¹ + Γ⁻¹`, the estimate the
/// optimal fusion of its independent part and the common one, so
/// `E[e_j e_lᵀ] = A_j Γ⁻¹ A_l` for `j ≠ l`.
fn common_information(rng: &mut ChaCha8Rng, k: usize) -> (Vec<M>, Vec<Vec<M>>) {
    let g = spd(rng);
    let gi = inv(&g);
    let ps: Vec<M> = (0..k).map(|_| inv(&(inv(&spd(rng)) + gi))).collect();
    let joint = (0..k)
        .map(|r| {
            (0..k)
                .map(|c| if r == c { ps[r] } else { ps[r] * gi * ps[c] })
                .collect()
        })
        .collect();
    (ps, joint)
}

fn weights(rng: &mut ChaCha8Rng, k: usize) -> Vec<f64> {
    (0..k).map(|_| rng.random_range(0.05..1.0)).collect()
}

fn rules(names: &[&str]) -> Vec<FusionRule> {
    names.iter().map(|n| n.parse().unwrap()).collect()
}

const TOL: f64 = -1e-9;

/// CI, with fixed and optimised weights: consistent for any correlation of
/// consistent inputs (2–4 inputs, 300 random joint covariances each).
#[test]
fn ci_is_consistent_for_any_correlation() {
    let mut rng = rng(3001);
    for rule in rules(&["ci", "ci-trace", "ci-det"]) {
        let mut worst = f64::INFINITY;
        for case in 0..300 {
            let k = 2 + case % 3;
            let joint = any_joint(&mut rng, k);
            let ps: Vec<M> = (0..k).map(|j| joint[j][j]).collect();
            let w = weights(&mut rng, k);
            worst = worst.min(margin(rule, &ps, &joint, &w, None));
        }
        assert!(worst >= TOL, "{rule}: worst margin {worst:e}");
    }
}

/// The fixed-weight rule is the paper's `combine_ci`, bit for bit.
#[test]
fn ci_rule_is_the_papers_combination() {
    let mut rng = rng(3002);
    for _ in 0..50 {
        let infos: Vec<InfoPair<f64, D>> = (0..3)
            .map(|_| Gaussian {
                x: V::from_fn(|_, _| rng.random_range(-1.0..1.0)),
                p: spd(&mut rng),
            })
            .map(|g| g.to_info().unwrap())
            .collect();
        let w = weights(&mut rng, 3);
        let a = combine_ci(w.iter().copied().zip(&infos)).unwrap();
        let b = fuse_information(
            FusionRule::CI,
            w.iter().copied().zip(infos.iter().copied()),
            None,
        )
        .unwrap();
        assert!(
            (a.p - b.p).norm() <= 1e-12 * a.p.norm()
                && (a.x - b.x).norm() <= 1e-12 * (1.0 + a.x.norm())
        );
    }
}

/// ICI (pairwise, in order), fixed and optimised `ω`: consistent over 300 random
/// cases of common information each, 2–4 inputs.
#[test]
fn ici_is_consistent_for_common_information() {
    let mut rng = rng(3003);
    for rule in rules(&["ici", "ici-trace", "ici-det"]) {
        let mut worst = f64::INFINITY;
        for case in 0..300 {
            let k = 2 + case % 3;
            let (ps, joint) = common_information(&mut rng, k);
            let w = weights(&mut rng, k);
            worst = worst.min(margin(rule, &ps, &joint, &w, None));
        }
        assert!(worst >= TOL, "{rule}: worst margin {worst:e}");
    }
}

/// Where ICI's guarantee ends: with arbitrary correlations (outside the common
/// information class) it is overconfident in some of 300 random cases, while
/// CI on the same cases is not.
#[test]
fn ici_is_not_consistent_for_any_correlation() {
    let mut rng = rng(3004);
    let (ici, ci) = (
        FusionRule::Ici(edccif_core::fusion_rules::Weights::Fixed),
        FusionRule::CI,
    );
    let (mut bad, mut worst, mut ci_worst) = (0, f64::INFINITY, f64::INFINITY);
    for _ in 0..300 {
        let joint = any_joint(&mut rng, 2);
        let ps = vec![joint[0][0], joint[1][1]];
        let m = margin(ici, &ps, &joint, &[0.5, 0.5], None);
        bad += usize::from(m < TOL);
        worst = worst.min(m);
        ci_worst = ci_worst.min(margin(ci, &ps, &joint, &[0.5, 0.5], None));
    }
    println!("ICI outside its class: {bad} of 300 overconfident, worst margin {worst:.3}");
    assert!(bad > 10 && worst < -0.01, "{bad} {worst}");
    assert!(ci_worst >= TOL);
}

/// The N-input closed form of ICI (`C⁻¹ = Σ A_j⁻¹ − (N−1)(Σ ω_j A_j)⁻¹`,
/// gains `C (A_j⁻¹ − (N−1) ω_j (Σ ω A)⁻¹)`) is not consistent within ICI's own
/// class for three inputs with unequal weights, which is why the rule fuses
/// pairwise (this test computes that closed form by hand).
#[test]
fn the_n_input_closed_form_of_ici_is_not_consistent() {
    let mut rng = rng(3005);
    let mut bad = 0;
    for _ in 0..300 {
        let (ps, joint) = common_information(&mut rng, 3);
        let w = weights(&mut rng, 3);
        let t: f64 = w.iter().sum();
        let w = [w[0] / t, w[1] / t, w[2] / t];
        let s = ps.iter().zip(w).fold(M::zeros(), |a, (p, w)| a + p * w);
        let si = inv(&s);
        let cinv = ps.iter().fold(M::zeros(), |a, p| a + inv(p)) - si * 2.0;
        let (d, _) = jacobi_eigen(&cinv);
        if d.min() <= 0.0 {
            bad += 1;
            continue;
        }
        let c = inv(&cinv);
        let ks: Vec<M> = ps
            .iter()
            .zip(w)
            .map(|(p, w)| c * (inv(p) - si * (2.0 * w)))
            .collect();
        let mut cov = M::zeros();
        for j in 0..3 {
            for l in 0..3 {
                cov += ks[j] * joint[j][l] * ks[l].transpose();
            }
        }
        let (dd, _) = jacobi_eigen(&(c - cov));
        let (dc, _) = jacobi_eigen(&c);
        bad += usize::from(dd.min() < TOL * dc.max());
    }
    println!("N-input ICI closed form: {bad} of 300 cases of common information overconfident");
    assert!(bad >= 10, "{bad}");
}

/// Split CI: the dependent parts arbitrarily correlated, the independent
/// information (a measurement `z = H x + v`, `ŷ = Hᵀ R⁻¹ z`, `Y = Hᵀ R⁻¹ H`)
/// independent of them: consistent over 300 random cases for each weighting;
/// and overconfident when that information is already inside the dependent
/// parts (counted twice: outside its class).
#[test]
fn split_ci_is_consistent_when_the_independent_part_is() {
    let mut rng = rng(3006);
    for rule in rules(&["split-ci", "split-ci-trace", "split-ci-det"]) {
        let mut worst = f64::INFINITY;
        for case in 0..300 {
            let k = 2 + case % 3;
            let joint = any_joint(&mut rng, k);
            let ps: Vec<M> = (0..k).map(|j| joint[j][j]).collect();
            let h = SMatrix::<f64, 2, D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let r = SMatrix::<f64, 2, 2>::from_diagonal(&SVector::from_fn(|_, _| {
                10f64.powf(rng.random_range(-1.0..1.0))
            }));
            let y_ind = h.transpose() * r.try_inverse().unwrap() * h;
            let w = weights(&mut rng, k);
            worst = worst.min(margin(rule, &ps, &joint, &w, Some(&y_ind)));
        }
        assert!(worst >= TOL, "{rule}: worst margin {worst:e}");
    }
    // Outside the class: the "independent" information is input 0 itself.
    let mut bad = 0;
    for _ in 0..100 {
        let joint = any_joint(&mut rng, 2);
        let ps = vec![joint[0][0], joint[1][1]];
        let y_ind = inv(&ps[0]);
        let (ks, g, pf) = gains(rules(&["split-ci"])[0], &ps, &[0.5, 0.5], Some(&y_ind));
        let g = g.unwrap();
        // ŷ_ind − Y_ind x = Y_0 e_0: the error of the "independent" part is input 0's.
        let k0 = ks[0] + g * y_ind;
        let mut cov = k0 * joint[0][0] * k0.transpose() + ks[1] * joint[1][1] * ks[1].transpose();
        cov += k0 * joint[0][1] * ks[1].transpose() + ks[1] * joint[1][0] * k0.transpose();
        let (dd, _) = jacobi_eigen(&(pf - cov));
        let (dp, _) = jacobi_eigen(&pf);
        bad += usize::from(dd.min() < TOL * dp.max());
    }
    println!("split CI with double-counted information: {bad} of 100 overconfident");
    assert!(bad > 50, "{bad}");
}

/// Split ICI: the dependent parts from common information (ICI's class), the
/// independent measurement as for split CI: consistent over 300 random cases
/// for each weighting.
#[test]
fn split_ici_is_consistent_for_common_information_and_an_independent_measurement() {
    let mut rng = rng(3009);
    for rule in rules(&["split-ici", "split-ici-trace", "split-ici-det"]) {
        let mut worst = f64::INFINITY;
        for case in 0..300 {
            let k = 2 + case % 3;
            let (ps, joint) = common_information(&mut rng, k);
            let h = SMatrix::<f64, 2, D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
            let y_ind = h.transpose() * h * 10f64.powf(rng.random_range(-1.0..1.0));
            let w = weights(&mut rng, k);
            worst = worst.min(margin(rule, &ps, &joint, &w, Some(&y_ind)));
        }
        assert!(worst >= TOL, "{rule}: worst margin {worst:e}");
    }
}

/// Where split ICI's guarantee ends: dependent parts arbitrarily correlated
/// (outside ICI's class), the measurement still independent: overconfident in
/// some of 300 random cases, while split CI on the same cases is not.
#[test]
fn split_ici_is_not_consistent_for_any_correlation() {
    let mut rng = rng(3010);
    let (sici, sci) = (rules(&["split-ici"])[0], rules(&["split-ci"])[0]);
    let (mut bad, mut sci_worst) = (0, f64::INFINITY);
    for _ in 0..300 {
        let joint = any_joint(&mut rng, 2);
        let ps = vec![joint[0][0], joint[1][1]];
        let h = SMatrix::<f64, 2, D>::from_fn(|_, _| rng.random_range(-1.0..1.0));
        let y_ind = h.transpose() * h * 10f64.powf(rng.random_range(-1.0..1.0));
        bad += usize::from(margin(sici, &ps, &joint, &[0.5, 0.5], Some(&y_ind)) < TOL);
        sci_worst = sci_worst.min(margin(sci, &ps, &joint, &[0.5, 0.5], Some(&y_ind)));
    }
    println!("split ICI outside its class: {bad} of 300 overconfident");
    assert!(bad > 10, "{bad}");
    assert!(sci_worst >= TOL, "{sci_worst:e}");
}

/// EI has no guarantee: overconfident in many cases of ICI's common-information
/// class (where ICI holds, test above).
#[test]
fn ellipsoidal_intersection_is_not_consistent() {
    let mut rng = rng(3007);
    let mut bad = 0;
    for case in 0..300 {
        let k = 2 + case % 2;
        let (ps, joint) = common_information(&mut rng, k);
        let w = weights(&mut rng, k);
        bad += usize::from(margin(FusionRule::EiUnsafe, &ps, &joint, &w, None) < TOL);
    }
    println!("EI in the common-information class: {bad} of 300 overconfident");
    assert!(bad > 30, "{bad}");
}

/// Every rule returns an input fused with itself (identical estimates carry no
/// new information), and every rule's name parses back to it.
#[test]
fn identical_inputs_and_names() {
    let mut rng = rng(3008);
    for rule in FusionRule::ALL {
        assert_eq!(rule.name().parse::<FusionRule>().unwrap(), rule);
        for _ in 0..20 {
            let g = Gaussian {
                x: V::from_fn(|_, _| rng.random_range(-3.0..3.0)),
                p: spd(&mut rng),
            };
            let i = g.to_info().unwrap();
            let w = weights(&mut rng, 3);
            let f = fuse_information(rule, w.iter().map(|w| (*w, i)), None).unwrap();
            assert!((f.p - g.p).norm() <= 1e-8 * g.p.norm(), "{rule}");
            assert!((f.x - g.x).norm() <= 1e-8 * (1.0 + g.x.norm()), "{rule}");
        }
    }
}

/// Bad inputs are named errors.
#[test]
fn errors() {
    let i = InfoPair {
        y: V::zeros(),
        ymat: M::identity(),
    };
    for rule in FusionRule::ALL {
        assert!(fuse_information::<f64, _, D>(rule, core::iter::empty(), None).is_err());
        assert!(fuse_information(rule, [(-1.0, i)].into_iter(), None).is_err());
        assert!(fuse_information(rule, [(0.0, i), (0.0, i)].into_iter(), None).is_err());
        let bad = InfoPair {
            y: V::zeros(),
            ymat: -M::identity(),
        };
        assert!(
            fuse_information(rule, [(0.5, i), (0.5, bad)].into_iter(), None).is_err(),
            "{rule}"
        );
    }
    assert!("nope".parse::<FusionRule>().is_err());
}
