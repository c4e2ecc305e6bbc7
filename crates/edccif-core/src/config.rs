//! What an algorithm row is made of: the local filter every node runs, its
//! trigger, the untriggered-step options, and how the nodes fuse (the paper's
//! rows: `docs/algorithm.md` §5).

use nalgebra::RealField;

use crate::error::{Error, Result};
use crate::filters::{EtOptions, LocalFilter};
use crate::fusion_rules::FusionRule;
use crate::sigma::SigmaRule;
use crate::trigger::Trigger;

/// The local filter each node runs.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum NodeFilter<T> {
    /// Cubature information filter with event triggering (contributions in
    /// information form; required by the diffusion fusions).
    Cif,
    /// A covariance-form filter (CKF, EKF, UKF).
    Cov(LocalFilter<T>),
}

/// How the nodes' estimates are fused after the local step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Fusion {
    /// Diffusion adaptation + combination with covariance intersection (DC-CIF, EDC-CIF).
    DiffusionCi,
    /// Diffusion adaptation + convex combination of estimates (D-CIF, ED-CIF).
    DiffusionConvex,
    /// `iterations` synchronous consensus iterations on the local posteriors'
    /// information pairs (the C-/EC-/DEC- baselines).
    Consensus {
        /// Number of iterations `L ≥ 1`.
        iterations: usize,
    },
    /// No fusion: each node keeps its local posterior.
    Local,
}

/// One algorithm: local filter, trigger, untriggered-step options, fusion and
/// the rule of the CI combination.
///
/// ```
/// use edccif_core::{NetworkConfig, Fusion, FusionRule, NodeFilter, Trigger, EtOptions};
/// let edc = NetworkConfig::<f64> {
///     filter: NodeFilter::Cif,
///     trigger: Trigger::SendOnDelta { delta: 0.04 },
///     et: EtOptions::default(),
///     fusion: Fusion::DiffusionCi,
///     rule: FusionRule::CI,
/// };
/// assert!(edc.validate().is_ok());
/// // a rule other than CI needs the CI combination of diffusion
/// let ici = NetworkConfig { rule: "ici".parse()?, ..edc };
/// assert!(ici.validate().is_ok());
/// assert!(NetworkConfig { fusion: Fusion::DiffusionConvex, ..ici }.validate().is_err());
/// # Ok::<(), edccif_core::Error>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct NetworkConfig<T> {
    /// Local filter.
    pub filter: NodeFilter<T>,
    /// Trigger on each sensor → estimator link.
    pub trigger: Trigger<T>,
    /// Untriggered-step policy and gain parameters.
    pub et: EtOptions<T>,
    /// Fusion across the network.
    pub fusion: Fusion,
    /// The rule of the combination under [`Fusion::DiffusionCi`]
    /// ([`fusion_rules`](crate::fusion_rules), `docs/fusion.md`); the paper's
    /// [`FusionRule::CI`] by default.
    #[cfg_attr(feature = "serde", serde(default))]
    pub rule: FusionRule,
}

impl<T: RealField + Copy> NetworkConfig<T> {
    /// Checks the parameters and that the fusion fits the filter (diffusion needs
    /// information-form contributions, i.e. [`NodeFilter::Cif`]).
    pub fn validate(&self) -> Result<()> {
        self.trigger.validate()?;
        self.et.validate()?;
        if let NodeFilter::Cov(LocalFilter::Ukf { alpha, beta, kappa }) = self.filter {
            SigmaRule::unscented(2, alpha, beta, kappa)?;
        }
        match (self.filter, self.fusion) {
            (NodeFilter::Cov(_), Fusion::DiffusionCi | Fusion::DiffusionConvex) => {
                Err(Error::InvalidParameter {
                    what: "fusion",
                    expected:
                        "consensus or local for a covariance-form filter (diffusion needs the CIF)",
                })
            }
            (_, Fusion::Consensus { iterations: 0 }) => Err(Error::InvalidParameter {
                what: "consensus iterations",
                expected: ">= 1",
            }),
            (_, Fusion::DiffusionConvex | Fusion::Consensus { .. } | Fusion::Local)
                if !self.rule.is_paper() =>
            {
                Err(Error::InvalidParameter {
                    what: "fusion rule",
                    expected: "ci unless the fusion is diffusion with CI (the rules replace its combination)",
                })
            }
            _ => Ok(()),
        }
    }
}
