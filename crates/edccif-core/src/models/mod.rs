//! The model catalogue: motion models and sensors ready to use, each with analytic
//! Jacobians and validated parameters (a bad one is a named
//! [`Error`](crate::Error) from `new`).
//!
//! | motion | state | `N` |
//! |---|---|---|
//! | [`ConstantVelocity`] | `[p(d), v(d)]` | 2, 4, 6 (1-D, 2-D, 3-D) |
//! | [`ConstantAcceleration`] | `[p(d), v(d), a(d)]` | 3, 6, 9 |
//! | [`CoordinatedTurn`] | `[px, py, pz, vx, vy, vz, ω]` (`docs/algorithm.md` §1) | 7 |
//! | [`CoordinatedTurn2`] | `[x, y, vx, vy, ω]` | 5 |
//! | [`RandomWalk`] | any | any |
//! | [`LinearMotion`] | any (`F`, `Q` given) | any |
//!
//! | sensor | `z` | `M` | angles |
//! |---|---|---|---|
//! | [`Position2`] / [`Position3`] | the first 2 / 3 state components | 2 / 3 | — |
//! | [`RangeBearing`] | range, bearing in the plane | 2 | 1 |
//! | [`BearingOnly`] | bearing in the plane | 1 | 0 |
//! | [`RangeOnly`] | range in 2-D or 3-D | 1 | — |
//! | [`RangePitchAzimuth`] | range, pitch, azimuth (`docs/algorithm.md` §1) | 3 | 1, 2 |
//! | [`LinearMeasurement`] | `H x` | any | — |
//!
//! Sensors measure the position held in the first 2 or 3 state components, so one
//! sensor serves every motion model. The sensors and the motion models of several
//! dimensions implement their trait for every state dimension `N`, so that code
//! generic over `N` can hold them; an `N` the model does not define
//! (`ConstantVelocity::supports`, `ConstantAcceleration::supports`, a state shorter
//! than a sensor's position) gives NaN, which every filter reports as
//! [`Error::NonFinite`](crate::Error::NonFinite) without committing anything.
//!
//! ```
//! use edccif_core::models::{ConstantVelocity, RangeBearing};
//! use edccif_core::{cif_predict, cif_update, EtOptions, Gaussian, Observation, Trigger, TriggerState};
//! use nalgebra::{Matrix4, Vector2, Vector4};
//!
//! let motion = ConstantVelocity::new(0.1)?;              // 2-D: [x, y, vx, vy]
//! let radar = RangeBearing::new([0.0, 0.0], 0.5, 0.01)?;
//! let est = Gaussian::new(Vector4::new(10.0, 0.0, 0.0, 1.0), Matrix4::identity())?;
//! let prior = cif_predict(&motion, 1.0, &est)?;
//! let trig = Trigger::Always;
//! let step = cif_update(&radar, &prior, &Observation::Measured(Vector2::new(10.1, 0.1)),
//!                       &trig, &TriggerState::new(&trig), &EtOptions::default())?;
//! assert!(step.local_posterior().to_gaussian()?.p.trace() < prior.p().trace());
//! # Ok::<(), edccif_core::Error>(())
//! ```

mod motion;
mod sensors;
mod undefined;

/// Serde default of the models' `fast_trig` (on).
#[cfg(feature = "serde")]
fn yes() -> bool {
    true
}

#[cfg(test)]
pub(crate) use motion::CT_JACOBIAN_PATTERN;
pub use motion::{
    ConstantAcceleration, ConstantVelocity, CoordinatedTurn, CoordinatedTurn2, LinearMotion,
    RandomWalk, CT2_DIM, CT_DIM,
};
pub use sensors::{
    BearingOnly, LinearMeasurement, Position2, Position3, RangeBearing, RangeOnly,
    RangePitchAzimuth,
};
