//! `cov_local` for the CKF, EKF and UKF with fuzzed inputs.
#![no_main]
use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
use edccif_core::*;
use edccif_fuzz::*;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes::new(data);
    let filter = match b.u8() % 3 {
        0 => LocalFilter::Ckf,
        1 => LocalFilter::Ekf,
        _ => LocalFilter::Ukf {
            alpha: b.pos(),
            beta: b.f(),
            kappa: b.f(),
        },
    };
    let Ok(motion) = CoordinatedTurn::new(b.pos(), b.pos(), b.pos()) else {
        return;
    };
    let Ok(sensor) = RangePitchAzimuth::new([b.f(), b.f(), b.f()], b.pos(), b.pos()) else {
        return;
    };
    let estimate = Gaussian {
        x: b.vec::<7>(),
        p: b.cov::<7>(),
    };
    let obs = if b.u8() < 30 {
        Observation::Missing
    } else {
        Observation::Measured(b.vec::<3>())
    };
    let trigger = match b.u8() % 3 {
        0 => Trigger::Always,
        1 => Trigger::SendOnDelta { delta: b.pos() },
        _ => Trigger::Dynamic {
            delta: b.pos(),
            lambda: b.f(),
            theta: b.pos(),
        },
    };
    let mut ts = TriggerState::new(&trigger);
    if b.bool() {
        ts.last_sent = Some(b.vec::<3>());
    }
    let policy = [EtPolicy::Optimal, EtPolicy::Hold, EtPolicy::Skip][usize::from(b.u8() % 3)];
    let opts = EtOptions {
        policy,
        sigma1: b.pos(),
        sigma2: b.pos(),
        gate: if b.bool() { Some(b.pos()) } else { None },
    };
    if let Ok(r) = cov_local(
        &filter, &motion, &sensor, &estimate, &obs, &trigger, &ts, &opts,
    ) {
        check_gaussian(&r.posterior, "posterior");
    }
});
