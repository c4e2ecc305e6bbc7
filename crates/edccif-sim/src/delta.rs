//! Trigger thresholds: a scenario's or a run's `δ` ([`Delta`]) and the
//! defaults the rows and the normalised triggers start from.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The default threshold of the send-on-delta family when it is normalised
/// (`normalised`: `δ` on `ΔᵀR⁻¹Δ`, in units of the sensor's noise) and the run
/// sets none: a change of 4 σ in one component, which gives about the paper's
/// trigger rate on the 4-node default scenario (56.1 % over seeds 0–11, against
/// 55.4 % for the raw 0.04), as the other triggers' defaults
/// ([`TriggerKind::default_delta`](crate::TriggerKind::default_delta)). Sensors that see slower changes need a
/// smaller one (`docs/triggers.md`, "Normalised thresholds").
pub const DEFAULT_NORMALISED_DELTA: f64 = 16.0;

/// The paper's send-on-delta threshold `δ = 0.04` (ALGORITHM.md §6), in the
/// measurement's raw squared units.
pub const PAPER_DELTA: f64 = 0.04;

/// A trigger threshold `δ`: one value for every node, or one per node (TOML
/// `delta = 0.04` or `delta = [0.04, 0.01, 0.04]`).
///
/// ```
/// use edccif_sim::Delta;
/// let d: Delta = serde_json::from_str("[0.04, 0.01]").unwrap();
/// assert_eq!(d, Delta::PerNode(vec![0.04, 0.01]));
/// assert_eq!((d.node(1), d.per_node()), (0.01, Some(&[0.04, 0.01][..])));
/// assert!(d.check(2).is_ok());
/// assert_eq!(d.check(3).unwrap_err().to_string(),
///            "delta: has 2 values for 3 nodes; expected one per node (or one number for every node)");
/// assert!(Delta::PerNode(vec![0.04, f64::NAN]).check(2).unwrap_err().to_string().starts_with("delta[1]"));
/// assert_eq!(Delta::from(0.04), Delta::All(0.04));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(untagged)]
pub enum Delta {
    /// One `δ` for every node.
    All(f64),
    /// `δ_i` for node i.
    PerNode(Vec<f64>),
}

impl Default for Delta {
    fn default() -> Self {
        Delta::All(PAPER_DELTA)
    }
}

impl From<f64> for Delta {
    fn from(d: f64) -> Self {
        Delta::All(d)
    }
}

impl From<Vec<f64>> for Delta {
    fn from(d: Vec<f64>) -> Self {
        Delta::PerNode(d)
    }
}

impl Delta {
    /// Node i's threshold (the one value, or the i-th; node 0's when `i` is out
    /// of range of a list: [`check`](Self::check) first).
    pub fn node(&self, i: usize) -> f64 {
        match self {
            Delta::All(d) => *d,
            Delta::PerNode(v) => v.get(i).or(v.first()).copied().unwrap_or(f64::NAN),
        }
    }

    /// The per-node list, if this is one.
    pub fn per_node(&self) -> Option<&[f64]> {
        match self {
            Delta::All(_) => None,
            Delta::PerNode(v) => Some(v),
        }
    }

    /// Checks the values for a network of `nodes` nodes: each finite and `> 0`,
    /// and a list has one per node. Errors name the entry (`delta[2]`).
    pub fn check(&self, nodes: usize) -> Result<()> {
        let bad = |what: String, v: f64| Error::Value {
            what,
            problem: format!("expected a finite number > 0, got {v}"),
        };
        match self {
            Delta::All(d) if !(d.is_finite() && *d > 0.0) => Err(bad("delta".into(), *d)),
            Delta::All(_) => Ok(()),
            Delta::PerNode(v) => {
                if v.len() != nodes {
                    return Err(Error::Value {
                        what: "delta".into(),
                        problem: format!(
                            "has {} values for {nodes} nodes; expected one per node (or one \
                             number for every node)",
                            v.len()
                        ),
                    });
                }
                match v.iter().position(|d| !(d.is_finite() && *d > 0.0)) {
                    Some(i) => Err(bad(format!("delta[{i}]"), v[i])),
                    None => Ok(()),
                }
            }
        }
    }
}
