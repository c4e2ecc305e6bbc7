//! Local filters of one node: the cubature information filter with event
//! triggering (ET-CIF, `docs/algorithm.md` §3) and the covariance-form CKF, EKF
//! and UKF of the consensus baselines (§5), all sharing the trigger decision
//! and the error-minimised gain for untriggered steps.
//!
//! | file | holds |
//! |---|---|
//! | `gain.rs` | the untriggered-step options [`EtOptions`], [`EtPolicy`] and the gain [`EtGain`] |
//! | `decision.rs` | the trigger decision, the innovation gate ([`normalised_innovation`]) and what the measurement part of a step does |
//! | `contributions.rs` | the information contributions `(ī, Ī)` of triggered and untriggered steps |
//! | `cif.rs` | the ET-CIF step: [`cif_predict`], [`cif_update`], [`cif_local`] |
//! | `cov.rs` | the covariance-form step: [`cov_predict`], [`cov_update`], [`cov_local`], [`cov_local_chained`], [`kalman_update`], [`CheckedGaussian`] |
//!
//! Each step has one definition: a public entry point, at most one sibling
//! with more inputs (a checked estimate, a factor the caller already has), and
//! one internal function both call.

mod cif;
mod contributions;
mod cov;
mod decision;
mod gain;

pub use cif::{cif_local, cif_predict, cif_update, CifLocal, CifPrior};
pub(crate) use cif::{cif_predict_factored, cif_update_internal};
pub use contributions::{
    triggered_contribution, triggered_contribution_factored, untriggered_contribution,
    untriggered_contribution_closed,
};
pub(crate) use cov::cov_local_factored;
pub use cov::{
    cov_local, cov_local_chained, cov_predict, cov_update, kalman_update, CheckedGaussian,
    CovLocal, LocalFilter,
};
pub use decision::normalised_innovation;
pub(crate) use decision::{EtStep, TriggerOutcome};
pub use gain::{EtGain, EtOptions, EtPolicy};
