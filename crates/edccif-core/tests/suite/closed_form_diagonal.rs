//! The closed-form untriggered contribution with a diagonal `R̃` (rows of `G`
//! and `Δz̄` scaled by `1/√r̃ₖₖ`, no factorisation) against the general
//! path (Cholesky factor and triangular solves), which a `R` with a
//! negligible off-diagonal entry (1e-300) takes: `Ī` and `ī` within 1e-14 of
//! the scale of their entries on random cases, and the same named errors.

use crate::common;

use common::*;
use edccif_core::nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use edccif_core::{untriggered_contribution_closed, Error, EtOptions};
use rand::Rng;

#[test]
fn a_diagonal_noise_matches_the_factorised_path_within_1e_14() {
    let mut rng = rng(17);
    let mut worst = 0.0f64;
    for round in 0..500 {
        let mut seed = round as u64 + 1;
        let lf = lower_factor::<7>(&mut seed, 1.0 + (round % 5) as f64, 0.3, 1.0);
        let y = lf * lf.transpose();
        let x = SVector::<f64, 7>::from_fn(|_, _| rng.random_range(-20.0..20.0));
        let g = SMatrix::<f64, 3, 7>::from_fn(|_, _| rng.random_range(-2.0..2.0));
        let dz = Vector3::from_fn(|_, _| rng.random_range(-0.5..0.5));
        let r = Matrix3::from_diagonal(&Vector3::from_fn(|_, _| rng.random_range(1e-4..1.0)));
        let mut r_off = r;
        r_off[(1, 0)] = 1e-300;
        r_off[(0, 1)] = 1e-300;
        let sigma = [5e-4, 0.1, 0.5][round % 3];
        let o = EtOptions {
            sigma1: sigma,
            sigma2: sigma,
            ..EtOptions::default()
        };
        let delta = [0.0, 0.04, 1.0][round % 3];
        let fast = untriggered_contribution_closed(&x, &y, &g, &r, delta, &o, &dz).unwrap();
        let general = untriggered_contribution_closed(&x, &y, &g, &r_off, delta, &o, &dz).unwrap();
        worst = worst
            .max(rel(&fast.imat, &general.imat))
            .max(rel(&fast.i, &general.i));
    }
    eprintln!("diagonal R̃: largest relative difference {worst:e}");
    assert!(worst < 1e-14, "largest relative difference {worst:e}");
}

#[test]
fn a_diagonal_noise_fails_with_the_factorisations_errors() {
    let what = "untriggered noise R̃ = μ2 R + μ3 δ I";
    let o = EtOptions::<f64>::default();
    let y = SMatrix::<f64, 7, 7>::identity();
    let x = SVector::<f64, 7>::zeros();
    let g = SMatrix::<f64, 3, 7>::from_element(0.5);
    let dz = Vector3::new(0.1, 0.0, 0.0);
    let bad = [
        (f64::NAN, Error::NonFinite { what }),
        (f64::INFINITY, Error::NonFinite { what }),
        (-1.0, Error::NotPositiveDefinite { what }),
        (0.0, Error::NotPositiveDefinite { what }),
    ];
    for (v, want) in bad {
        let r = Matrix3::from_diagonal(&Vector3::new(0.1, v, 0.1));
        let e = untriggered_contribution_closed(&x, &y, &g, &r, 0.0, &o, &dz).unwrap_err();
        assert_eq!(e, want, "R₁₁ = {v}");
    }
    // R̃ is checked before Δz̄, as by the factorisation
    let r = Matrix3::from_diagonal(&Vector3::new(0.1, 0.1, 0.1));
    let dz = Vector3::new(f64::NAN, 0.0, 0.0);
    let e = untriggered_contribution_closed(&x, &y, &g, &r, 0.0, &o, &dz).unwrap_err();
    assert_eq!(
        e,
        Error::NonFinite {
            what: "innovation Δz̄"
        }
    );
}
