//! # edccif-core
//!
//! The allocation-free numerical core of **EDC-CIF** (event-triggered diffusion
//! cubature information filtering with covariance intersection) and of the
//! baselines it is compared against: cubature, extended and unscented Kalman
//! filters with event triggers and consensus fusion.
//!
//! `#![no_std]`, no allocator, no `unsafe`. Everything is generic over the scalar
//! `T: RealField + Copy` and over const dimensions: **`N`** is the state
//! dimension, **`M`** the measurement dimension. Matrices are nalgebra
//! [`SMatrix`](nalgebra::SMatrix) on the stack; cubature points are generated from
//! the Cholesky factor on the fly. The numbers follow the project's numerical
//! contract, `docs/algorithm.md` in the repository (the equations as
//! implemented, with the paper's equation numbers), section by section:
//!
//! | `docs/algorithm.md` | here |
//! |---|---|
//! | §1 models | the catalogue in [`models`], traits in [`model`] |
//! | §2 angles | [`angles`], [`trig`] (also the opt-in fast `atan2`, `sin_cos`) |
//! | §3 CKF → CIF → ET-CIF | [`sigma`], [`filters`]: [`cif_local`] (= [`cif_predict`] + [`cif_update`]), [`EtGain`]; [`Trigger`] |
//! | §4 diffusion, CI | [`node`] (the phases), [`fusion`] (the kernels, the weights) |
//! | fusion rules beyond CI (`docs/fusion.md`) | [`fusion_rules`] |
//! | §5 baselines, consensus | [`cov_local`], [`node_consensus_round`], [`config`] (the rows) |
//! | the whole network step | [`network_step`] ([`network_step_sparse`] over [`Neighbours`] lists, [`network_step_weighted`] with the weights in the lists too), a loop over the phases of [`node`] |
//! | packets as bytes | [`wire`] |
//!
//! Your own problem: implement [`MotionModel`] (`f`, `Q(dt)`) and
//! [`MeasurementModel`] (`h`, `R`, which components are angles) or take them from
//! the [`models`] catalogue; run one filter with [`cif_predict`]/[`cif_update`] (or
//! [`cov_predict`]/[`cov_update`] for the CKF, EKF, UKF) or a network with
//! [`network_step`]. A model whose evaluation has a per-call cost overrides the batch
//! hooks [`MotionModel::transition_points`] and [`MeasurementModel::measure_points`]
//! to evaluate every sigma point in one call (`examples/custom_model.rs`).
//!
//! Every fallible step returns [`Result`]; on error the caller's state is unchanged.
//!
//! ```
//! use edccif_core::*;
//! use edccif_core::models::{CoordinatedTurn, RangePitchAzimuth};
//! use nalgebra::{SMatrix, SVector, Vector3};
//!
//! let motion = CoordinatedTurn::new(0.5, 1e-4)?;
//! let sensor = RangePitchAzimuth::new([10.0, 0.0, 0.0], 0.1, 0.01)?;
//! let start = Gaussian::new(
//!     SVector::<f64, 7>::from([5.0, 0.0, 1.0, 0.0, 1.5, 0.1, 0.3]),
//!     SMatrix::<f64, 7, 7>::identity() * 0.01,
//! )?;
//! let trigger = Trigger::SendOnDelta { delta: 0.04 };
//! let step = cif_local(&motion, 0.1, &sensor, &start, &Observation::Measured(Vector3::new(5.0, 0.1, 3.1)),
//!                      &trigger, &TriggerState::new(&trigger), &EtOptions::default())?;
//! let posterior = step.local_posterior().to_gaussian()?;
//! assert!(posterior.p.trace() < step.p_prior.trace());
//! # Ok::<(), edccif_core::Error>(())
//! ```
#![no_std]
#![forbid(unsafe_code)]
#![deny(missing_docs)]
// `!(x > 0)` is used on purpose throughout: unlike `x <= 0` it is true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod angles;
pub mod config;
mod error;
pub mod filters;
pub mod fusion;
pub mod fusion_rules;
mod lanes;
pub mod linalg;
mod message;
pub mod model;
pub mod models;
pub mod network;
pub mod node;
pub mod rng;
pub mod sigma;
pub mod silence;
pub mod trig;
pub mod trigger;
pub mod wire;

pub use config::{Fusion, NetworkConfig, NodeFilter};
pub use error::{Error, Result};
pub use filters::triggered_contribution_factored;
pub use filters::{
    cif_local, cif_predict, cif_update, cov_local, cov_local_chained, cov_predict, cov_update,
    kalman_update, normalised_innovation, triggered_contribution, untriggered_contribution,
    untriggered_contribution_closed, CheckedGaussian, CifLocal, CifPrior, CovLocal, EtGain,
    EtOptions, EtPolicy, LocalFilter,
};
pub use fusion::CiCriterion;
pub use fusion_rules::FusionRule;
pub use message::{Contribution, Gaussian, InfoPair, Observation, Packet};
pub use model::{MeasurementModel, MotionModel, PointImages};
pub use network::{
    network_fusion, network_step, network_step_sparse, network_step_weighted, LinkMask,
    NeighbourWeights, Neighbours, NodeScratch, StepInputs, StepReport,
};
pub use node::{
    node_adapt, node_combine, node_combine_ci, node_combine_convex, node_consensus_round,
    node_local, node_local_into, node_local_received, AdaptOutput, AdaptedPacket, LocalEstimate,
    LocalOutput, LocalPacket, NodeState, PhaseScratch,
};
pub use sigma::{MeasurementStats, SigmaRule};
pub use trigger::{Trigger, TriggerState};

/// Re-export of the linear-algebra crate the API is written in.
pub use nalgebra;
