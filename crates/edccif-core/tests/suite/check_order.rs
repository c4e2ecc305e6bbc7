//! Finiteness checks the ET-CIF step makes once instead of twice, or implies
//! from another check, still fail with the same named errors:
//!
//! - `cif_predict`: a predicted covariance that overflows is reported by the
//!   factorisation of `P⁻` as `NonFinite("predicted covariance P⁻")`, the
//!   error the sigma-point prediction itself gives (`sigma_predict`);
//! - `CifPrior`: `ŷ⁻ = Y⁻ x̂⁻` is checked before `Y⁻` (a finite `ŷ⁻` proves
//!   `Y⁻` finite); an overflowing `Y⁻` is still named first, an overflowing
//!   `ŷ⁻` with a finite `Y⁻` named as `ŷ⁻`;
//! - the closed-form untriggered contribution: the same for `Ī` and `ī`.

use edccif_core::models::LinearMotion;
use edccif_core::nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
use edccif_core::sigma::{sigma_predict, SigmaRule};
use edccif_core::{
    cif_predict, untriggered_contribution_closed, CifPrior, Error, EtOptions, Gaussian,
};

fn non_finite(what: &'static str) -> Error {
    Error::NonFinite { what }
}

#[test]
fn an_overflowing_predicted_covariance_is_named_as_before() {
    // Points at ±√2·3e153 through F = 10 I: their squares overflow, their
    // mean (0) does not.
    let m = LinearMotion::new(Matrix2::identity() * 10.0, Matrix2::identity()).unwrap();
    let est = Gaussian {
        x: Vector2::zeros(),
        p: Matrix2::identity() * 1e307,
    };
    let want = non_finite("predicted covariance P⁻");
    let reference = sigma_predict(&SigmaRule::cubature(2), &m, 0.1, &est.x, &est.p);
    assert_eq!(reference.unwrap_err(), want);
    assert_eq!(cif_predict(&m, 0.1, &est).unwrap_err(), want);
}

#[test]
fn the_information_prior_names_the_first_non_finite_quantity() {
    // P⁻ = 1e-320 I factorises (diagonal 1e-160) but Y⁻ = 1e320 I overflows.
    for x in [Vector2::zeros(), Vector2::new(1.0, -2.0)] {
        let g = Gaussian {
            x,
            p: Matrix2::identity() * 1e-320,
        };
        assert_eq!(
            CifPrior::new(&g).unwrap_err(),
            non_finite("information prior Y⁻")
        );
    }
    // Y⁻ = 1e300 I is finite, ŷ⁻ = 1e300 · 1e10 is not.
    let g = Gaussian {
        x: Vector2::new(1e10, 0.0),
        p: Matrix2::identity() * 1e-300,
    };
    assert_eq!(
        CifPrior::new(&g).unwrap_err(),
        non_finite("information prior ŷ⁻")
    );
    // and a representable prior passes
    let g = Gaussian {
        x: Vector2::new(1e10, 0.0),
        p: Matrix2::identity() * 1e-10,
    };
    let prior = CifPrior::new(&g).unwrap();
    let y0: f64 = prior.info().y[0];
    assert!((y0 - 1e20).abs() <= 1e5);
}

#[test]
fn the_closed_form_names_the_first_non_finite_quantity() {
    let o = EtOptions::<f64>::default();
    let (r, dz) = (Matrix1::new(0.01), Vector1::new(0.1));
    let y = Matrix2::identity();
    // Gᵀ R̃⁻¹ G overflows: Ī is not finite (whatever x̂⁻).
    let g = Matrix1x2::new(1e200, 0.0);
    for x in [Vector2::zeros(), Vector2::new(1.0, 1.0)] {
        let e = untriggered_contribution_closed(&x, &y, &g, &r, 0.04, &o, &dz).unwrap_err();
        assert_eq!(e, non_finite("contribution Ī"));
    }
    // Ī finite (Ī₀₀ ≈ 100²/R̃ ≈ 62), ī = Ī x̂⁻ + … overflows.
    let g = Matrix1x2::new(100.0, 0.0);
    let x = Vector2::new(1e307, 0.0);
    let e = untriggered_contribution_closed(&x, &y, &g, &r, 0.04, &o, &dz).unwrap_err();
    assert_eq!(e, non_finite("contribution ī"));
    // and a NaN in x̂⁻ is reported as ī, not Ī
    let x = Vector2::new(f64::NAN, 0.0);
    let e = untriggered_contribution_closed(&x, &y, &g, &r, 0.04, &o, &dz).unwrap_err();
    assert_eq!(e, non_finite("contribution ī"));
}
