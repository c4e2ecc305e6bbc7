//! The algorithm rows of the paper's tables (ALGORITHM.md §5) and run options.

use std::fmt;
use std::str::FromStr;

use edccif_core::{
    EtOptions, EtPolicy, Fusion, FusionRule, LocalFilter, NetworkConfig, NodeFilter, Trigger,
};
use serde::{Deserialize, Serialize};

pub use crate::delta::{Delta, DEFAULT_NORMALISED_DELTA, PAPER_DELTA};
use crate::error::{Error, Result};
pub use crate::scenario::parse_fusion_rule;
use crate::scenario::{DynamicTrigger, Scenario, UkfParams};

/// One row of the paper's tables.
///
/// ```
/// use edccif_sim::Algorithm;
/// let a: Algorithm = "edc-cif".parse().unwrap();
/// assert_eq!(a, Algorithm::EdcCif);
/// assert_eq!(a.to_string(), "edc-cif");
/// assert_eq!(a.label(), "EDC-CIF");
/// assert!("edc".parse::<Algorithm>().unwrap_err().to_string().contains("ec-ckf"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Algorithm {
    /// CKF, no trigger, consensus.
    CCkf,
    /// EKF, send-on-delta, consensus.
    EcEkf,
    /// UKF (1, 2, 0), send-on-delta, consensus.
    EcUkf,
    /// ET-CKF, send-on-delta, consensus.
    EcCkf,
    /// ET-CKF, dynamic trigger, consensus.
    DecCkf,
    /// CIF, no trigger, diffusion without CI.
    DCif,
    /// CIF, no trigger, diffusion with CI.
    DcCif,
    /// ET-CIF, send-on-delta, diffusion without CI.
    EdCif,
    /// ET-CIF, send-on-delta, diffusion with CI (the paper's method).
    EdcCif,
}

impl Algorithm {
    /// All rows in table order.
    pub const ALL: [Algorithm; 9] = [
        Algorithm::CCkf,
        Algorithm::EcEkf,
        Algorithm::EcUkf,
        Algorithm::EcCkf,
        Algorithm::DecCkf,
        Algorithm::DCif,
        Algorithm::DcCif,
        Algorithm::EdCif,
        Algorithm::EdcCif,
    ];
    /// Names accepted by [`FromStr`], in table order.
    pub const NAMES: [&'static str; 9] = crate::names::ALGORITHMS;

    /// Lower-case name, e.g. `"edc-cif"`.
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// The paper's label, e.g. `"EDC-CIF"`.
    pub fn label(self) -> &'static str {
        [
            "C-CKF", "EC-EKF", "EC-UKF", "EC-CKF", "DEC-CKF", "D-CIF", "DC-CIF", "ED-CIF",
            "EDC-CIF",
        ][self as usize]
    }

    /// Whether the sensors are event-triggered.
    pub fn is_event_triggered(self) -> bool {
        !matches!(self, Algorithm::CCkf | Algorithm::DCif | Algorithm::DcCif)
    }
}

impl fmt::Display for Algorithm {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Algorithm {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        lookup(s, &Self::NAMES, &Self::ALL).ok_or_else(|| Error::UnknownAlgorithm(s.to_string()))
    }
}

/// The entry of `all` whose name (`names`, same order) is `s`, ignoring case,
/// surrounding space and `_` for `-`.
fn lookup<K: Copy>(s: &str, names: &[&str], all: &[K]) -> Option<K> {
    let key = s.trim().to_ascii_lowercase().replace('_', "-");
    names.iter().position(|n| *n == key).map(|i| all[i])
}

/// Fusion override (`fusion=`): a structural one for ablations (e.g. ET-CIF
/// with consensus = "w/o diffusion with CI"), or diffusion whose CI
/// combination uses another rule (`docs/fusion.md`). Written and read as its
/// name.
///
/// ```
/// use edccif_sim::FusionKind;
/// use edccif_core::FusionRule;
/// assert_eq!("ici".parse::<FusionKind>().unwrap(), FusionKind::Rule("ici".parse().unwrap()));
/// assert_eq!("ci".parse::<FusionKind>().unwrap(), FusionKind::DiffusionCi); // the paper's
/// assert_eq!(FusionKind::Rule(FusionRule::EiUnsafe).to_string(), "ei-unsafe");
/// assert!("ei".parse::<FusionKind>().unwrap_err().to_string().contains("ei-unsafe"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FusionKind {
    /// Diffusion adaptation + CI combination (`diffusion-ci`, or `ci`).
    DiffusionCi,
    /// Diffusion adaptation + convex combination.
    DiffusionConvex,
    /// Consensus with the scenario's (or the options') iterations.
    Consensus,
    /// No fusion.
    Local,
    /// Diffusion adaptation + combination by this rule (any rule name but
    /// `ci`, which is [`DiffusionCi`](Self::DiffusionCi)).
    Rule(FusionRule),
}

impl FusionKind {
    /// The name: `diffusion-ci`, `diffusion-convex`, `consensus`, `local` or the rule's.
    pub fn name(self) -> &'static str {
        match self {
            FusionKind::DiffusionCi => "diffusion-ci",
            FusionKind::DiffusionConvex => "diffusion-convex",
            FusionKind::Consensus => "consensus",
            FusionKind::Local => "local",
            FusionKind::Rule(r) => r.name(),
        }
    }
}

impl fmt::Display for FusionKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for FusionKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let key = s.trim().to_ascii_lowercase().replace('_', "-");
        match key.as_str() {
            "diffusion-ci" | "ci" => Ok(FusionKind::DiffusionCi),
            "diffusion-convex" | "diffusion" => Ok(FusionKind::DiffusionConvex),
            "consensus" => Ok(FusionKind::Consensus),
            "local" | "none" => Ok(FusionKind::Local),
            other => FusionRule::from_name(other)
                .map(FusionKind::Rule)
                .ok_or_else(|| Error::UnknownOption {
                    name: format!("fusion={s}"),
                    expected: format!(
                        "one of diffusion-ci, diffusion-convex, consensus, local, or a fusion rule: {}",
                        FusionRule::NAMES.join(", ")
                    ),
                }),
        }
    }
}

impl Serialize for FusionKind {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for FusionKind {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// Parses an ET policy name (`optimal`, `hold`, `skip`).
pub fn parse_policy(s: &str) -> Result<EtPolicy> {
    match s.trim().to_ascii_lowercase().as_str() {
        "optimal" => Ok(EtPolicy::Optimal),
        "hold" => Ok(EtPolicy::Hold),
        "skip" => Ok(EtPolicy::Skip),
        _ => Err(Error::UnknownOption {
            name: format!("et_policy={s}"),
            expected: "one of optimal, hold, skip".into(),
        }),
    }
}

/// A trigger selected by name, overriding the row's own (`trigger="..."`); its
/// threshold is the run's `delta` (each trigger reads it in its own units, see
/// `docs/triggers.md`).
///
/// ```
/// use edccif_sim::TriggerKind;
/// let t: TriggerKind = "sod-inflated".parse().unwrap();
/// assert_eq!(t, TriggerKind::SodInflated);
/// assert_eq!(t.to_string(), "sod-inflated");
/// assert!("nope".parse::<TriggerKind>().unwrap_err().to_string().contains("innovation"));
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TriggerKind {
    /// The paper's send-on-delta with the error-minimised gain (`et_policy` applies).
    Sod,
    /// Send-on-delta, a silent step holds `z_τ` as a fresh measurement (ablation).
    SodHold,
    /// Send-on-delta, a silent step adds nothing (ablation).
    SodSkip,
    /// The dynamic trigger of DEC-CKF (`λ`, `θ` from the scenario).
    Dynamic,
    /// Open-loop stochastic send-on-delta with its exact silent update (Han et al. 2015).
    Stochastic,
    /// Send-on-delta with the silence as `z_τ` plus the δ-ball's covariance.
    SodInflated,
    /// Whitened-innovation trigger with the truncated-Gaussian silent update
    /// (Wu et al. 2013); the node sends `(ẑ, Pzz)` to its sensor each step.
    Innovation,
    /// Every measurement is sent.
    Always,
}

impl TriggerKind {
    /// Every trigger, in the order of [`NAMES`](Self::NAMES).
    pub const ALL: [TriggerKind; 8] = [
        TriggerKind::Sod,
        TriggerKind::SodHold,
        TriggerKind::SodSkip,
        TriggerKind::Dynamic,
        TriggerKind::Stochastic,
        TriggerKind::SodInflated,
        TriggerKind::Innovation,
        TriggerKind::Always,
    ];
    /// Names accepted by [`FromStr`].
    pub const NAMES: [&'static str; 8] = [
        "sod",
        "sod-hold",
        "sod-skip",
        "dynamic",
        "stochastic",
        "sod-inflated",
        "innovation",
        "always",
    ];

    /// Lower-case name, e.g. `"stochastic"`.
    pub fn name(self) -> &'static str {
        Self::NAMES[self as usize]
    }

    /// The threshold used when the run sets no `delta`: the scenario's `δ` for
    /// the send-on-delta family, and for the others the value that gives about
    /// the paper's trigger rate (≈ 54 %) on the 4-node default scenario.
    ///
    /// ```
    /// use edccif_sim::{Scenario, TriggerKind};
    /// let sc = Scenario::paper(4);
    /// assert_eq!(TriggerKind::SodInflated.default_delta(&sc), 0.04);
    /// assert_eq!(TriggerKind::Innovation.default_delta(&sc), 1.2);
    /// ```
    pub fn default_delta(self, sc: &Scenario) -> f64 {
        self.default_delta_for(sc.delta.node(0))
    }

    /// [`default_delta`](Self::default_delta) with the send-on-delta family's
    /// threshold given directly.
    pub fn default_delta_for(self, sod_delta: f64) -> f64 {
        match self {
            TriggerKind::Stochastic => 3.0,
            TriggerKind::Innovation => 1.2,
            _ => sod_delta,
        }
    }

    /// The core trigger with threshold `delta`, and the silent-step policy it
    /// implies (`None`: the run's `et_policy`).
    ///
    /// ```
    /// use edccif_core::{EtPolicy, Trigger};
    /// use edccif_sim::{Scenario, TriggerKind};
    /// let sc = Scenario::paper(4);
    /// assert_eq!(TriggerKind::SodSkip.trigger(0.04, &sc),
    ///            (Trigger::SendOnDelta { delta: 0.04 }, Some(EtPolicy::Skip)));
    /// assert_eq!(TriggerKind::Stochastic.trigger(3.0, &sc).0, Trigger::Stochastic { delta: 3.0 });
    /// ```
    pub fn trigger(self, delta: f64, sc: &Scenario) -> (Trigger<f64>, Option<EtPolicy>) {
        self.trigger_with(delta, &sc.dynamic)
    }

    /// [`trigger`](Self::trigger) with the dynamic trigger's `λ`, `θ` given directly.
    pub fn trigger_with(
        self,
        delta: f64,
        dynamic: &DynamicTrigger,
    ) -> (Trigger<f64>, Option<EtPolicy>) {
        let sod = Trigger::SendOnDelta { delta };
        match self {
            TriggerKind::Sod => (sod, None),
            TriggerKind::SodHold => (sod, Some(EtPolicy::Hold)),
            TriggerKind::SodSkip => (sod, Some(EtPolicy::Skip)),
            TriggerKind::Dynamic => (
                Trigger::Dynamic {
                    delta,
                    lambda: dynamic.lambda,
                    theta: dynamic.theta,
                },
                None,
            ),
            TriggerKind::Stochastic => (Trigger::Stochastic { delta }, None),
            TriggerKind::SodInflated => (Trigger::SendOnDeltaInflated { delta }, None),
            TriggerKind::Innovation => (Trigger::Innovation { delta }, None),
            TriggerKind::Always => (Trigger::Always, None),
        }
    }
}

impl fmt::Display for TriggerKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for TriggerKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        lookup(s, &Self::NAMES, &Self::ALL).ok_or_else(|| Error::UnknownOption {
            name: format!("trigger={s}"),
            expected: format!("one of {}", Self::NAMES.join(", ")),
        })
    }
}

/// Overrides for one run; `None` keeps the scenario's value.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunOptions {
    /// Untriggered-step policy (default `optimal`).
    #[serde(default)]
    pub et_policy: Option<EtPolicy>,
    /// Trigger threshold `δ`, one for every node or one per node.
    #[serde(default)]
    pub delta: Option<Delta>,
    /// The threshold in units of the sensor's noise: the send-on-delta family
    /// compares `ΔᵀR⁻¹Δ` with `δ` ([`Trigger::normalised`]); `None` keeps the
    /// scenario's (default off: the paper's raw squared units).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normalised: Option<bool>,
    /// `σ1`.
    #[serde(default)]
    pub sigma1: Option<f64>,
    /// `σ2`.
    #[serde(default)]
    pub sigma2: Option<f64>,
    /// Consensus iterations `L`.
    #[serde(default)]
    pub consensus_iters: Option<usize>,
    /// Fusion override: a structural fusion (ablations) or a fusion rule of
    /// the CI combination (`docs/fusion.md`); `None` keeps the row's, with the
    /// scenario's rule ([`Scenario::fusion`](crate::Scenario::fusion)) for the
    /// rows that combine with CI.
    #[serde(default)]
    pub fusion: Option<FusionKind>,
    /// Force γ ≡ 1 (every measurement sent), keeping the row's filter and fusion.
    #[serde(default)]
    pub force_trigger: bool,
    /// χ² innovation gate on triggered measurements (see
    /// [`EtOptions::gate`](edccif_core::EtOptions::gate)); `None`: no gate.
    #[serde(default)]
    pub gate: Option<f64>,
    /// Trigger override (`None`: the row's own); `delta` is its threshold.
    #[serde(default)]
    pub trigger: Option<TriggerKind>,
    /// Seed of the stochastic trigger's streams (node i draws from
    /// `(seed, i)`); `None`: 0 ([`monte_carlo`](crate::monte_carlo) uses the
    /// run's simulation seed).
    #[serde(default)]
    pub trigger_seed: Option<u64>,
    /// Threads of the network step: `None` or `Some(1)` the serial step (the
    /// default), `Some(n)` with `n >= 2` the parallel step
    /// ([`crate::parallel`]) on a pool of `n` threads
    /// ([`shared_pool`](crate::parallel::shared_pool)); `Some(0)` is an error.
    /// The numbers are the same bit for bit either way; only large networks
    /// (about 64 nodes and more) run faster (see `docs/guide.md`, "Parallel
    /// network step"). [`monte_carlo`](crate::monte_carlo) already runs its
    /// runs in parallel; this adds threads inside each run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threads: Option<usize>,
    /// The ET-CIF's untriggered contribution in closed form
    /// ([`EtOptions::untriggered_closed_form`](edccif_core::EtOptions::untriggered_closed_form));
    /// `None` keeps the scenario's
    /// ([`Scenario::untriggered_closed_form`](crate::Scenario::untriggered_closed_form),
    /// default on; `Some(false)` the paper's stable form).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub untriggered_closed_form: Option<bool>,
}

/// Builds the core configuration of a row for a scenario.
///
/// ```
/// use edccif_sim::{network_config, Algorithm, RunOptions, Scenario};
/// use edccif_core::{Fusion, NodeFilter};
/// let cfg = network_config(Algorithm::EcCkf, &Scenario::paper(4), &RunOptions::default()).unwrap();
/// assert_eq!(cfg.fusion, Fusion::Consensus { iterations: 5 });
/// let cfg = network_config(Algorithm::EdcCif, &Scenario::paper(4), &RunOptions::default()).unwrap();
/// assert_eq!((cfg.filter, cfg.fusion), (NodeFilter::Cif, Fusion::DiffusionCi));
/// ```
pub fn network_config(
    alg: Algorithm,
    sc: &Scenario,
    opt: &RunOptions,
) -> Result<NetworkConfig<f64>> {
    // The adequate L only for a consensus row (it needs the weights' eigenvalues).
    let iters = match opt.consensus_iters {
        Some(l) => l,
        None => {
            let cfg = row_config(alg, &RowParams::of(sc, 1), opt)?;
            if !matches!(cfg.fusion, Fusion::Consensus { .. }) {
                return Ok(cfg);
            }
            sc.consensus_iterations()?
        }
    };
    row_config(alg, &RowParams::of(sc, iters), opt)
}

/// The row parameters a network needs besides its models and graph: what a
/// [`Scenario`] holds for the built-in networks, given directly for networks of
/// one's own models ([`crate::mixed`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RowParams {
    /// Send-on-delta threshold `δ` (on the squared measurement change, or on
    /// `ΔᵀR⁻¹Δ` when [`normalised`](Self::normalised)); per-node thresholds
    /// come from [`RunOptions::delta`] ([`node_deltas`]).
    pub delta: f64,
    /// `σ1` of the error-minimised gain.
    pub sigma1: f64,
    /// `σ2` of the error-minimised gain.
    pub sigma2: f64,
    /// Consensus iterations `L` (≥ 1) of the consensus rows.
    pub consensus_iters: usize,
    /// Dynamic-trigger `λ`, `θ` (DEC-CKF).
    pub dynamic: DynamicTrigger,
    /// Unscented-transform parameters (EC-UKF).
    pub ukf: UkfParams,
    /// The ET-CIF's untriggered contribution in closed form (default off;
    /// [`EtOptions::untriggered_closed_form`]).
    pub untriggered_closed_form: bool,
    /// The rule of the CI combination of the diffusion-with-CI rows (DC-CIF,
    /// EDC-CIF); the paper's CI by default (`docs/fusion.md`).
    pub fusion_rule: FusionRule,
    /// `delta` in units of the sensor's noise ([`RunOptions::normalised`]).
    pub normalised: bool,
}

impl RowParams {
    /// The paper's defaults (ALGORITHM.md §6): `δ = 0.04`, `σ1 = σ2 = 5·10⁻⁴`,
    /// the dynamic trigger `(λ, θ) = (0.9, 2)`, the UKF `(α, β, κ) = (1, 2, 0)`,
    /// with `consensus_iters` iterations.
    pub fn paper(consensus_iters: usize) -> Self {
        let sc = Scenario::paper(1);
        Self::of(&sc, consensus_iters)
    }

    /// A scenario's parameters with `consensus_iters` iterations.
    pub fn of(sc: &Scenario, consensus_iters: usize) -> Self {
        Self {
            delta: sc.delta.node(0),
            sigma1: sc.sigma1,
            sigma2: sc.sigma2,
            consensus_iters,
            dynamic: sc.dynamic,
            ukf: sc.ukf,
            untriggered_closed_form: sc.untriggered_closed_form,
            fusion_rule: sc.fusion.unwrap_or_default(),
            normalised: sc.normalised,
        }
    }
}

/// Builds the core configuration of a row from its parameters (the run options
/// override them as in [`network_config`], which is this with a scenario's).
///
/// ```
/// use edccif_sim::{row_config, Algorithm, RowParams, RunOptions};
/// use edccif_core::{Fusion, Trigger};
/// let cfg = row_config(Algorithm::EdcCif, &RowParams::paper(3), &RunOptions::default()).unwrap();
/// assert_eq!((cfg.trigger, cfg.fusion), (Trigger::SendOnDelta { delta: 0.04 }, Fusion::DiffusionCi));
/// let cfg = row_config(Algorithm::CCkf, &RowParams::paper(3), &RunOptions::default()).unwrap();
/// assert_eq!(cfg.fusion, Fusion::Consensus { iterations: 3 });
/// ```
pub fn row_config(alg: Algorithm, p: &RowParams, opt: &RunOptions) -> Result<NetworkConfig<f64>> {
    if let Some(t) = opt.threads {
        crate::parallel::check_threads(t)?;
    }
    let normalised = opt.normalised.unwrap_or(p.normalised);
    let delta = match &opt.delta {
        Some(d) => d.node(0),
        None => {
            let family = family_delta(p.delta, p.normalised, normalised);
            opt.trigger.map_or(family, |t| t.default_delta_for(family))
        }
    };
    let (chosen, implied_policy) = match opt.trigger {
        Some(t) => {
            let (tr, pol) = t.trigger_with(delta, &p.dynamic);
            (Some(tr), pol)
        }
        None => (None, None),
    };
    let et = EtOptions {
        policy: implied_policy.or(opt.et_policy).unwrap_or_default(),
        sigma1: opt.sigma1.unwrap_or(p.sigma1),
        sigma2: opt.sigma2.unwrap_or(p.sigma2),
        gate: opt.gate,
        untriggered_closed_form: opt
            .untriggered_closed_form
            .unwrap_or(p.untriggered_closed_form),
    };
    let iters = opt.consensus_iters.unwrap_or(p.consensus_iters);
    let sod = Trigger::SendOnDelta { delta };
    let ukf = LocalFilter::Ukf {
        alpha: p.ukf.alpha,
        beta: p.ukf.beta,
        kappa: p.ukf.kappa,
    };
    use Algorithm::*;
    let (filter, trigger, fusion) = match alg {
        CCkf => (
            NodeFilter::Cov(LocalFilter::Ckf),
            Trigger::Always,
            Fusion::Consensus { iterations: iters },
        ),
        EcEkf => (
            NodeFilter::Cov(LocalFilter::Ekf),
            sod,
            Fusion::Consensus { iterations: iters },
        ),
        EcUkf => (
            NodeFilter::Cov(ukf),
            sod,
            Fusion::Consensus { iterations: iters },
        ),
        EcCkf => (
            NodeFilter::Cov(LocalFilter::Ckf),
            sod,
            Fusion::Consensus { iterations: iters },
        ),
        DecCkf => (
            NodeFilter::Cov(LocalFilter::Ckf),
            Trigger::Dynamic {
                delta,
                lambda: p.dynamic.lambda,
                theta: p.dynamic.theta,
            },
            Fusion::Consensus { iterations: iters },
        ),
        DCif => (NodeFilter::Cif, Trigger::Always, Fusion::DiffusionConvex),
        DcCif => (NodeFilter::Cif, Trigger::Always, Fusion::DiffusionCi),
        EdCif => (NodeFilter::Cif, sod, Fusion::DiffusionConvex),
        EdcCif => (NodeFilter::Cif, sod, Fusion::DiffusionCi),
    };
    // A run's `fusion=` replaces the row's fusion (and its rule); without it
    // the rows that combine with CI take the scenario's rule.
    let (fusion, rule) = match opt.fusion {
        None if fusion == Fusion::DiffusionCi => (fusion, p.fusion_rule),
        None => (fusion, FusionRule::CI),
        Some(FusionKind::DiffusionCi) => (Fusion::DiffusionCi, FusionRule::CI),
        Some(FusionKind::Rule(r)) => (Fusion::DiffusionCi, r),
        Some(FusionKind::DiffusionConvex) => (Fusion::DiffusionConvex, FusionRule::CI),
        Some(FusionKind::Consensus) => (Fusion::Consensus { iterations: iters }, FusionRule::CI),
        Some(FusionKind::Local) => (Fusion::Local, FusionRule::CI),
    };
    let trigger = if opt.force_trigger {
        Trigger::Always
    } else if normalised {
        chosen.unwrap_or(trigger).normalised()
    } else {
        chosen.unwrap_or(trigger)
    };
    let cfg = NetworkConfig {
        filter,
        trigger,
        et,
        fusion,
        rule,
    };
    cfg.validate().map_err(|e| match e {
        edccif_core::Error::InvalidParameter { what, expected } => Error::Value {
            what: what.to_string(),
            problem: format!("expected {expected}"),
        },
        other => other.into(),
    })?;
    Ok(cfg)
}

/// The send-on-delta family's threshold when the run sets none: the row
/// parameters' `δ` when its units are the run's, else the default of the run's
/// units ([`PAPER_DELTA`] raw, [`DEFAULT_NORMALISED_DELTA`] normalised).
fn family_delta(delta: f64, params_normalised: bool, normalised: bool) -> f64 {
    if params_normalised == normalised {
        delta
    } else if normalised {
        DEFAULT_NORMALISED_DELTA
    } else {
        PAPER_DELTA
    }
}

/// The per-node thresholds of a run on `nodes` nodes, checked: `opt.delta` when
/// it is a list; else `scenario` (the scenario's `δ` and whether it is
/// normalised) when that is a list, the run reads it (no trigger with a default
/// of its own, `stochastic` or `innovation`, and the same units) and the row has
/// a threshold. `None`: every node uses the configuration's one `δ`.
///
/// ```
/// use edccif_sim::{node_deltas, Algorithm, Delta, RunOptions, TriggerKind};
/// let sc = Delta::PerNode(vec![0.04, 0.01]);
/// let opt = RunOptions::default();
/// assert_eq!(node_deltas(Algorithm::EdcCif, Some((&sc, false)), &opt, 2).unwrap(), Some(vec![0.04, 0.01]));
/// // the stochastic trigger has its own default threshold
/// let st = RunOptions { trigger: Some(TriggerKind::Stochastic), ..RunOptions::default() };
/// assert_eq!(node_deltas(Algorithm::EdcCif, Some((&sc, false)), &st, 2).unwrap(), None);
/// let bad = RunOptions { delta: Some(Delta::PerNode(vec![0.04])), ..RunOptions::default() };
/// assert!(node_deltas(Algorithm::EdcCif, None, &bad, 2).is_err());
/// ```
pub fn node_deltas(
    alg: Algorithm,
    scenario: Option<(&Delta, bool)>,
    opt: &RunOptions,
    nodes: usize,
) -> Result<Option<Vec<f64>>> {
    if let Some(d) = &opt.delta {
        d.check(nodes)?;
        return Ok(d.per_node().map(<[f64]>::to_vec));
    }
    let Some((d, sc_normalised)) = scenario else {
        return Ok(None);
    };
    d.check(nodes)?;
    let own_default = matches!(
        opt.trigger,
        Some(TriggerKind::Stochastic | TriggerKind::Innovation)
    );
    let same_units = opt.normalised.is_none_or(|n| n == sc_normalised);
    let sends_all = opt.force_trigger
        || matches!(opt.trigger, Some(TriggerKind::Always))
        || (opt.trigger.is_none() && !alg.is_event_triggered());
    if own_default || !same_units || sends_all {
        return Ok(None);
    }
    Ok(d.per_node().map(<[f64]>::to_vec))
}

/// The configuration node `node` of a scenario network runs: [`network_config`]
/// with the node's own threshold when the run has one per node ([`node_deltas`]),
/// for a node driven on its own (one process per node, a sensor's trigger).
///
/// ```
/// use edccif_sim::{node_config, Algorithm, Delta, RunOptions, Scenario};
/// use edccif_core::Trigger;
/// let sc = Scenario { delta: Delta::PerNode(vec![0.04, 0.01, 0.09]), ..Scenario::paper(3) };
/// let cfg = node_config(Algorithm::EdcCif, &sc, &RunOptions::default(), 1).unwrap();
/// assert_eq!(cfg.trigger, Trigger::SendOnDelta { delta: 0.01 });
/// assert!(node_config(Algorithm::EdcCif, &sc, &RunOptions::default(), 3).is_err());
/// ```
pub fn node_config(
    alg: Algorithm,
    sc: &Scenario,
    opt: &RunOptions,
    node: usize,
) -> Result<NetworkConfig<f64>> {
    let k = sc.nodes();
    if node >= k {
        return Err(Error::Value {
            what: "node".into(),
            problem: format!("expected an index in 0..{k}, got {node}"),
        });
    }
    let mut cfg = network_config(alg, sc, opt)?;
    if let Some(d) = node_deltas(alg, Some((&sc.delta, sc.normalised)), opt, k)? {
        cfg.trigger = cfg.trigger.with_delta(d[node])?;
    }
    Ok(cfg)
}
