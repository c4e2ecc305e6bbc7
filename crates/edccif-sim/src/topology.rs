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
    /// The row-major `n × n` adjacency; validated (symmetric, no self-loops,
    /// connected). Dense: refused with [`Error::TooLarge`] when `n × n` does
    /// not fit in memory ([`neighbours`](Self::neighbours) is the sparse form).
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
        let Topology::Custom { adjacency, .. } = self else {
            check_dense(n, 1, "adjacency")?;
            return Ok(self.neighbours(n)?.adjacency());
        };
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
        let a: Vec<bool> = adjacency.iter().flatten().copied().collect();
        edccif_core::fusion::validate_adjacency(&a, n)?;
        Ok(a)
    }

    /// Upper bound of the entries of the neighbour lists of `n` nodes (each
    /// node and its neighbours): `3n` for a ring or a line, `3n` for a star,
    /// `n²` for the complete graph and a custom adjacency (given as `n × n`
    /// already), and `None` for a random geometric graph (counted when drawn).
    pub fn entries_bound(&self, n: usize) -> Option<u128> {
        match self {
            Topology::Ring | Topology::Line | Topology::Star { .. } => Some(3 * n as u128),
            Topology::Complete | Topology::Custom { .. } => Some(crate::limits::product(&[n, n])),
            Topology::RandomGeometric { .. } => None,
        }
    }

    /// The validated graph and combination weights as neighbour lists: memory
    /// O(n + edges), where [`adjacency`](Self::adjacency) and
    /// [`weights`](Self::weights) are `n × n`. The weights are those of
    /// [`weights`](Self::weights), bit for bit. The size (nodes × (degree +
    /// 1)) is checked against the memory available before the lists are
    /// allocated ([`Error::TooLarge`]).
    ///
    /// ```
    /// use edccif_sim::Topology;
    /// let g = Topology::Ring.neighbours(100_000).unwrap();
    /// assert_eq!(g.row(0), &[0, 1, 99_999]);
    /// let w = g.row_weights(0);
    /// assert_eq!(w[1..], [1.0 / 3.0, 1.0 / 3.0]);
    /// assert!((w[0] - 1.0 / 3.0).abs() < 1e-15); // the self weight: 1 − the others'
    /// assert_eq!(w, Topology::Ring.weights(5).unwrap()[..5].iter().copied()
    ///     .filter(|&c| c > 0.0).collect::<Vec<_>>());
    /// let small = Topology::Star { center: 1 }.neighbours(4).unwrap();
    /// assert_eq!(small.to_dense().unwrap(), Topology::Star { center: 1 }.weights(4).unwrap());
    /// assert!(Topology::Star { center: 4 }.neighbours(4).is_err());
    /// ```
    pub fn neighbours(&self, n: usize) -> Result<NeighbourLists> {
        if n == 0 {
            return Err(scenario_err("sensors", "at least one node is needed"));
        }
        if let Some(e) = self.entries_bound(n) {
            check_lists(n, e)?;
        }
        let build = |f: &dyn Fn(usize, &mut Vec<usize>)| -> Result<NeighbourLists> {
            NeighbourLists::max_degree(n, f)
        };
        match self {
            Topology::Ring => build(&|i, out| {
                if n > 1 {
                    out.extend([(i + n - 1) % n, (i + 1) % n]);
                }
            }),
            Topology::Line => build(&|i, out| {
                if i > 0 {
                    out.push(i - 1);
                }
                if i + 1 < n {
                    out.push(i + 1);
                }
            }),
            Topology::Star { center } => {
                let c = *center;
                if c >= n {
                    return Err(scenario_err(
                        "topology.center",
                        format!("expected a node index in 0..{n}, got {c}"),
                    ));
                }
                build(&|i, out| {
                    if i == c {
                        out.extend(0..n);
                    } else {
                        out.push(c);
                    }
                })
            }
            Topology::Complete => build(&|_, out| out.extend(0..n)),
            Topology::RandomGeometric { radius, seed } => random_geometric(n, *radius, *seed),
            Topology::Custom { .. } => NeighbourLists::from_dense(&self.weights(n)?, n),
        }
    }
}

/// The first connected random geometric graph of the draws `seed, seed+1, …`
/// (at most 1000): `n` uniform points of the unit square, `i ↔ j` when their
/// distance is `≤ radius`. The pairs are found through a grid of cells at
/// least `radius` wide (each point against the points of its own and the
/// adjacent cells), the same pairs as a test of every pair.
fn random_geometric(n: usize, radius: f64, seed: u64) -> Result<NeighbourLists> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(scenario_err("topology.radius", "must be finite and > 0"));
    }
    check_lists(n, n as u128)?;
    // Cells of width `cell ≥ radius`, at most ~n of them.
    // (a relative margin far above rounding keeps points within `radius` in
    // adjacent cells)
    let side = ((1.0 - 1e-9) / radius)
        .floor()
        .clamp(1.0, (n as f64).sqrt().ceil() + 1.0) as usize;
    let cell_of = |v: f64| ((v * side as f64) as usize).min(side - 1);
    for attempt in 0..1000u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed.wrapping_add(attempt));
        let pts: Vec<(f64, f64)> = (0..n).map(|_| (rng.random(), rng.random())).collect();
        let mut by_cell: Vec<Vec<usize>> = vec![Vec::new(); side * side];
        for (i, p) in pts.iter().enumerate() {
            by_cell[cell_of(p.1) * side + cell_of(p.0)].push(i);
        }
        let near = |i: usize, out: &mut Vec<usize>| {
            let (cx, cy) = (cell_of(pts[i].0), cell_of(pts[i].1));
            for y in cy.saturating_sub(1)..=(cy + 1).min(side - 1) {
                for x in cx.saturating_sub(1)..=(cx + 1).min(side - 1) {
                    for &j in &by_cell[y * side + x] {
                        let d = (pts[i].0 - pts[j].0).hypot(pts[i].1 - pts[j].1);
                        if j != i && d <= radius {
                            out.push(j);
                        }
                    }
                }
            }
        };
        // The size of the lists, checked before they are built.
        let mut entries = n as u128;
        let mut buf = Vec::new();
        for i in 0..n {
            buf.clear();
            near(i, &mut buf);
            entries += buf.len() as u128;
        }
        check_lists(n, entries)?;
        let g = NeighbourLists::max_degree(n, &near)?;
        if g.connected() {
            return Ok(g);
        }
    }
    Err(scenario_err(
        "topology",
        format!("no connected random geometric graph of {n} nodes with radius {radius} in 1000 seeds; use a larger radius"),
    ))
}

/// Refuses neighbour lists of `entries` entries over `n` nodes that do not
/// fit ([`limits::graph_bytes`](crate::limits::graph_bytes)).
pub(crate) fn check_lists(n: usize, entries: u128) -> Result<()> {
    crate::limits::check_memory(
        || format!("nodes = {n}: neighbour lists of {entries} entries (nodes × (degree + 1))"),
        crate::limits::graph_bytes(n, entries),
    )
}

/// Refuses a dense `n × n` matrix of `bytes`-byte entries that does not fit,
/// naming the sparse form to use instead.
pub(crate) fn check_dense(n: usize, bytes: usize, what: &str) -> Result<()> {
    crate::limits::check_memory(
        || {
            format!(
                "the dense {n} × {n} {what} (the neighbour lists hold the same graph: `neighbours` of a Scenario or Network, in Rust and Python)"
            )
        },
        crate::limits::product(&[n, n, bytes]),
    )
}

/// A communication graph and its combination weights as neighbour lists
/// (compressed rows): node i's closed neighbourhood (itself and its
/// neighbours, ascending) is `indices[offsets[i]..offsets[i + 1]]`, and
/// `weights` holds `c_ij` for each entry (`c_ii` at node i's own). Memory
/// O(nodes + edges); [`Topology::neighbours`] builds it,
/// [`core`](Self::core) views it as the core's [`NeighbourWeights`](edccif_core::NeighbourWeights).
///
/// ```
/// use edccif_sim::Topology;
/// let g = Topology::Line.neighbours(3).unwrap();
/// assert_eq!((g.nodes(), g.entries()), (3, 7));
/// assert_eq!(g.row(1), &[0, 1, 2]);
/// assert_eq!(g.adjacency(), Topology::Line.adjacency(3).unwrap());
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct NeighbourLists {
    offsets: Vec<usize>,
    indices: Vec<usize>,
    weights: Vec<f64>,
}

impl NeighbourLists {
    /// The max-degree weights (as [`weights`]) of the graph whose node i has
    /// the neighbours `nbrs(i, out)` appends (in any order, repeats and i
    /// itself allowed; the graph must be symmetric, which is not checked).
    fn max_degree(n: usize, nbrs: &dyn Fn(usize, &mut Vec<usize>)) -> Result<Self> {
        let mut offsets = Vec::with_capacity(n + 1);
        let mut indices = Vec::new();
        let mut row = Vec::new();
        offsets.push(0);
        let mut max_deg = 0;
        for i in 0..n {
            row.clear();
            nbrs(i, &mut row);
            row.push(i);
            row.sort_unstable();
            row.dedup();
            max_deg = max_deg.max(row.len() - 1);
            indices.extend_from_slice(&row);
            offsets.push(indices.len());
        }
        // As `edccif_core::fusion::max_degree_weights`, bit for bit.
        let cw = 1.0 / ((1 + max_deg) as f64);
        let mut weights = vec![cw; indices.len()];
        for i in 0..n {
            let mut self_w = 1.0;
            let (a, b) = (offsets[i], offsets[i + 1]);
            for &j in &indices[a..b] {
                if j != i {
                    self_w -= cw;
                }
            }
            let own = a + indices[a..b].binary_search(&i).unwrap_or(0);
            weights[own] = self_w;
        }
        Ok(Self {
            offsets,
            indices,
            weights,
        })
    }

    /// The lists of a row-major `n × n` weight matrix: node i's closed
    /// neighbourhood is i and the `j` with `weights[i*n + j] > 0` (as
    /// [`Neighbours::from_weights`](edccif_core::Neighbours::from_weights)).
    pub fn from_dense(weights: &[f64], n: usize) -> Result<Self> {
        if weights.len() != n * n {
            return Err(Error::Shape {
                what: "weights".into(),
                expected: format!("({n}, {n})"),
                got: format!("{} values", weights.len()),
            });
        }
        let mut offsets = Vec::with_capacity(n + 1);
        let (mut indices, mut w) = (Vec::new(), Vec::new());
        offsets.push(0);
        for i in 0..n {
            for j in 0..n {
                let v = weights[i * n + j];
                if j == i || v > 0.0 {
                    indices.push(j);
                    w.push(v);
                }
            }
            offsets.push(indices.len());
        }
        Ok(Self {
            offsets,
            indices,
            weights: w,
        })
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        self.offsets.len() - 1
    }

    /// Entries of the lists: nodes plus directed edges.
    pub fn entries(&self) -> usize {
        self.indices.len()
    }

    /// Node i's closed neighbourhood, ascending.
    pub fn row(&self, i: usize) -> &[usize] {
        &self.indices[self.offsets[i]..self.offsets[i + 1]]
    }

    /// The weights of node i's list, entry by entry (`c_ij` for `j` in
    /// [`row`](Self::row)`(i)`).
    pub fn row_weights(&self, i: usize) -> &[f64] {
        &self.weights[self.offsets[i]..self.offsets[i + 1]]
    }

    /// The offsets (`nodes + 1`), indices and weights (one per entry).
    pub fn parts(&self) -> (&[usize], &[usize], &[f64]) {
        (&self.offsets, &self.indices, &self.weights)
    }

    /// The lists as the core's
    /// [`NeighbourWeights`](edccif_core::NeighbourWeights) (checked).
    pub fn core(&self) -> Result<edccif_core::NeighbourWeights<'_, f64>> {
        let nb = edccif_core::Neighbours::new(&self.offsets, &self.indices)?;
        Ok(edccif_core::NeighbourWeights::new(nb, &self.weights)?)
    }

    /// Whether the graph is connected (a breadth-first search).
    pub fn connected(&self) -> bool {
        let n = self.nodes();
        let mut seen = vec![false; n];
        let mut queue = std::collections::VecDeque::from([0usize]);
        seen[0] = true;
        let mut count = 1;
        while let Some(i) = queue.pop_front() {
            for &j in self.row(i) {
                if !seen[j] {
                    seen[j] = true;
                    count += 1;
                    queue.push_back(j);
                }
            }
        }
        count == n
    }

    /// The row-major `n × n` adjacency (no self-loops). Dense: the caller
    /// checks the size.
    pub fn adjacency(&self) -> Vec<bool> {
        let n = self.nodes();
        let mut a = vec![false; n * n];
        for i in 0..n {
            for &j in self.row(i) {
                a[i * n + j] = j != i;
            }
        }
        a
    }

    /// The row-major `n × n` weight matrix; refused with [`Error::TooLarge`]
    /// when it does not fit in memory.
    pub fn to_dense(&self) -> Result<Vec<f64>> {
        let n = self.nodes();
        check_dense(n, 8, "weight matrix")?;
        let mut w = vec![0.0; n * n];
        for i in 0..n {
            for (&j, &c) in self.row(i).iter().zip(self.row_weights(i)) {
                w[i * n + j] = c;
            }
        }
        Ok(w)
    }

    /// Second-largest eigenvalue modulus of the (symmetric) weights
    /// ([`lambda2`]); needs the dense matrix, refused when it does not fit.
    pub fn lambda2(&self) -> Result<f64> {
        Ok(lambda2(&self.to_dense()?, self.nodes()))
    }
}

impl Topology {
    /// The validated combination weights (row-major `n × n`): the custom weights
    /// of a [`Topology::Custom`] that has them (checked by [`validate_weights`]),
    /// otherwise the max-degree weights of the adjacency. Dense: refused with
    /// [`Error::TooLarge`] when `n × n` does not fit in memory
    /// ([`neighbours`](Self::neighbours) is the sparse form).
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
        check_dense(n, 8, "weight matrix")?;
        if !matches!(self, Topology::Custom { .. }) {
            return self.neighbours(n)?.to_dense();
        }
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
    iterations_of_lambda2(lambda2(weights, n))
}

/// [`adequate_consensus_iterations`] of a weight matrix whose [`lambda2`] is `l2`.
pub fn iterations_of_lambda2(l2: f64) -> usize {
    if l2 < 1e-12 {
        return 1;
    }
    if l2 >= 1.0 - 1e-15 {
        return usize::MAX;
    }
    (0.01f64.ln() / l2.ln()).ceil().max(1.0) as usize
}
