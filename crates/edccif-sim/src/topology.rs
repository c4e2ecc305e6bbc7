//! Communication topologies, their max-degree weights and the "adequate" number
//! of consensus iterations.

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{scenario_err, Error, Result};

/// How the estimators are connected (undirected).
///
/// In TOML: `topology = { kind = "ring" }`, `{ kind = "random-geometric", radius = 0.5, seed = 3 }`,
/// `{ kind = "custom", adjacency = [[false, true], [true, false]] }`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Topology {
    /// `i ↔ i±1 mod N` (N = 2: one edge; N = 3: complete).
    Ring,
    /// `i ↔ i+1`.
    Line,
    /// Node 0 connected to every other node.
    Star,
    /// Every pair connected.
    Complete,
    /// Nodes at seeded uniform points of the unit square, connected within
    /// `radius`; the first connected draw of seeds `seed, seed+1, …` (at most 1000).
    RandomGeometric {
        /// Connection radius in the unit square.
        radius: f64,
        /// Seed of the first draw.
        seed: u64,
    },
    /// Explicit symmetric adjacency (`N × N`, no self-loops).
    Custom {
        /// `adjacency[i][j]`: i and j communicate.
        adjacency: Vec<Vec<bool>>,
    },
}

impl Topology {
    /// The row-major `n × n` adjacency; validated (symmetric, no self-loops, connected).
    ///
    /// ```
    /// use edccif_sim::Topology;
    /// let a = Topology::Ring.adjacency(4).unwrap();
    /// assert_eq!(a.iter().filter(|e| **e).count(), 8);
    /// assert!(edccif_sim::Topology::Custom { adjacency: vec![vec![false, false], vec![false, false]] }
    ///     .adjacency(2).is_err());
    /// ```
    pub fn adjacency(&self, n: usize) -> Result<Vec<bool>> {
        if n == 0 {
            return Err(scenario_err("sensors", "at least one node is needed"));
        }
        let mut a = vec![false; n * n];
        let edge = |i: usize, j: usize, a: &mut Vec<bool>| {
            if i != j {
                a[i * n + j] = true;
                a[j * n + i] = true;
            }
        };
        match self {
            Topology::Ring => {
                for i in 0..n {
                    edge(i, (i + 1) % n, &mut a);
                }
            }
            Topology::Line => {
                for i in 0..n.saturating_sub(1) {
                    edge(i, i + 1, &mut a);
                }
            }
            Topology::Star => {
                for i in 1..n {
                    edge(0, i, &mut a);
                }
            }
            Topology::Complete => {
                for i in 0..n {
                    for j in 0..n {
                        edge(i, j, &mut a);
                    }
                }
            }
            Topology::RandomGeometric { radius, seed } => {
                if !(radius.is_finite() && *radius > 0.0) {
                    return Err(scenario_err("topology.radius", "must be finite and > 0"));
                }
                for attempt in 0..1000u64 {
                    let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_add(attempt));
                    let pts: Vec<(f64, f64)> =
                        (0..n).map(|_| (rng.random(), rng.random())).collect();
                    let mut b = vec![false; n * n];
                    for i in 0..n {
                        for j in (i + 1)..n {
                            let d = (pts[i].0 - pts[j].0).hypot(pts[i].1 - pts[j].1);
                            if d <= *radius {
                                b[i * n + j] = true;
                                b[j * n + i] = true;
                            }
                        }
                    }
                    if edccif_core::fusion::validate_adjacency(&b, n).is_ok() {
                        return Ok(b);
                    }
                }
                return Err(scenario_err(
                    "topology",
                    format!("no connected random geometric graph of {n} nodes with radius {radius} in 1000 seeds; use a larger radius"),
                ));
            }
            Topology::Custom { adjacency } => {
                if adjacency.len() != n || adjacency.iter().any(|r| r.len() != n) {
                    return Err(Error::Shape {
                        what: "topology.adjacency".into(),
                        expected: format!("({n}, {n}) (one row and column per sensor)"),
                        got: format!(
                            "({}, {:?})",
                            adjacency.len(),
                            adjacency.iter().map(Vec::len).collect::<Vec<_>>()
                        ),
                    });
                }
                for (i, row) in adjacency.iter().enumerate() {
                    a[i * n..(i + 1) * n].copy_from_slice(row);
                }
            }
        }
        edccif_core::fusion::validate_adjacency(&a, n)?;
        Ok(a)
    }
}

/// Max-degree weights (row-major `n × n`) for a validated adjacency.
pub fn weights(adjacency: &[bool], n: usize) -> Result<Vec<f64>> {
    let mut w = vec![0.0; n * n];
    edccif_core::fusion::max_degree_weights(adjacency, n, &mut w)?;
    Ok(w)
}

/// Second-largest eigenvalue modulus of a symmetric weight matrix.
pub fn lambda2(weights: &[f64], n: usize) -> f64 {
    if n < 2 {
        return 0.0;
    }
    let m = DMatrix::from_row_slice(n, n, weights);
    let mut ev: Vec<f64> = m
        .symmetric_eigen()
        .eigenvalues
        .iter()
        .map(|v| v.abs())
        .collect();
    ev.sort_by(|a, b| b.total_cmp(a));
    ev[1]
}

/// The "adequate" number of consensus iterations (ALGORITHM.md §5):
/// `L = max(1, ⌈ln 0.01 / ln |λ2(C)|⌉)` (`λ2 = 0 → 1`).
///
/// ```
/// use edccif_sim::{topology::{adequate_consensus_iterations, weights}, Topology};
/// for (n, l) in [(4, 5), (8, 22)] {
///     let w = weights(&Topology::Ring.adjacency(n).unwrap(), n).unwrap();
///     assert_eq!(adequate_consensus_iterations(&w, n), l);
/// }
/// ```
pub fn adequate_consensus_iterations(weights: &[f64], n: usize) -> usize {
    let l2 = lambda2(weights, n);
    if l2 < 1e-12 {
        return 1;
    }
    if l2 >= 1.0 - 1e-15 {
        return usize::MAX;
    }
    (0.01f64.ln() / l2.ln()).ceil().max(1.0) as usize
}
