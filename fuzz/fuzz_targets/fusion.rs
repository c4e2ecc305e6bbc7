//! The fusion functions: adaptation, CI / information / convex combination,
//! a consensus iteration and optimal-weight CI, on fuzzed information pairs,
//! estimates and weights.
#![no_main]
use edccif_core::fusion::{
    adapt, ci_fuse_optimal, combine_ci, combine_convex, combine_information, consensus_iteration,
};
use edccif_core::*;
use edccif_fuzz::*;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes::new(data);
    let k = 1 + usize::from(b.u8() % 4);
    let infos: Vec<InfoPair<f64, 4>> = (0..k)
        .map(|_| InfoPair {
            y: b.vec::<4>(),
            ymat: b.cov::<4>(),
        })
        .collect();
    let gs: Vec<Gaussian<f64, 4>> = (0..k)
        .map(|_| Gaussian {
            x: b.vec::<4>(),
            p: b.cov::<4>(),
        })
        .collect();
    let w: Vec<f64> = (0..k)
        .map(|_| {
            if b.u8() < 200 {
                f64::from(b.u8()) / 255.0
            } else {
                b.f()
            }
        })
        .collect();
    let contribs: Vec<Contribution<f64, 4>> = (0..k)
        .map(|_| Contribution {
            i: b.vec::<4>(),
            imat: b.cov::<4>(),
        })
        .collect();

    let a = adapt(&infos[0], &contribs[0], contribs[1..].iter());
    if a.to_gaussian().is_ok() {
        // `to_gaussian` succeeded: its result must satisfy the estimate invariant
        check_gaussian(&a.to_gaussian().unwrap(), "adapted");
    }
    if let Ok(g) = combine_ci(w.iter().copied().zip(infos.iter())) {
        check_gaussian(&g, "combine_ci");
    }
    if let Ok(p) = combine_information(w.iter().copied().zip(infos.iter())) {
        check_info(&p, "combine_information");
    }
    if let Ok(g) = combine_convex(w.iter().copied().zip(gs.iter())) {
        // a convex combination of valid estimates is valid; of invalid ones, finite
        if gs.iter().all(|g| Gaussian::new(g.x, g.p).is_ok()) {
            check_gaussian(&g, "combine_convex");
        } else {
            assert!(finite(&g.x) && finite(&g.p), "combine_convex: non-finite");
        }
    }
    let wm: Vec<f64> = (0..k * k).map(|_| f64::from(b.u8()) / 255.0).collect();
    let mut next = vec![InfoPair::zeros(); k];
    if consensus_iteration(&wm, &infos, &mut next).is_ok() {
        for p in &next {
            check_info(p, "consensus_iteration");
        }
    }
    let crit = if b.bool() {
        CiCriterion::Trace
    } else {
        CiCriterion::Determinant
    };
    let mut ow = vec![0.0; k];
    if let Ok(g) = ci_fuse_optimal(&infos, crit, &mut ow) {
        check_gaussian(&g, "ci_fuse_optimal");
        assert!(
            ow.iter().all(|v| v.is_finite() && *v >= 0.0),
            "CI weights {ow:?}"
        );
    }
});
