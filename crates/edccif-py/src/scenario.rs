//! `edccif.Scenario`.

use std::path::PathBuf;

use edccif_sim::{Scenario, SensorSpec};
use numpy::PyArrayDyn;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{bool_array, finite_array, to_numpy, to_numpy_bool, Dim};
use crate::errors::{IntoPyResult, ScenarioError, UnknownOptionError};

/// Python value → JSON value, through the `json` module (numpy arrays via `tolist`).
pub fn py_to_json(py: Python<'_>, v: &Bound<'_, PyAny>) -> PyResult<serde_json::Value> {
    let json = py.import("json")?;
    let helpers = PyModule::from_code(
        py,
        c"def default(o):\n    if hasattr(o, 'tolist'):\n        return o.tolist()\n    raise TypeError(f'cannot convert {type(o).__name__} to a scenario value')\n",
        c"edccif_json_helpers.py",
        c"edccif_json_helpers",
    )?;
    let kwargs = PyDict::new(py);
    kwargs.set_item("default", helpers.getattr("default")?)?;
    let text: String = json.call_method("dumps", (v,), Some(&kwargs))?.extract()?;
    serde_json::from_str(&text).map_err(|e| ScenarioError::new_err(e.to_string()))
}

/// JSON value → Python object.
pub fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (v.to_string(),))
}

const REPLACE_KEYS: &str = "name, dt, steps, delta, normalised, sigma1, sigma2, consensus_iters, x0, p0_diag, sensors, motion, measurement, topology, weights, dynamic, ukf, q1, q2, q, sigma_r, sigma_a, sigma, fast_trig, untriggered_closed_form, fusion";

/// An experiment definition: models, noises, sensors, topology, initial estimate,
/// trigger and gain parameters.
///
/// >>> import edccif
/// >>> s = edccif.Scenario.paper(nodes=4)
/// >>> s.nodes, s.steps, s.sensors.shape
/// (4, 200, (4, 3))
#[pyclass(name = "Scenario", module = "edccif", frozen, eq)]
#[derive(Clone, PartialEq)]
pub struct PyScenario {
    /// The Rust scenario.
    pub inner: Scenario,
}

impl PyScenario {
    fn json(&self) -> serde_json::Value {
        serde_json::to_value(&self.inner).expect("scenario serialises")
    }
}

#[pymethods]
impl PyScenario {
    /// The built-in default scenario (ALGORITHM.md §6) for `nodes` sensors.
    /// `nodes` is checked against the memory available first (`SizeError`:
    /// every node's state and the ring's neighbour lists, linear in `nodes`).
    #[staticmethod]
    #[pyo3(signature = (nodes = 4))]
    fn paper(#[pyo3(from_py_with = crate::args::named::nodes)] nodes: usize) -> PyResult<Self> {
        edccif_sim::limits::check_nodes(nodes).py()?;
        let inner = Scenario::paper(nodes);
        inner.validate().py()?;
        Ok(Self { inner })
    }

    /// Reads a TOML scenario file; unknown keys and wrong types name the key and line.
    /// A Python model it names (`kind = "python"`, `model = "module:attribute"`)
    /// is imported from its `python_path` (relative to the file's directory) and
    /// `sys.path`, called when it is a factory and checked now (`ScenarioError`
    /// naming the reference and what was expected).
    #[staticmethod]
    fn from_toml(path: PathBuf) -> PyResult<Self> {
        let inner = Scenario::from_toml_file(path).map_err(|e| match e {
            edccif_sim::Error::Io(m) => ScenarioError::new_err(m),
            other => crate::errors::to_py(other),
        })?;
        crate::refs::check(&inner)?;
        Ok(Self { inner })
    }

    /// Parses TOML text; `base_dir`: the directory its `python_path` is
    /// relative to (default: the working directory).
    #[staticmethod]
    #[pyo3(signature = (text, *, base_dir = None))]
    fn from_toml_str(text: &str, base_dir: Option<PathBuf>) -> PyResult<Self> {
        let mut inner = Scenario::from_toml_str(text).py()?;
        inner.source_dir = edccif_sim::scenario::SourceDir(base_dir);
        crate::refs::check(&inner)?;
        Ok(Self { inner })
    }

    /// Builds a scenario from a dict of the same structure as `to_dict()`;
    /// `base_dir` as `from_toml_str`.
    #[staticmethod]
    #[pyo3(signature = (d, *, base_dir = None))]
    fn from_dict(
        py: Python<'_>,
        d: &Bound<'_, PyAny>,
        base_dir: Option<PathBuf>,
    ) -> PyResult<Self> {
        let v = py_to_json(py, d)?;
        let mut inner: Scenario =
            serde_json::from_value(v).map_err(|e| ScenarioError::new_err(e.to_string()))?;
        inner.validate().py()?;
        inner.source_dir = edccif_sim::scenario::SourceDir(base_dir);
        crate::refs::check(&inner)?;
        Ok(Self { inner })
    }

    /// The directory `python_path` is relative to: the scenario file's
    /// (`from_toml`) or the `base_dir` given; None: the working directory.
    #[getter]
    fn base_dir(&self) -> Option<String> {
        self.inner
            .source_dir
            .0
            .as_ref()
            .map(|p| p.to_string_lossy().into_owned())
    }

    /// The scenario as TOML text.
    fn to_toml(&self) -> PyResult<String> {
        self.inner.to_toml().py()
    }

    /// Writes the scenario to a TOML file.
    fn save_toml(&self, path: PathBuf) -> PyResult<()> {
        std::fs::write(&path, self.inner.to_toml().py()?)
            .map_err(|e| ScenarioError::new_err(format!("cannot write {}: {e}", path.display())))
    }

    /// The scenario as a plain dict.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.json())
    }

    /// A copy with some values replaced, e.g. `s.replace(delta=0.02, steps=100)`.
    /// Accepted keys: the fields of `to_dict()` and the shortcuts `q1`, `q2`, `q`
    /// (motion), `sigma_r`, `sigma_a`, `sigma` (measurement); `topology` also takes a
    /// name (`"ring"`, `"line"`, `"star"`, `"complete"`) or an (N, N) adjacency, and
    /// `weights` an (N, N) combination matrix (symmetric, rows summing to 1, > 0
    /// exactly on the edges; without `topology`, the graph is where it is > 0).
    /// A per-node scenario (`[[nodes]]`) sets each node's sensor, position and
    /// noise in `nodes` (an edited `to_dict()["nodes"]`); `sensors`,
    /// `measurement`, `sigma_r`, `sigma_a` and `sigma` raise `ScenarioError` there.
    /// `fast_trig=False` switches off the (default) fast trigonometry of the turn
    /// model and the angle sensors for the platform libm's, bit for bit (the
    /// two agree to about 1e-13 relative; see `docs/performance.md`), and
    /// `untriggered_closed_form=False` the (default) closed form of the
    /// untriggered ET-CIF step for the paper's stable form.
    ///
    /// >>> import edccif
    /// >>> edccif.Scenario.paper(nodes=4).replace(fast_trig=False).fast_trig
    /// False
    #[pyo3(signature = (**overrides))]
    fn replace(&self, py: Python<'_>, overrides: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut v = self.json();
        let mut weights = None;
        let mut new_topology = false;
        if let Some(ov) = overrides {
            for (key, value) in ov.iter() {
                let key: String = key.extract()?;
                if key == "weights" {
                    weights = Some(value);
                    continue;
                }
                new_topology |= key == "topology";
                if let Ok(f) = value.extract::<f64>() {
                    if !f.is_finite() {
                        return Err(ScenarioError::new_err(format!(
                            "scenario field `{key}`: must be a finite number, got {f}"
                        )));
                    }
                }
                let jv = py_to_json(py, &value).map_err(|e| {
                    ScenarioError::new_err(format!("scenario field `{key}`: {e} (values must be finite numbers, lists or dicts)"))
                })?;
                let obj = v.as_object_mut().expect("object");
                match key.as_str() {
                    "q1" | "q2" | "q" => {
                        obj["motion"][key.as_str()] = jv;
                    }
                    "sensors" | "measurement" | "sigma_r" | "sigma_a" | "sigma"
                        if !self.inner.nodes.is_empty() =>
                    {
                        return Err(ScenarioError::new_err(format!(
                            "scenario field `{key}`: this scenario gives each node its own sensor \
                             in `nodes` ([[nodes]]); per-node scenarios set each node's sensor \
                             position and noise in [[nodes]] (replace `nodes` with the edited \
                             list of to_dict()[\"nodes\"]), not with `{key}`"
                        )));
                    }
                    "sigma_r" | "sigma_a" | "sigma" => {
                        obj["measurement"][key.as_str()] = jv;
                    }
                    // a name, an adjacency (booleans or 0/1) or a table: what a
                    // scenario file and `from_dict` take (`edccif_sim::Topology`)
                    "topology" => {
                        obj.insert(key, jv);
                    }
                    "fusion" => {
                        // A fusion rule's name (`docs/fusion.md`), or None for the paper's CI.
                        if value.is_none() {
                            obj.remove("fusion");
                        } else {
                            let Ok(name) = value.extract::<String>() else {
                                return Err(ScenarioError::new_err(format!(
                                    "scenario field `fusion`: expected a fusion rule name (str) or None, got {}",
                                    value.repr()?
                                )));
                            };
                            edccif_sim::parse_fusion_rule(&name).py()?;
                            obj.insert(key, serde_json::Value::String(name));
                        }
                    }
                    "fast_trig" | "untriggered_closed_form" | "normalised" => {
                        if !value.is_instance_of::<pyo3::types::PyBool>() {
                            return Err(ScenarioError::new_err(format!(
                                "scenario field `{key}`: expected True or False, got {}",
                                value.repr()?
                            )));
                        }
                        obj.insert(key, jv);
                    }
                    k if obj.contains_key(k) || k == "consensus_iters" => {
                        obj.insert(key, jv);
                    }
                    _ => {
                        return Err(UnknownOptionError::new_err(format!(
                            "unknown scenario key {key:?}; expected one of {REPLACE_KEYS}"
                        )))
                    }
                }
            }
        }
        let mut inner: Scenario =
            serde_json::from_value(v).map_err(|e| ScenarioError::new_err(e.to_string()))?;
        inner.validate().py()?;
        inner.source_dir = self.inner.source_dir.clone();
        crate::refs::check(&inner)?;
        let Some(w) = weights else {
            return Ok(Self { inner });
        };
        let k = inner.nodes();
        let a = if new_topology {
            Some(crate::convert::to_numpy_bool(py, inner.adjacency().py()?, &[k, k])?.into_any())
        } else {
            None
        };
        let inner = scenario_with_graph(&inner, a.as_ref(), Some(&w))?;
        Ok(Self { inner })
    }

    /// Simulates one seeded run: `(truth (T, n), z (T, N, m), x0 (n,))`, where
    /// `x0 = x₀ + chol(P0) ξ` is the run's initial estimate; `z` is `(T, Σ m_i)`
    /// (every node's values in node order) when the nodes' sensors differ in
    /// dimension, NaN where a node does not measure (its `every`/`times`). The sizes are
    /// checked first (`SizeError`); a long simulation releases the GIL, stops
    /// with `KeyboardInterrupt` on Ctrl-C and reports to `progress` (True or a
    /// callable `progress(done, total)` in steps).
    #[pyo3(signature = (seed = 0, *, progress = None))]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        #[pyo3(from_py_with = crate::args::named::seed)] seed: u64,
        progress: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let progress = crate::drive::Progress::from_arg(progress, "simulate", "steps")?;
        let sc = self.inner.clone();
        edccif_sim::simulate::check_simulation_size(sc.steps, sc.nodes(), sc.state_dim()).py()?;
        let long =
            crate::drive::network_work(sc.steps, sc.nodes(), 0) >= 10 * crate::drive::LONG_WORK;
        crate::refs::clear_failure();
        let sim = crate::refs::finish(
            crate::drive::drive_if(py, long, &progress, move |ctl| {
                edccif_sim::simulate::simulate_with_control(&sc, seed, None, ctl)
            })
            .into_result()?
            .py(),
        )?;
        let (t, k, n) = (sim.steps, sim.nodes, sim.n);
        let truth = to_numpy(py, sim.truth, &[t, n])?;
        let z = match sim.meas_dims.first() {
            Some(&m) if sim.meas_dims.iter().all(|d| *d == m) => to_numpy(py, sim.z, &[t, k, m])?,
            _ => {
                let total = sim.meas_dims.iter().sum();
                to_numpy(py, sim.z, &[t, total])?
            }
        };
        let x0 = to_numpy(py, sim.x0_hat, &[n])?;
        PyTuple::new(py, [truth.into_any(), z.into_any(), x0.into_any()])
    }

    /// Label.
    #[getter]
    fn name(&self) -> String {
        self.inner.name.clone()
    }
    /// Number of nodes N.
    #[getter]
    fn nodes(&self) -> usize {
        self.inner.nodes()
    }
    /// Number of steps T.
    #[getter]
    fn steps(&self) -> usize {
        self.inner.steps
    }
    /// Sampling period (s).
    #[getter]
    fn dt(&self) -> f64 {
        self.inner.dt
    }
    /// State dimension n.
    #[getter]
    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }
    /// How many leading states are the target's position (2 or 3; None for a
    /// random-walk or linear motion, whose states the file does not name).
    #[getter]
    fn position_dim(&self) -> Option<usize> {
        self.inner.motion.spatial_dim()
    }
    /// Measurement dimension m shared by every node (None when the nodes'
    /// sensors differ in dimension).
    #[getter]
    fn meas_dim(&self) -> Option<usize> {
        self.inner.meas_dim()
    }
    /// Each node's measurement dimension `m_i` (node order): the widths of
    /// the node's columns in `simulate`'s `(T, Σ m_i)` measurements.
    #[getter]
    fn meas_dims(&self) -> Vec<usize> {
        self.inner.meas_dims()
    }
    /// Send-on-delta threshold δ: a number for every node, or a list with one
    /// per node.
    #[getter]
    fn delta<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        match &self.inner.delta {
            edccif_sim::Delta::All(d) => Ok(d.into_pyobject(py)?.into_any()),
            edccif_sim::Delta::PerNode(v) => Ok(pyo3::types::PyList::new(py, v)?.into_any()),
        }
    }
    /// Whether `delta` is in units of each sensor's noise (the send-on-delta
    /// family compares `(z − z_τ)ᵀR⁻¹(z − z_τ)` with δ).
    #[getter]
    fn normalised(&self) -> bool {
        self.inner.normalised
    }
    /// σ1 of the error-minimised gain.
    #[getter]
    fn sigma1(&self) -> f64 {
        self.inner.sigma1
    }
    /// σ2 of the error-minimised gain.
    #[getter]
    fn sigma2(&self) -> f64 {
        self.inner.sigma2
    }
    /// Whether the fast trigonometry is on (the default; `replace(fast_trig=False)`
    /// for the platform libm's).
    #[getter]
    fn fast_trig(&self) -> bool {
        self.inner.fast_trig
    }
    /// Whether the ET-CIF's untriggered contribution is in closed form
    /// (the default; `replace(untriggered_closed_form=False)` for the paper's
    /// stable form).
    #[getter]
    fn untriggered_closed_form(&self) -> bool {
        self.inner.untriggered_closed_form
    }
    /// The rule of the CI combination of DC-CIF and EDC-CIF (`fusion = "ici"` in
    /// TOML, `replace(fusion="ici")`; `docs/fusion.md`); "ci" (the paper's)
    /// when not set.
    ///
    /// >>> import edccif
    /// >>> edccif.Scenario.paper(nodes=4).replace(fusion="split-ci").fusion
    /// 'split-ci'
    #[getter]
    fn fusion(&self) -> &'static str {
        self.inner.fusion.unwrap_or_default().name()
    }
    /// What makes the scenario one of the model network rather than of the
    /// paper's kinds (a uniform `[measurement]` and a 3-D coordinated-turn,
    /// constant-velocity or constant-acceleration motion), in words; `None` for
    /// the paper's kinds. Recordings (`record`, `replay`) take the paper's
    /// kinds only; `run`, `Network` and `monte_carlo` take every scenario.
    #[getter]
    fn model_network_reason(&self) -> Option<String> {
        self.inner.model_network_reason()
    }
    /// Consensus iterations in force (the scenario's or the adequate L).
    #[getter]
    fn consensus_iters(&self) -> PyResult<usize> {
        self.inner.consensus_iterations().py()
    }
    /// Sensor positions (m), one row per node: (N, 3) in the uniform form
    /// (`sensors`); in the per-node form (`[[nodes]]`), (N, d) with `d` the
    /// longest node position (2 or 3; the target's position dimension when no
    /// node has one), NaN where a node's sensor has no position (`position`,
    /// `linear`) and in the third column of a planar sensor in a 3-D scenario.
    #[getter]
    fn sensors<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        if self.inner.nodes.is_empty() {
            let v: Vec<f64> = self.inner.sensors.iter().flatten().copied().collect();
            return to_numpy(py, v, &[self.inner.nodes(), 3]);
        }
        let positions: Vec<Option<&[f64]>> = self
            .inner
            .nodes
            .iter()
            .map(|n| match &n.sensor {
                SensorSpec::RangePitchAzimuth { position, .. } => Some(&position[..]),
                SensorSpec::RangeBearing { position, .. }
                | SensorSpec::BearingOnly { position, .. } => Some(&position[..]),
                SensorSpec::RangeOnly { position, .. } => Some(&position[..]),
                SensorSpec::Position { .. }
                | SensorSpec::Linear { .. }
                | SensorSpec::Python { .. } => None,
            })
            .collect();
        let d = positions
            .iter()
            .flatten()
            .map(|p| p.len())
            .max()
            .or(self.inner.motion.spatial_dim())
            .unwrap_or(0);
        let mut v = vec![f64::NAN; positions.len() * d];
        for (row, p) in v.chunks_mut(d.max(1)).zip(&positions) {
            if let Some(p) = p {
                row[..p.len()].copy_from_slice(p);
            }
        }
        to_numpy(py, v, &[positions.len(), d])
    }
    /// Adjacency (N, N) bool. Dense: `SizeError` when N × N does not fit in
    /// memory (`neighbours` is the same graph as lists).
    #[getter]
    fn adjacency<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<bool>>> {
        let k = self.inner.nodes();
        to_numpy_bool(py, self.inner.adjacency().py()?, &[k, k])
    }
    /// Combination weights (N, N): the topology's own or max-degree. Dense:
    /// `SizeError` when N × N does not fit in memory (`neighbours` holds the
    /// same weights as lists).
    #[getter]
    fn weights<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let k = self.inner.nodes();
        to_numpy(py, self.inner.weights().py()?, &[k, k])
    }
    /// The graph and combination weights as neighbour lists (compressed
    /// rows), memory O(N + edges): `(offsets, indices, weights)` with node
    /// i's closed neighbourhood (itself included, ascending) in
    /// `indices[offsets[i]:offsets[i + 1]]` and its weights `c_ij` at the same
    /// places of `weights`. `scipy.sparse.csr_array((weights, indices,
    /// offsets))` is the `weights` matrix.
    ///
    /// >>> import edccif
    /// >>> offsets, indices, w = edccif.Scenario.paper(nodes=100_000).neighbours
    /// >>> indices[offsets[0]:offsets[1]].tolist(), w[:3].round(3).tolist()
    /// ([0, 1, 99999], [0.333, 0.333, 0.333])
    #[getter]
    fn neighbours<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        crate::convert::neighbours_to_py(py, &self.inner.neighbours().py()?)
    }
    /// True initial state x₀ (n,).
    #[getter]
    fn x0<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        to_numpy(py, self.inner.x0.clone(), &[self.inner.state_dim()])
    }
    /// Initial covariance P0 (n, n).
    #[getter]
    fn p0<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArrayDyn<f64>>> {
        let n = self.inner.state_dim();
        let mut v = vec![0.0; n * n];
        for (i, d) in self.inner.p0_diag.iter().enumerate() {
            v[i * n + i] = *d;
        }
        to_numpy(py, v, &[n, n])
    }
    /// Motion model parameters (dict).
    #[getter]
    fn motion<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.json()["motion"])
    }
    /// Measurement model parameters (dict) of the uniform form; a per-node
    /// scenario (`[[nodes]]`) has none and raises `ScenarioError` (each node's
    /// sensor is in `to_dict()["nodes"]`).
    #[getter]
    fn measurement<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        if !self.inner.nodes.is_empty() {
            return Err(ScenarioError::new_err(
                "scenario field `measurement`: this scenario gives each node its own sensor in \
                 `nodes` ([[nodes]]) and has no single measurement; read each node's sensor \
                 from to_dict()[\"nodes\"]",
            ));
        }
        json_to_py(py, &self.json()["measurement"])
    }
    /// Topology (dict).
    #[getter]
    fn topology<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.json()["topology"])
    }

    fn __repr__(&self) -> String {
        let delta = match &self.inner.delta {
            edccif_sim::Delta::All(d) => d.to_string(),
            edccif_sim::Delta::PerNode(v) => format!("{v:?}"),
        };
        format!(
            "Scenario(name={:?}, nodes={}, steps={}, dt={}, delta={delta}{}, sigma1={}, sigma2={})",
            self.inner.name,
            self.inner.nodes(),
            self.inner.steps,
            self.inner.dt,
            if self.inner.normalised {
                ", normalised=True"
            } else {
                ""
            },
            self.inner.sigma1,
            self.inner.sigma2
        )
    }
}

/// A scenario with the graph given by `adjacency` (N, N) and/or `weights` (N, N)
/// (see `Scenario::with_graph`); the scenario itself when both are `None`.
pub fn scenario_with_graph(
    sc: &edccif_sim::Scenario,
    adjacency: Option<&Bound<'_, PyAny>>,
    weights: Option<&Bound<'_, PyAny>>,
) -> PyResult<edccif_sim::Scenario> {
    let k = sc.nodes();
    let a = adjacency
        .filter(|a| !a.is_none())
        .map(|a| bool_array(a, "adjacency", &[Dim::Is(k), Dim::Is(k)]))
        .transpose()?;
    let w = weights
        .filter(|w| !w.is_none())
        .map(|w| finite_array(w, "weights", &[Dim::Is(k), Dim::Is(k)]).map(|(v, _)| v))
        .transpose()?;
    sc.with_graph(a.as_deref(), w.as_deref())
        .map_err(|e| match e {
            // a bad graph is a graph error even when the scenario check found it
            edccif_sim::Error::Scenario { .. } => crate::errors::GraphError::new_err(e.to_string()),
            other => crate::errors::to_py(other),
        })
}
