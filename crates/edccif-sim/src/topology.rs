//! Communication topologies, their max-degree weights and the "adequate" number
//! of consensus iterations.

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::error::{scenario_err, Error, Result};

/// How the estimators are connected (undirected).
///
/// In TOML: `topology = { kind = "ring" }` (or the name alone, `topology =
/// "ring"`), `{ kind = "star", center = 2 }`, `{ kind = "random-geometric",
/// radius = 0.5, seed = 3 }`, `{ kind = "custom", adjacency = [[false, true],
/// [true, false]] }` (or the adjacency alone, `topology = [[0, 1], [1, 0]]`;
/// `0`/`1` or booleans), optionally with its own combination weights
/// `weights = [[0.5, 0.5], [0.5, 0.5]]` (default: the max-degree weights of
/// the adjacency). Keys a kind does not have are errors.
///
/// ```
/// use edccif_sim::Topology;
/// #[derive(serde::Deserialize)]
/// struct F { topology: Topology }
/// let t = |s: &str| toml::from_str::<F>(s).map(|f| f.topology);
/// assert_eq!(t("topology = \"line\"").unwrap(), Topology::Line);
/// assert_eq!(t("topology = { kind = \"star\", center = 2 }").unwrap(), Topology::Star { center: 2 });
/// assert!(t("topology = { kind = \"ring\", center = 2 }").unwrap_err().to_string().contains("center"));
/// assert_eq!(t("topology = [[0, 1], [1, 0]]").unwrap(),
///            Topology::Custom { adjacency: vec![vec![false, true], vec![true, false]], weights: None });
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(
    tag = "kind",
    rename_all = "kebab-case",
    deny_unknown_fields,
    from = "TopologyFile"
)]
pub enum Topology {
    /// `i ↔ i±1 mod N` (N = 2: one edge; N = 3: complete).
    Ring,
    /// `i ↔ i+1`.
    Line,
    /// Node `center` (default 0) connected to every other node.
    Star {
        /// The hub.
        #[serde(default, skip_serializing_if = "is_zero")]
        center: usize,
    },
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
    /// Explicit symmetric adjacency (`N × N`, no self-loops), optionally with
    /// explicit combination weights.
    Custom {
        /// `adjacency[i][j]`: i and j communicate.
        adjacency: Vec<Vec<bool>>,
        /// Combination weights `C` (`N × N`): symmetric, non-negative, rows summing
        /// to 1, `c_ij > 0` exactly on the edges (`i ≠ j`); `None`: max-degree
        /// weights ([`weights`]).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        weights: Option<Vec<Vec<f64>>>,
    },
}

fn is_zero(v: &usize) -> bool {
    *v == 0
}

/// A topology as a file gives it: a table with `kind`, a kind's name, or an
/// adjacency matrix.
#[derive(JsonSchema)]
#[serde(untagged)]
enum TopologyFile {
    /// `{ kind = ..., ... }`.
    Table(TopologyTable),
    /// `"ring"`, `"line"`, `"star"` or `"complete"`.
    Name(TopologyName),
    /// The adjacency of a custom topology (booleans or 0/1).
    Adjacency(Vec<Vec<AdjacencyEntry>>),
}

/// The kinds that need no parameter.
#[derive(JsonSchema, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum TopologyName {
    Ring,
    Line,
    Star,
    Complete,
}

/// An adjacency entry: a boolean or 0/1.
#[derive(JsonSchema)]
#[serde(untagged)]
#[allow(dead_code)]
enum AdjacencyEntry {
    Bool(bool),
    /// `0` (false) or `1` (true).
    Int(u8),
}

/// The table form, with every kind's keys checked.
#[derive(JsonSchema, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
enum TopologyTable {
    Ring {},
    Line {},
    Star {
        #[serde(default)]
        center: usize,
    },
    Complete {},
    RandomGeometric {
        radius: f64,
        seed: u64,
    },
    Custom {
        #[serde(deserialize_with = "adjacency_rows")]
        #[schemars(with = "Vec<Vec<AdjacencyEntry>>")]
        adjacency: Vec<Vec<bool>>,
        #[serde(default)]
        weights: Option<Vec<Vec<f64>>>,
    },
}

/// Rows of booleans or 0/1 numbers.
fn adjacency_rows<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> std::result::Result<Vec<Vec<bool>>, D::Error> {
    let rows: Vec<Vec<serde_json::Value>> = Deserialize::deserialize(d)?;
    rows.iter()
        .enumerate()
        .map(|(i, r)| {
            r.iter()
                .enumerate()
                .map(|(j, v)| match v {
                    serde_json::Value::Bool(b) => Ok(*b),
                    serde_json::Value::Number(n) if n.as_f64() == Some(0.0) => Ok(false),
                    serde_json::Value::Number(n) if n.as_f64() == Some(1.0) => Ok(true),
                    other => Err(serde::de::Error::custom(format!(
                        "adjacency[{i}][{j}]: expected true/false or 0/1, got {other}"
                    ))),
                })
                .collect()
        })
        .collect()
}

impl<'de> Deserialize<'de> for TopologyFile {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = TopologyFile;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(
                    "a topology: a table with `kind`, a name (\"ring\", \"line\", \"star\", \"complete\") or an adjacency matrix",
                )
            }
            fn visit_str<E: serde::de::Error>(
                self,
                s: &str,
            ) -> std::result::Result<TopologyFile, E> {
                TopologyName::deserialize(serde::de::value::StrDeserializer::<E>::new(s))
                    .map(TopologyFile::Name)
                    .map_err(|_| {
                        E::custom(format!(
                            "unknown topology {s:?}; a name is one of ring, line, star, complete \
                             (random-geometric and custom need a table with their parameters)"
                        ))
                    })
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                map: A,
            ) -> std::result::Result<TopologyFile, A::Error> {
                TopologyTable::deserialize(serde::de::value::MapAccessDeserializer::new(map))
                    .map(TopologyFile::Table)
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                seq: A,
            ) -> std::result::Result<TopologyFile, A::Error> {
                adjacency_rows(serde::de::value::SeqAccessDeserializer::new(seq)).map(|a| {
                    TopologyFile::Adjacency(
                        a.into_iter()
                            .map(|r| r.into_iter().map(AdjacencyEntry::Bool).collect())
                            .collect(),
                    )
                })
            }
        }
        d.deserialize_any(V)
    }
}

impl From<TopologyFile> for Topology {
    fn from(f: TopologyFile) -> Self {
        match f {
            TopologyFile::Name(TopologyName::Ring)
            | TopologyFile::Table(TopologyTable::Ring {}) => Topology::Ring,
            TopologyFile::Name(TopologyName::Line)
            | TopologyFile::Table(TopologyTable::Line {}) => Topology::Line,
            TopologyFile::Name(TopologyName::Star) => Topology::Star { center: 0 },
            TopologyFile::Table(TopologyTable::Star { center }) => Topology::Star { center },
            TopologyFile::Name(TopologyName::Complete)
            | TopologyFile::Table(TopologyTable::Complete {}) => Topology::Complete,
            TopologyFile::Table(TopologyTable::RandomGeometric { radius, seed }) => {
                Topology::RandomGeometric { radius, seed }
            }
            TopologyFile::Table(TopologyTable::Custom { adjacency, weights }) => {
                Topology::Custom { adjacency, weights }
            }
            TopologyFile::Adjacency(rows) => Topology::Custom {
                adjacency: rows
                    .into_iter()
                    .map(|r| {
                        r.into_iter()
                            .map(|e| {
                                matches!(e, AdjacencyEntry::Bool(true) | AdjacencyEntry::Int(1))
                            })
                            .collect()
                    })
                    .collect(),
                weights: None,
            },
        }
    }
}

impl Topology {
    /// The row-major `n × n` adjacency; validated (symmetric, no self-loops, connected).
    ///
    /// ```
    /// use edccif_sim::Topology;
    /// let a = Topology::Ring.adjacency(4).unwrap();
    /// assert_eq!(a.iter().filter(|e| **e).count(), 8);
    /// assert!(edccif_sim::Topology::Custom { adjacency: vec![vec![false, false], vec![false, false]], weights: None }
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
            Topology::Star { center } => {
                if *center >= n {
                    return Err(scenario_err(
                        "topology.center",
                        format!("expected a node index in 0..{n}, got {center}"),
                    ));
                }
                for i in 0..n {
                    edge(*center, i, &mut a);
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
            Topology::Custom { adjacency, .. } => {
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

impl Topology {
    /// The validated combination weights (row-major `n × n`): the custom weights
    /// of a [`Topology::Custom`] that has them (checked by [`validate_weights`]),
    /// otherwise the max-degree weights of the adjacency.
    ///
    /// ```
    /// use edccif_sim::Topology;
    /// let adjacency = vec![vec![false, true], vec![true, false]];
    /// let t = Topology::Custom { adjacency: adjacency.clone(), weights: Some(vec![vec![0.75, 0.25], vec![0.25, 0.75]]) };
    /// assert_eq!(t.weights(2).unwrap(), vec![0.75, 0.25, 0.25, 0.75]);
    /// // rows must sum to 1
    /// let t = Topology::Custom { adjacency, weights: Some(vec![vec![0.75, 0.5], vec![0.5, 0.75]]) };
    /// assert!(t.weights(2).unwrap_err().to_string().contains("sum"));
    /// ```
    pub fn weights(&self, n: usize) -> Result<Vec<f64>> {
        let a = self.adjacency(n)?;
        match self {
            Topology::Custom {
                weights: Some(w), ..
            } => {
                if w.len() != n || w.iter().any(|r| r.len() != n) {
                    return Err(Error::Shape {
                        what: "topology.weights".into(),
                        expected: format!("({n}, {n}) (one row and column per sensor)"),
                        got: format!(
                            "({}, {:?})",
                            w.len(),
                            w.iter().map(Vec::len).collect::<Vec<_>>()
                        ),
                    });
                }
                let flat: Vec<f64> = w.iter().flatten().copied().collect();
                validate_weights(&flat, &a, n)?;
                Ok(flat)
            }
            _ => weights(&a, n),
        }
    }
}

/// Tolerance of [`validate_weights`] on symmetry and row sums.
pub const WEIGHT_TOLERANCE: f64 = 1e-9;

/// Checks combination weights `c` (row-major `n × n`) against a validated
/// adjacency: finite and `≥ 0`; `c_ij > 0` exactly where `i ≠ j` are neighbours;
/// symmetric and every row summing to 1 (so doubly stochastic), both to
/// [`WEIGHT_TOLERANCE`]. The error ([`Error::Graph`]) names the entry or row.
///
/// ```
/// use edccif_sim::topology::validate_weights;
/// let a = [false, true, true, false];
/// assert!(validate_weights(&[0.5, 0.5, 0.5, 0.5], &a, 2).is_ok());
/// assert!(validate_weights(&[0.6, 0.4, 0.5, 0.5], &a, 2).unwrap_err().to_string().contains("symmetric"));
/// assert!(validate_weights(&[1.0, 0.0, 0.0, 1.0], &a, 2).unwrap_err().to_string().contains("edge"));
/// ```
pub fn validate_weights(c: &[f64], adjacency: &[bool], n: usize) -> Result<()> {
    if c.len() != n * n || adjacency.len() != n * n {
        return Err(Error::Shape {
            what: "weights".into(),
            expected: format!("({n}, {n})"),
            got: format!("{} values", c.len()),
        });
    }
    let graph = |what: String, problem: String| Error::Graph { what, problem };
    for i in 0..n {
        for j in 0..n {
            let v = c[i * n + j];
            if !(v.is_finite() && v >= 0.0) {
                return Err(graph(
                    format!("weights[{i}][{j}]"),
                    format!("must be finite and >= 0, got {v}"),
                ));
            }
            if i != j && adjacency[i * n + j] != (v > 0.0) {
                return Err(graph(
                    format!("weights[{i}][{j}]"),
                    if v > 0.0 {
                        format!("is {v} but nodes {i} and {j} are not neighbours (no edge in the adjacency); weights must be > 0 exactly on the edges")
                    } else {
                        format!("is 0 but nodes {i} and {j} share an edge; weights must be > 0 exactly on the edges")
                    },
                ));
            }
            let t = c[j * n + i];
            if (v - t).abs() > WEIGHT_TOLERANCE {
                return Err(graph(
                    format!("weights[{i}][{j}]"),
                    format!("the weight matrix must be symmetric: weights[{i}][{j}] = {v} but weights[{j}][{i}] = {t}"),
                ));
            }
        }
        let sum: f64 = c[i * n..(i + 1) * n].iter().sum();
        if (sum - 1.0).abs() > WEIGHT_TOLERANCE {
            return Err(graph(
                format!("weights row {i}"),
                format!("must sum to 1 (row-stochastic), sums to {sum}"),
            ));
        }
    }
    Ok(())
}

/// The adjacency implied by weights (row-major `n × n`): `i ≠ j` are neighbours
/// where `c_ij > 0` or `c_ji > 0` (so an asymmetric support is caught by
/// [`validate_weights`], not hidden).
pub fn adjacency_of_weights(c: &[f64], n: usize) -> Vec<bool> {
    let mut a = vec![false; n * n];
    for i in 0..n {
        for j in 0..n {
            if i != j {
                a[i * n + j] = c[i * n + j] > 0.0 || c[j * n + i] > 0.0;
            }
        }
    }
    a
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
