//! A run as an MCAP file for Foxglove, and the replay of measurements from one.
//!
//! # Topics
//!
//! Every message is JSON (`message_encoding = "json"`), every schema a JSON Schema
//! (`schema encoding = "jsonschema"`), except the optional ROS 2 topics (CDR,
//! `ros2msg` schema; see [`crate::ros2`]). Chunks are zstd-compressed unless
//! [`McapWriteOptions::compression`] is [`ChunkCompression::None`]. Step `t` (0-based row of the run's arrays)
//! has log time, publish time and message `timestamp` `t0_ns + round(t·dt·1e9)` ns.
//! The frame is [`McapWriteOptions::frame_id`] (default `"world"`).
//!
//! | topic | schema | content, per step |
//! |---|---|---|
//! | `/truth` | `foxglove.PoseInFrame` | true position (the first [`McapRunData::position_dim`] state values, zeros after them), identity orientation; only when the truth is known |
//! | `/node{i}/measurement` | `edccif.Measurement` | node `i`'s measurement `z` (or `null` when it has none) and its trigger flag; channel metadata [`META_M`] = its size `m` when a node of the file measures other than 3 values |
//! | `/node{i}/local` | `foxglove.PoseInFrame` | node `i`'s local (pre-combination) position estimate; only when recorded |
//! | `/node{i}/fused` | `foxglove.PoseInFrame` | node `i`'s fused position estimate |
//! | `/node{i}/point` | `geometry_msgs/msg/PointStamped` (CDR) | node `i`'s measurement `z` as a ROS 2 point (`x, y, z` = the 3 measured values), stamped with the step time; none when `z` is missing; only with [`McapWriteOptions::ros2`], for nodes that measure 3 values |
//! | `/truth/point` | `geometry_msgs/msg/PointStamped` (CDR) | the true position as a ROS 2 point; only with [`McapWriteOptions::ros2`] and a known truth |
//! | `/scene` | `foxglove.SceneUpdate` | entity `sensors` (a cube per sensor position), `target` (a sphere at the true position), `node{i}/covariance` (an ellipsoid per node: the fused position covariance, `k`-σ, see below) |
//!
//! Nodes are numbered from 0. A step whose estimate is not finite is not written on
//! that node's estimate topics.
//!
//! ## `edccif.Measurement`
//!
//! ```json
//! {"timestamp": {"sec": 0, "nsec": 100000000}, "frame_id": "world",
//!  "node": 2, "z": [1.0, 2.0, 3.0], "triggered": true}
//! ```
//!
//! `node` is the node index (it must match the topic), `z` the node's `m` measured
//! values in the scenario's units (`m` from the channel's metadata [`META_M`], 3
//! when it has none, as in files written before it existed; `null`: no
//! measurement at this step), `triggered` whether
//! the node's sensor sent `z` to its estimator (always `false` when `z` is `null`).
//! The schema text is [`measurement_schema`].
//!
//! ## Covariance ellipsoids
//!
//! For the fused position covariance `P` (the 3 × 3 top-left block), with
//! `P = V diag(λ) Vᵀ` (`V` a rotation), the ellipsoid is a `foxglove.SpherePrimitive`
//! at the fused position with orientation `V` and size (diameters)
//! `2 k √λ_j` along its axes; `k` is [`McapWriteOptions::ellipsoid_sigmas`] (2).
//!
//! ## Foxglove schemas
//!
//! The `foxglove.PoseInFrame` and `foxglove.SceneUpdate` schema texts written to
//! the file ([`pose_in_frame_schema`], [`scene_update_schema`]) describe the fields
//! this module writes, with the names and types of Foxglove's published schemas
//! (a subset: e.g. no arrows or text primitives are described), which Foxglove
//! recognises by schema name.
//!
//! # Replay
//!
//! [`read_measurements`] collects the `/node{i}/measurement` messages of a file
//! into a `(T, Σ m_i)` array (`(T, N, 3)` when every node measures 3 values):
//! the rows are the distinct log times of those messages in increasing order,
//! `N` is one more than the largest node index among the measurement channels,
//! node `i`'s `m_i` values follow those of the nodes before it, and a node
//! without a message (or with `"z": null`) at a time has NaN there. Other
//! topics are ignored.
//!
//! The file is read through the `mcap` crate (see `mcap_read` in the sources):
//! chunks uncompressed, zstd or lz4; with or without summary and index; a file
//! whose tail is missing gives the messages before the cut and says where it
//! stopped in [`McapReplay::truncated`]. CRCs are checked where the file has
//! them; Metadata records are returned in [`McapReplay::metadata`];
//! attachments are skipped. Errors name the record (its
//! number in reading order), the topic and what was expected. It never panics
//! on malformed input. ROS 2 recordings are read by [`crate::ros2::read_ros2`].
//!
//! ```
//! use edccif_io::mcap_io::{mcap_to_bytes, read_measurements, McapRunData, McapWriteOptions};
//! // Two steps of two nodes; node 1 has no measurement at step 1.
//! let data = McapRunData {
//!     dt: 0.1, t0_ns: 0, steps: 2, nodes: 2, n: 3,
//!     truth: Some(vec![0.0, 0.0, 1.0, 0.1, 0.0, 1.0]),
//!     position_dim: None,
//!     sensors: vec![5.0, 0.0, 0.0, -5.0, 0.0, 0.0],
//!     meas_dims: None,
//!     z: vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, f64::NAN, f64::NAN, f64::NAN],
//!     triggered: vec![true, false, true, false],
//!     local_estimates: None,
//!     fused_estimates: vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 0.1, 0.0, 1.0, 0.1, 0.0, 1.0],
//!     fused_covariances: None,
//!     node_ids: None,
//! };
//! let bytes = mcap_to_bytes(&data, &McapWriteOptions::default())?;
//! let replay = read_measurements(&bytes)?;
//! assert_eq!((replay.steps, replay.nodes), (2, 2));
//! assert_eq!(replay.t_ns, vec![0, 100_000_000]);
//! assert_eq!(replay.z[..9], data.z[..9]);
//! assert!(replay.z[9..].iter().all(|v| v.is_nan()));
//! # Ok::<(), edccif_io::Error>(())
//! ```

use std::collections::{BTreeMap, HashMap};
use std::io::{Cursor, Seek, Write};
use std::path::Path;

use nalgebra::{Matrix3, Rotation3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::error::{Error, Result};
pub use crate::mcap_read::name_file;
use crate::mcap_read::{check_magic, for_each_message_watched, input_err, read_file};

/// Dimension of a measurement of the uniform layout (3-D): a measurement
/// channel without the metadata key [`META_M`] holds 3 values.
const M: usize = 3;

/// Largest measurement dimension a recording may declare.
const MAX_M: usize = 64;

/// Channel metadata key of a `/node{i}/measurement` channel that gives the
/// node's measurement dimension `m` (a decimal number); absent: 3. Written on
/// every measurement channel of a file in which a node measures other than 3
/// values (the uniform layout of 3 values per node has none).
pub const META_M: &str = "m";

/// Topic of the true position.
pub const TOPIC_TRUTH: &str = "/truth";
/// Topic of the 3-D scene.
pub const TOPIC_SCENE: &str = "/scene";
/// Schema name of our measurement messages.
pub const MEASUREMENT_SCHEMA_NAME: &str = "edccif.Measurement";

/// Topic of node `i`'s measurements: `/node{i}/measurement`.
pub fn measurement_topic(i: usize) -> String {
    format!("/node{i}/measurement")
}

/// Topic of node `i`'s measurements as ROS 2 `PointStamped`: `/node{i}/point`.
pub fn point_topic(i: usize) -> String {
    format!("/node{i}/point")
}

/// Topic of the true position as ROS 2 `PointStamped`.
pub const TOPIC_TRUTH_POINT: &str = "/truth/point";

/// Topic of node `i`'s local estimate: `/node{i}/local`.
pub fn local_topic(i: usize) -> String {
    format!("/node{i}/local")
}

/// Topic of node `i`'s fused estimate: `/node{i}/fused`.
pub fn fused_topic(i: usize) -> String {
    format!("/node{i}/fused")
}

/// Everything written for one run. Arrays are flat and row-major; `T` steps,
/// `N` nodes, `n` state dimension (the first 3 state values are the position).
#[derive(Debug, Clone, PartialEq)]
pub struct McapRunData {
    /// Sampling period (s).
    pub dt: f64,
    /// Time of step 0 (ns).
    pub t0_ns: u64,
    /// `T`.
    pub steps: usize,
    /// `N`.
    pub nodes: usize,
    /// `n`.
    pub n: usize,
    /// How many leading state values are the position, 1 to 3 (`None`: 3).
    /// The poses, the scene and the ROS 2 truth pad a shorter position with
    /// zeros (a planar target moves in the plane `z = 0`).
    pub position_dim: Option<usize>,
    /// True states `(T, d)` with `d ≥` the position's dimension (only the
    /// position is used), if known.
    pub truth: Option<Vec<f64>>,
    /// Sensor positions `(N, 3)` (NaN: not drawn).
    pub sensors: Vec<f64>,
    /// Each node's measurement dimension `m_i` (`None`: 3 for every node).
    pub meas_dims: Option<Vec<usize>>,
    /// Measurements `(T, Σ m_i)`, node `i`'s `m_i` values after those of the
    /// nodes before it (with every `m_i = 3` this is `(T, N, 3)`); a node's
    /// values all NaN mean no measurement.
    pub z: Vec<f64>,
    /// Trigger flags `(T, N)`.
    pub triggered: Vec<bool>,
    /// Local (pre-combination) estimates `(T, N, n)`, if recorded.
    pub local_estimates: Option<Vec<f64>>,
    /// Fused estimates `(T, N, n)`.
    pub fused_estimates: Vec<f64>,
    /// Fused covariances `(T, N, n, n)`, if recorded (needed for the ellipsoids).
    pub fused_covariances: Option<Vec<f64>>,
    /// The node id of each of the `N` nodes, used in the topic names
    /// (`/node{id}/...`) and the `node` field of the measurements; `None`:
    /// `0, 1, …, N−1`. A file written by one node of a distributed run holds
    /// only that node, e.g. `Some(vec![3])`.
    pub node_ids: Option<Vec<usize>>,
}

fn shape_err(what: &str, expected: String, got: usize) -> Error {
    Error::Shape {
        what: what.into(),
        expected,
        got: format!("{got} values"),
    }
}

impl McapRunData {
    /// Checks every shape and `dt`.
    pub fn validate(&self) -> Result<()> {
        let (t, k, n) = (self.steps, self.nodes, self.n);
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(Error::Value {
                what: "dt".into(),
                problem: format!("must be finite and > 0, got {}", self.dt),
            });
        }
        let p = self.pos_dim();
        if !(1..=3).contains(&p) {
            return Err(Error::Value {
                what: "position_dim".into(),
                problem: format!("must be 1, 2 or 3, got {p}"),
            });
        }
        if t == 0 || k == 0 || n < p {
            return Err(Error::Value {
                what: "McapRunData dimensions".into(),
                problem: format!(
                    "need T >= 1, N >= 1, n >= {p} (the position's dimension); got T = {t}, N = {k}, n = {n}"
                ),
            });
        }
        if let Some(tr) = &self.truth {
            if tr.len() % t != 0 || tr.len() / t < p {
                return Err(shape_err(
                    "truth",
                    format!("({t}, d) with d >= {p}"),
                    tr.len(),
                ));
            }
        }
        if let Some(dims) = &self.meas_dims {
            if dims.len() != k {
                return Err(shape_err("meas_dims", format!("({k},)"), dims.len()));
            }
            if let Some(i) = dims.iter().position(|m| !(1..=MAX_M).contains(m)) {
                return Err(Error::Value {
                    what: format!("meas_dims[{i}]"),
                    problem: format!("must be 1 to {MAX_M}, got {}", dims[i]),
                });
            }
        }
        let total: usize = self.dims().iter().sum();
        let z_shape = match &self.meas_dims {
            None => format!("({t}, {k}, 3)"),
            Some(_) => format!("({t}, {total}): every node's m_i values per step"),
        };
        let checks: [(&str, usize, String); 4] = [
            ("sensors", k * 3, format!("({k}, 3)")),
            ("z", t * total, z_shape),
            ("triggered", t * k, format!("({t}, {k})")),
            ("fused_estimates", t * k * n, format!("({t}, {k}, {n})")),
        ];
        let lens = [
            self.sensors.len(),
            self.z.len(),
            self.triggered.len(),
            self.fused_estimates.len(),
        ];
        for ((what, want, shape), got) in checks.into_iter().zip(lens) {
            if got != want {
                return Err(shape_err(what, shape, got));
            }
        }
        if let Some(l) = &self.local_estimates {
            if l.len() != t * k * n {
                return Err(shape_err(
                    "local_estimates",
                    format!("({t}, {k}, {n})"),
                    l.len(),
                ));
            }
        }
        if let Some(ids) = &self.node_ids {
            if ids.len() != k {
                return Err(shape_err("node_ids", format!("({k},)"), ids.len()));
            }
            let mut sorted = ids.clone();
            sorted.sort_unstable();
            if sorted.windows(2).any(|w| w[0] == w[1])
                || sorted.last().is_some_and(|m| *m >= MAX_NODES)
            {
                return Err(Error::Value {
                    what: "node_ids".into(),
                    problem: format!("must be distinct and below {MAX_NODES}, got {ids:?}"),
                });
            }
        }
        if let Some(c) = &self.fused_covariances {
            if c.len() != t * k * n * n {
                return Err(shape_err(
                    "fused_covariances",
                    format!("({t}, {k}, {n}, {n})"),
                    c.len(),
                ));
            }
        }
        Ok(())
    }

    /// Every node's measurement dimension ([`McapRunData::meas_dims`]).
    pub fn dims(&self) -> Vec<usize> {
        self.meas_dims
            .clone()
            .unwrap_or_else(|| vec![M; self.nodes])
    }

    /// The position's dimension ([`McapRunData::position_dim`]).
    pub fn pos_dim(&self) -> usize {
        self.position_dim.unwrap_or(3)
    }

    /// The node id of node `i` (see [`McapRunData::node_ids`]).
    pub fn node_id(&self, i: usize) -> usize {
        self.node_ids.as_ref().map_or(i, |ids| ids[i])
    }

    /// Log time of step `t` (ns).
    pub fn time_ns(&self, t: usize) -> u64 {
        self.t0_ns + (t as f64 * self.dt * 1e9).round() as u64
    }
}

/// Compression of the chunks [`write_mcap`] writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ChunkCompression {
    /// zstd (the default, as `ros2 bag record` and Foxglove write).
    #[default]
    Zstd,
    /// Uncompressed chunks.
    None,
}

/// Options of [`write_mcap`]: presentation, ROS 2 topics and compression.
///
/// ```
/// use edccif_io::mcap_io::{ChunkCompression, McapWriteOptions};
/// let o = McapWriteOptions::default();
/// assert_eq!((o.compression, o.ros2, o.frame_id.as_str()), (ChunkCompression::Zstd, false, "world"));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct McapWriteOptions {
    /// Frame of every pose and scene entity.
    pub frame_id: String,
    /// `k` of the `k`-σ covariance ellipsoids.
    pub ellipsoid_sigmas: f64,
    /// Edge length of the sensor cubes (m).
    pub sensor_size: f64,
    /// Diameter of the target sphere (m).
    pub target_size: f64,
    /// Chunk compression (zstd unless set to [`ChunkCompression::None`]).
    pub compression: ChunkCompression,
    /// Also write the measurements and the truth as ROS 2 CDR
    /// `geometry_msgs/msg/PointStamped` messages on `/node{i}/point` and
    /// `/truth/point` (see the module documentation).
    pub ros2: bool,
    /// MCAP Metadata records to write: record name → its key/value pairs
    /// (e.g. the stored run of `edccif_sim::recording`, name `edccif.run`).
    /// Read back in [`McapReplay::metadata`].
    #[serde(default)]
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
}

impl Default for McapWriteOptions {
    fn default() -> Self {
        Self {
            frame_id: "world".into(),
            ellipsoid_sigmas: 2.0,
            sensor_size: 0.3,
            target_size: 0.2,
            compression: ChunkCompression::Zstd,
            ros2: false,
            metadata: BTreeMap::new(),
        }
    }
}

// ---------------------------------------------------------------- schemas

fn time_schema(description: &str) -> Value {
    json!({
        "type": "object", "title": "time", "description": description,
        "properties": {
            "sec": {"type": "integer", "minimum": 0},
            "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}
        }
    })
}

fn vector3_schema(description: &str) -> Value {
    json!({
        "title": "foxglove.Vector3", "description": description, "type": "object",
        "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}},
        "required": ["x", "y", "z"]
    })
}

fn pose_schema(description: &str) -> Value {
    json!({
        "title": "foxglove.Pose", "description": description, "type": "object",
        "properties": {
            "position": vector3_schema("Point denoting position in 3D space"),
            "orientation": {
                "title": "foxglove.Quaternion", "type": "object",
                "description": "Quaternion denoting orientation in 3D space",
                "properties": {
                    "x": {"type": "number"}, "y": {"type": "number"},
                    "z": {"type": "number"}, "w": {"type": "number"}
                },
                "required": ["x", "y", "z", "w"]
            }
        },
        "required": ["position", "orientation"]
    })
}

fn color_schema() -> Value {
    json!({
        "title": "foxglove.Color", "type": "object", "description": "RGBA color, values in [0, 1]",
        "properties": {
            "r": {"type": "number"}, "g": {"type": "number"},
            "b": {"type": "number"}, "a": {"type": "number"}
        },
        "required": ["r", "g", "b", "a"]
    })
}

fn primitive_schema(title: &str, description: &str) -> Value {
    json!({
        "title": title, "description": description, "type": "object",
        "properties": {
            "pose": pose_schema("Position of the center and orientation"),
            "size": vector3_schema("Size along each axis"),
            "color": color_schema()
        },
        "required": ["pose", "size", "color"]
    })
}

/// JSON Schema text of `foxglove.PoseInFrame` (the fields written here).
pub fn pose_in_frame_schema() -> String {
    json!({
        "title": "foxglove.PoseInFrame",
        "description": "A timestamped pose for an object or reference frame in 3D space \
                        (subset of Foxglove's schema written by edccif)",
        "type": "object",
        "properties": {
            "timestamp": time_schema("Timestamp of pose"),
            "frame_id": {"type": "string", "description": "Frame of reference"},
            "pose": pose_schema("Pose in 3D space")
        },
        "required": ["timestamp", "frame_id", "pose"]
    })
    .to_string()
}

/// JSON Schema text of `foxglove.SceneUpdate` (the fields written here: entities
/// with cube and sphere primitives; the other primitive arrays are always empty).
pub fn scene_update_schema() -> String {
    let empty_array = json!({"type": "array", "items": {"type": "object"}});
    json!({
        "title": "foxglove.SceneUpdate",
        "description": "An update to the entities displayed in a 3D scene \
                        (subset of Foxglove's schema written by edccif)",
        "type": "object",
        "properties": {
            "deletions": {"type": "array", "items": {"type": "object"}},
            "entities": {
                "type": "array",
                "items": {
                    "title": "foxglove.SceneEntity", "type": "object",
                    "properties": {
                        "timestamp": time_schema("Timestamp of the entity"),
                        "frame_id": {"type": "string"},
                        "id": {"type": "string"},
                        "lifetime": {
                            "type": "object", "title": "duration",
                            "properties": {
                                "sec": {"type": "integer"},
                                "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}
                            }
                        },
                        "frame_locked": {"type": "boolean"},
                        "metadata": {"type": "array", "items": {
                            "title": "foxglove.KeyValuePair", "type": "object",
                            "properties": {"key": {"type": "string"}, "value": {"type": "string"}},
                            "required": ["key", "value"]
                        }},
                        "arrows": empty_array.clone(),
                        "cubes": {"type": "array", "items": primitive_schema(
                            "foxglove.CubePrimitive", "A cube or rectangular prism")},
                        "spheres": {"type": "array", "items": primitive_schema(
                            "foxglove.SpherePrimitive", "A sphere or ellipsoid")},
                        "cylinders": empty_array.clone(),
                        "lines": empty_array.clone(),
                        "triangles": empty_array.clone(),
                        "texts": empty_array.clone(),
                        "models": empty_array
                    },
                    "required": ["timestamp", "frame_id", "id", "lifetime", "frame_locked",
                                 "metadata", "arrows", "cubes", "spheres", "cylinders",
                                 "lines", "triangles", "texts", "models"]
                }
            }
        },
        "required": ["deletions", "entities"]
    })
    .to_string()
}

/// JSON Schema text of `edccif.Measurement` (see the module documentation),
/// as written in a file whose nodes all measure 3 values.
pub fn measurement_schema() -> String {
    measurement_schema_of(false)
}

/// The `edccif.Measurement` schema text of a file whose nodes measure
/// different sizes (`per_node`: each channel's metadata [`META_M`] gives its
/// node's `m`), or 3 values each.
pub fn measurement_schema_of(per_node: bool) -> String {
    let z = if per_node {
        json!({
            "type": ["array", "null"], "items": {"type": "number"},
            "minItems": 1,
            "description": "The node's m measured values (m: the channel's metadata `m`); \
                            null when the node has no measurement"
        })
    } else {
        json!({
            "type": ["array", "null"], "items": {"type": "number"},
            "minItems": 3, "maxItems": 3,
            "description": "The measured values; null when the node has no measurement"
        })
    };
    json!({
        "title": MEASUREMENT_SCHEMA_NAME,
        "description": "One node's measurement at one step of an edccif run",
        "type": "object",
        "properties": {
            "timestamp": time_schema("Time of the step"),
            "frame_id": {"type": "string", "description": "Frame of the measurement"},
            "node": {"type": "integer", "minimum": 0, "description": "Node index (matches the topic)"},
            "z": z,
            "triggered": {"type": "boolean",
                          "description": "Whether the sensor sent z to its estimator"}
        },
        "required": ["timestamp", "frame_id", "node", "z", "triggered"]
    })
    .to_string()
}

// ---------------------------------------------------------------- writing

fn stamp(ns: u64) -> Value {
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

fn pose(p: [f64; 3], q: [f64; 4]) -> Value {
    json!({
        "position": {"x": p[0], "y": p[1], "z": p[2]},
        "orientation": {"x": q[0], "y": q[1], "z": q[2], "w": q[3]}
    })
}

fn color(rgba: [f64; 4]) -> Value {
    json!({"r": rgba[0], "g": rgba[1], "b": rgba[2], "a": rgba[3]})
}

fn primitive(p: [f64; 3], q: [f64; 4], size: [f64; 3], rgba: [f64; 4]) -> Value {
    json!({
        "pose": pose(p, q),
        "size": {"x": size[0], "y": size[1], "z": size[2]},
        "color": color(rgba)
    })
}

fn entity(ns: u64, frame: &str, id: &str, cubes: Vec<Value>, spheres: Vec<Value>) -> Value {
    json!({
        "timestamp": stamp(ns), "frame_id": frame, "id": id,
        "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": false, "metadata": [],
        "arrows": [], "cubes": cubes, "spheres": spheres,
        "cylinders": [], "lines": [], "triangles": [], "texts": [], "models": []
    })
}

const IDENTITY: [f64; 4] = [0.0, 0.0, 0.0, 1.0];

/// A distinct colour per node.
fn node_color(i: usize, alpha: f64) -> [f64; 4] {
    const PALETTE: [[f64; 3]; 6] = [
        [0.12, 0.47, 0.71],
        [1.0, 0.5, 0.05],
        [0.17, 0.63, 0.17],
        [0.58, 0.4, 0.74],
        [0.55, 0.34, 0.29],
        [0.89, 0.47, 0.76],
    ];
    let c = PALETTE[i % PALETTE.len()];
    [c[0], c[1], c[2], alpha]
}

/// Centre orientation and size of the `k`-σ ellipsoid of a row-major 3 × 3
/// covariance: `V` of `P = V diag(λ) Vᵀ` (made a proper rotation) as a quaternion
/// `(x, y, z, w)`, and the diameters `2 k √λ`. `None` if not finite.
///
/// ```
/// use edccif_io::mcap_io::ellipsoid;
/// let (q, size) = ellipsoid(&[4.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.25], 2.0).unwrap();
/// let mut s = size; s.sort_by(f64::total_cmp);
/// assert!((s[0] - 2.0).abs() < 1e-12 && (s[1] - 4.0).abs() < 1e-12 && (s[2] - 8.0).abs() < 1e-12);
/// assert!((q.iter().map(|v| v * v).sum::<f64>() - 1.0).abs() < 1e-12);
/// ```
pub fn ellipsoid(p3: &[f64], k: f64) -> Option<([f64; 4], [f64; 3])> {
    if p3.len() != 9 || p3.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let m = Matrix3::from_row_slice(p3);
    let m = (m + m.transpose()) * 0.5;
    let e = m.symmetric_eigen();
    let mut v = e.eigenvectors;
    if v.determinant() < 0.0 {
        v.set_column(2, &(-v.column(2)));
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(v));
    let size = [0, 1, 2].map(|j| 2.0 * k * e.eigenvalues[j].max(0.0).sqrt());
    let c = q.coords; // (i, j, k, w)
    Some(([c[0], c[1], c[2], c[3]], size))
}

struct Channels {
    truth: Option<u16>,
    meas: Vec<u16>,
    local: Vec<u16>,
    fused: Vec<u16>,
    scene: u16,
    /// With [`McapWriteOptions::ros2`]: the truth's `PointStamped` channel.
    ros_truth: Option<u16>,
    /// With [`McapWriteOptions::ros2`]: each node's `PointStamped` channel
    /// (`None` for a node that does not measure 3 values).
    ros_points: Vec<Option<u16>>,
}

/// Target uncompressed chunk size: small enough that a damaged chunk loses little
/// and that errors point close to the damage.
const CHUNK_SIZE: u64 = 64 * 1024;

fn mcap_err(e: mcap::McapError) -> Error {
    Error::Io(format!("cannot write MCAP: {e}"))
}

/// Writes a run as MCAP to any seekable writer (see the module documentation for
/// the topics). Chunks hold about 64 KiB of messages each, zstd-compressed unless
/// the options say otherwise.
pub fn write_mcap<W: Write + Seek>(w: W, data: &McapRunData, opt: &McapWriteOptions) -> Result<()> {
    check_write(data, opt)?;
    let mut wr = mcap::WriteOptions::new()
        .compression(match opt.compression {
            ChunkCompression::Zstd => Some(mcap::Compression::Zstd),
            ChunkCompression::None => None,
        })
        // One thread: the output is the same on every machine, and a run's
        // recording is small.
        .compression_threads(0)
        .chunk_size(Some(CHUNK_SIZE))
        .library(concat!("edccif-io ", env!("CARGO_PKG_VERSION")))
        .create(w)
        .map_err(mcap_err)?;
    let ch = add_channels(&mut wr, data, opt)?;
    let mut out = Out {
        wr,
        seq: HashMap::new(),
    };
    let sensor_cubes: Vec<Value> = data
        .sensors
        .chunks_exact(3)
        .filter_map(point_of)
        .map(|p| primitive(p, IDENTITY, [opt.sensor_size; 3], [0.35, 0.35, 0.4, 0.9]))
        .collect();
    let layout = Layout::of(data);
    for t in 0..data.steps {
        write_step(&mut out, &ch, data, opt, &layout, &sensor_cubes, t)?;
    }
    for (name, map) in &opt.metadata {
        out.wr
            .write_metadata(&mcap::records::Metadata {
                name: name.clone(),
                metadata: map.clone(),
            })
            .map_err(mcap_err)?;
    }
    out.wr.finish().map_err(mcap_err)?;
    Ok(())
}

/// What [`write_mcap`] refuses before writing anything: invalid data, an
/// ellipsoid scale that is not finite and > 0, ROS 2 stamps past 2038.
fn check_write(data: &McapRunData, opt: &McapWriteOptions) -> Result<()> {
    data.validate()?;
    if !(opt.ellipsoid_sigmas.is_finite() && opt.ellipsoid_sigmas > 0.0) {
        return Err(Error::Value {
            what: "ellipsoid_sigmas".into(),
            problem: format!("must be finite and > 0, got {}", opt.ellipsoid_sigmas),
        });
    }
    if opt.ros2 && data.time_ns(data.steps - 1) / 1_000_000_000 > i32::MAX as u64 {
        return Err(Error::Value {
            what: "t0_ns".into(),
            problem:
                "the last step is past 2038-01-19, which a ROS 2 stamp (int32 sec) cannot hold"
                    .into(),
        });
    }
    Ok(())
}

/// The schemas and channels of a recording of `data`: the JSON topics, and
/// with [`McapWriteOptions::ros2`] the CDR points (truth, and each node that
/// measures 3 values).
fn add_channels<W: Write + Seek>(
    wr: &mut mcap::Writer<W>,
    data: &McapRunData,
    opt: &McapWriteOptions,
) -> Result<Channels> {
    let no_meta = BTreeMap::new();
    let mut schema = |name: &str, encoding: &str, text: &str| {
        wr.add_schema(name, encoding, text.as_bytes())
            .map_err(mcap_err)
    };
    let pose_schema = schema(
        "foxglove.PoseInFrame",
        "jsonschema",
        &pose_in_frame_schema(),
    )?;
    let scene_schema = schema("foxglove.SceneUpdate", "jsonschema", &scene_update_schema())?;
    let dims = data.dims();
    // When a node measures other than 3 values, every measurement channel says
    // its node's m (channel metadata `m`); the uniform layout stays as it was.
    let per_node = dims.iter().any(|m| *m != M);
    let meas_schema = schema(
        MEASUREMENT_SCHEMA_NAME,
        "jsonschema",
        &measurement_schema_of(per_node),
    )?;
    let point_schema = if opt.ros2 {
        Some(schema(
            crate::ros2::POINT_STAMPED,
            "ros2msg",
            crate::ros2::point_stamped_schema(),
        )?)
    } else {
        None
    };
    let k = data.nodes;
    let meas: Vec<u16> = (0..k)
        .map(|i| {
            let meta = if per_node {
                BTreeMap::from([(META_M.to_string(), dims[i].to_string())])
            } else {
                BTreeMap::new()
            };
            wr.add_channel(
                meas_schema,
                &measurement_topic(data.node_id(i)),
                "json",
                &meta,
            )
            .map_err(mcap_err)
        })
        .collect::<Result<_>>()?;
    let mut add = |schema: u16, topic: &str, encoding: &str| {
        wr.add_channel(schema, topic, encoding, &no_meta)
            .map_err(mcap_err)
    };
    let nodes = |add: &mut dyn FnMut(u16, &str, &str) -> Result<u16>,
                 topic: fn(usize) -> String| {
        (0..k)
            .map(|i| add(pose_schema, &topic(data.node_id(i)), "json"))
            .collect::<Result<Vec<_>>>()
    };
    let truth = match data.truth {
        Some(_) => Some(add(pose_schema, TOPIC_TRUTH, "json")?),
        None => None,
    };
    let local = if data.local_estimates.is_some() {
        nodes(&mut add, local_topic)?
    } else {
        Vec::new()
    };
    let fused = nodes(&mut add, fused_topic)?;
    let scene = add(scene_schema, TOPIC_SCENE, "json")?;
    let (ros_truth, ros_points) = match point_schema {
        Some(s) => (
            match data.truth {
                Some(_) => Some(add(s, TOPIC_TRUTH_POINT, "cdr")?),
                None => None,
            },
            (0..k)
                .map(|i| {
                    (dims[i] == M)
                        .then(|| add(s, &point_topic(data.node_id(i)), "cdr"))
                        .transpose()
                })
                .collect::<Result<Vec<_>>>()?,
        ),
        None => (None, Vec::new()),
    };
    Ok(Channels {
        truth,
        meas,
        local,
        fused,
        scene,
        ros_truth,
        ros_points,
    })
}

/// Where each node's measurement lies in a row of `z`.
struct Layout {
    /// Each node's measurement size.
    dims: Vec<usize>,
    /// Each node's offset in a row.
    offsets: Vec<usize>,
    /// The row's length.
    total: usize,
}

impl Layout {
    fn of(data: &McapRunData) -> Self {
        let dims = data.dims();
        let offsets = dims
            .iter()
            .scan(0, |o, m| {
                *o += m;
                Some(*o - m)
            })
            .collect();
        let total = dims.iter().sum();
        Self {
            dims,
            offsets,
            total,
        }
    }

    /// Node i's measurement of step `t`.
    fn row<'z>(&self, z: &'z [f64], t: usize, i: usize) -> &'z [f64] {
        let a = t * self.total + self.offsets[i];
        &z[a..a + self.dims[i]]
    }
}

/// A 3-D point when its three values are finite.
fn point_of(v: &[f64]) -> Option<[f64; 3]> {
    let p = [v[0], v[1], v[2]];
    p.iter().all(|x| x.is_finite()).then_some(p)
}

/// The first `pd` values of `v` as a 3-D position (zeros after them), when
/// finite.
fn position_of(v: &[f64], pd: usize) -> Option<[f64; 3]> {
    let mut p = [0.0; 3];
    p[..pd].copy_from_slice(&v[..pd]);
    p.iter().all(|x| x.is_finite()).then_some(p)
}

/// The messages of step `t`: the truth, each node's measurement and
/// estimates, and the step's scene (sensors, target, covariance ellipsoids).
fn write_step<W: Write + Seek>(
    out: &mut Out<W>,
    ch: &Channels,
    data: &McapRunData,
    opt: &McapWriteOptions,
    layout: &Layout,
    sensor_cubes: &[Value],
    t: usize,
) -> Result<()> {
    let (k, pd) = (data.nodes, data.pos_dim());
    let frame = opt.frame_id.as_str();
    let ns = data.time_ns(t);
    let mut entities = vec![entity(ns, frame, "sensors", sensor_cubes.to_vec(), vec![])];
    if let (Some(tr), Some(c)) = (&data.truth, ch.truth) {
        let d = tr.len() / data.steps;
        if let Some(p) = position_of(&tr[t * d..t * d + pd], pd) {
            let msg = json!({"timestamp": stamp(ns), "frame_id": frame, "pose": pose(p, IDENTITY)});
            out.json(c, ns, &msg)?;
            if let Some(c) = ch.ros_truth {
                out.point(c, ns, frame, p)?;
            }
            let sphere = primitive(p, IDENTITY, [opt.target_size; 3], [0.85, 0.1, 0.1, 1.0]);
            entities.push(entity(ns, frame, "target", vec![], vec![sphere]));
        }
    }
    for i in 0..k {
        write_measurement(out, ch, data, frame, layout.row(&data.z, t, i), t, i)?;
        let off = (t * k + i) * data.n;
        if let Some(l) = &data.local_estimates {
            if let Some(p) = position_of(&l[off..off + pd], pd) {
                let msg =
                    json!({"timestamp": stamp(ns), "frame_id": frame, "pose": pose(p, IDENTITY)});
                out.json(ch.local[i], ns, &msg)?;
            }
        }
        if let Some(p) = position_of(&data.fused_estimates[off..off + pd], pd) {
            let msg = json!({"timestamp": stamp(ns), "frame_id": frame, "pose": pose(p, IDENTITY)});
            out.json(ch.fused[i], ns, &msg)?;
            if let Some(e) = covariance_entity(data, opt, t, i, p) {
                entities.push(e);
            }
        }
    }
    let scene = json!({"deletions": [], "entities": entities});
    out.json(ch.scene, ns, &scene)
}

/// Node i's measurement message of step `t`, `row` (and its ROS 2 point when
/// it measures 3 finite values).
fn write_measurement<W: Write + Seek>(
    out: &mut Out<W>,
    ch: &Channels,
    data: &McapRunData,
    frame: &str,
    row: &[f64],
    t: usize,
    i: usize,
) -> Result<()> {
    let ns = data.time_ns(t);
    let z = if row.iter().all(|v| v.is_finite()) {
        json!(row)
    } else {
        Value::Null
    };
    let trig = data.triggered[t * data.nodes + i] && !z.is_null();
    let msg = json!({"timestamp": stamp(ns), "frame_id": frame, "node": data.node_id(i),
                     "z": z, "triggered": trig});
    out.json(ch.meas[i], ns, &msg)?;
    // Only a node measuring 3 values has a point channel.
    if let Some(Some(c)) = ch.ros_points.get(i) {
        if let Some(p) = point_of(row) {
            out.point(*c, ns, frame, p)?;
        }
    }
    Ok(())
}

/// Node i's covariance ellipsoid of step `t` around its fused position `p`
/// (the position block, zeros outside the position's dimensions), when the
/// data has covariances and the block gives one.
fn covariance_entity(
    data: &McapRunData,
    opt: &McapWriteOptions,
    t: usize,
    i: usize,
    p: [f64; 3],
) -> Option<Value> {
    let cov = data.fused_covariances.as_ref()?;
    let (n, pd) = (data.n, data.pos_dim());
    let c0 = (t * data.nodes + i) * n * n;
    let p3: Vec<f64> = (0..3)
        .flat_map(|r| (0..3).map(move |c| (r, c)))
        .map(|(r, c)| {
            if r < pd && c < pd {
                cov[c0 + r * n + c]
            } else {
                0.0
            }
        })
        .collect();
    let (q, size) = ellipsoid(&p3, opt.ellipsoid_sigmas)?;
    let sphere = primitive(p, q, size, node_color(data.node_id(i), 0.35));
    Some(entity(
        data.time_ns(t),
        opt.frame_id.as_str(),
        &format!("node{}/covariance", data.node_id(i)),
        vec![],
        vec![sphere],
    ))
}

/// The writer and the per-channel message sequence numbers.
struct Out<W: Write + Seek> {
    wr: mcap::Writer<W>,
    seq: HashMap<u16, u32>,
}

impl<W: Write + Seek> Out<W> {
    fn bytes(&mut self, channel_id: u16, ns: u64, bytes: &[u8]) -> Result<()> {
        let s = self.seq.entry(channel_id).or_insert(0);
        *s += 1;
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: *s,
            log_time: ns,
            publish_time: ns,
        };
        self.wr
            .write_to_known_channel(&header, bytes)
            .map_err(mcap_err)
    }

    fn json(&mut self, channel_id: u16, ns: u64, msg: &Value) -> Result<()> {
        self.bytes(channel_id, ns, msg.to_string().as_bytes())
    }

    /// A `PointStamped` stamped `ns` (which the caller checked fits an int32 sec).
    fn point(&mut self, channel_id: u16, ns: u64, frame: &str, p: [f64; 3]) -> Result<()> {
        let (sec, nsec) = ((ns / 1_000_000_000) as i32, (ns % 1_000_000_000) as u32);
        self.bytes(
            channel_id,
            ns,
            &crate::ros2::point_stamped_cdr(sec, nsec, frame, p),
        )
    }
}

/// [`write_mcap`] into a byte vector.
pub fn mcap_to_bytes(data: &McapRunData, opt: &McapWriteOptions) -> Result<Vec<u8>> {
    let mut cur = Cursor::new(Vec::new());
    write_mcap(&mut cur, data, opt)?;
    Ok(cur.into_inner())
}

/// [`write_mcap`] to a file (created or truncated).
pub fn write_mcap_file(
    path: impl AsRef<Path>,
    data: &McapRunData,
    opt: &McapWriteOptions,
) -> Result<()> {
    let path = path.as_ref();
    let bytes = mcap_to_bytes(data, opt)?;
    std::fs::write(path, bytes)
        .map_err(|e| Error::Io(format!("cannot write {}: {e}", path.display())))
}

// ---------------------------------------------------------------- reading

/// Measurements replayed from an MCAP file. Arrays are flat, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct McapReplay {
    /// `T`: distinct log times of the measurement messages.
    pub steps: usize,
    /// `N`: one more than the largest node index of a measurement channel.
    pub nodes: usize,
    /// Log time of each row (ns), increasing.
    pub t_ns: Vec<u64>,
    /// Each node's measurement dimension `m_i`: its channel's metadata `m`,
    /// 3 without it (and for a node without a channel).
    pub meas_dims: Vec<usize>,
    /// Measurements `(T, Σ m_i)`, node `i`'s `m_i` values after those of the
    /// nodes before it (`(T, N, 3)` when every `m_i` is 3); NaN where a node
    /// has none.
    pub z: Vec<f64>,
    /// Trigger flags `(T, N)` as recorded (false where no measurement).
    pub triggered: Vec<bool>,
    /// `Some(where and why)` when the file's tail is missing (a recording that was
    /// cut or is still open): the rows hold every message before the cut.
    pub truncated: Option<String>,
    /// The file's MCAP Metadata records: name → key/value pairs (see
    /// [`McapWriteOptions::metadata`]); a name written twice keeps the last.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
}

impl McapReplay {
    /// Whether every node measures 3 values (the uniform layout: `z` is
    /// `(T, N, 3)`).
    pub fn uniform(&self) -> bool {
        self.meas_dims.iter().all(|m| *m == M)
    }

    /// Row times in seconds relative to the first row.
    pub fn times_s(&self) -> Vec<f64> {
        let t0 = self.t_ns.first().copied().unwrap_or(0);
        self.t_ns.iter().map(|t| (t - t0) as f64 * 1e-9).collect()
    }
}

/// Largest number of nodes a replayed file may have (guards the allocation of
/// the `(T, N, 3)` array against a damaged or hostile topic name).
const MAX_NODES: usize = 4096;

#[derive(Deserialize)]
struct MeasurementMsg {
    node: usize,
    z: Option<Vec<f64>>,
    #[serde(default)]
    triggered: bool,
}

/// `/node{i}/measurement` → `i`.
fn parse_node_topic(topic: &str) -> Option<usize> {
    let rest = topic.strip_prefix("/node")?;
    let idx = rest.strip_suffix("/measurement")?;
    if idx.is_empty() || !idx.bytes().all(|b| b.is_ascii_digit()) || idx.len() > 6 {
        return None;
    }
    idx.parse().ok()
}

/// Replays the `/node{i}/measurement` messages of an MCAP file held in memory
/// (see the module documentation). Read through the `mcap` crate: chunks
/// uncompressed, `zstd` or `lz4`, with or without a summary section; a file whose
/// tail is missing gives the messages before the cut and says so in
/// [`McapReplay::truncated`]. Errors name the record, the topic and what was
/// expected.
///
/// ```
/// use edccif_io::mcap_io::read_measurements;
/// let err = read_measurements(b"not an mcap file").unwrap_err();
/// assert!(err.to_string().contains("not an MCAP file"));
/// ```
pub fn read_measurements(bytes: &[u8]) -> Result<McapReplay> {
    read_measurements_watched(bytes, &crate::watch::Unwatched)
}

/// [`read_measurements`] that stops with [`Error::Interrupted`] soon after
/// `watch` is cancelled (Ctrl-C while a large recording is read); it counts
/// no work.
///
/// ```
/// use edccif_io::mcap_io::read_measurements_watched;
/// use edccif_io::watch::Watch;
/// struct Stop;
/// impl Watch for Stop {
///     fn add_total(&self, _: u64) {}
///     fn advance(&self, _: u64) {}
///     fn is_cancelled(&self) -> bool { true }
/// }
/// # let data = edccif_io::mcap_io::McapRunData {
/// #     dt: 0.1, t0_ns: 0, steps: 1, nodes: 1, n: 3, position_dim: None, truth: None,
/// #     sensors: vec![0.0; 3], meas_dims: None, z: vec![1.0, 2.0, 3.0], triggered: vec![true],
/// #     local_estimates: None, fused_estimates: vec![0.0; 3], fused_covariances: None, node_ids: None,
/// # };
/// # let bytes = edccif_io::mcap_io::mcap_to_bytes(&data, &Default::default())?;
/// let e = read_measurements_watched(&bytes, &Stop).unwrap_err();
/// assert!(matches!(e, edccif_io::Error::Interrupted));
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn read_measurements_watched(
    bytes: &[u8],
    watch: &dyn crate::watch::Watch,
) -> Result<McapReplay> {
    check_magic(bytes)?;
    // (log time, node, z, triggered)
    let mut rows: Vec<(u64, usize, Option<Vec<f64>>, bool)> = Vec::new();
    let mut max_node: Option<usize> = None;
    // channel id -> (node, its m)
    let mut checked: HashMap<u16, Option<(usize, usize)>> = HashMap::new();
    let mut dims: BTreeMap<usize, usize> = BTreeMap::new();
    let summary = for_each_message_watched(bytes, watch, |ch, meta, data| {
        let node = match checked.get(&ch.id) {
            Some(n) => *n,
            None => {
                let node = parse_node_topic(&ch.topic);
                if let Some(node) = node {
                    let at = meta.describe(&ch.topic);
                    if node >= MAX_NODES {
                        return Err(input_err(format!(
                            "{at}: node index {node} is too large (at most {})",
                            MAX_NODES - 1
                        )));
                    }
                    if ch.message_encoding != "json" {
                        return Err(input_err(format!(
                            "{at}: the channel has message encoding `{}`, expected `json`",
                            ch.message_encoding
                        )));
                    }
                    if ch.schema_name != MEASUREMENT_SCHEMA_NAME {
                        return Err(input_err(format!(
                            "{at}: the channel has schema `{}`, expected `{MEASUREMENT_SCHEMA_NAME}`",
                            ch.schema_name
                        )));
                    }
                    max_node = Some(max_node.map_or(node, |m| m.max(node)));
                }
                let node = match node {
                    Some(node) => {
                        let at = meta.describe(&ch.topic);
                        let m =
                            channel_m(&ch.metadata).map_err(|p| input_err(format!("{at}: {p}")))?;
                        if let Some(prev) = dims.insert(node, m) {
                            if prev != m {
                                return Err(input_err(format!(
                                    "{at}: the channel says node {node} measures {m} values, an \
                                     earlier channel of the same topic said {prev}"
                                )));
                            }
                        }
                        Some((node, m))
                    }
                    None => None,
                };
                checked.insert(ch.id, node);
                node
            }
        };
        let Some((node, m)) = node else {
            return Ok(());
        };
        let at = || meta.describe(&ch.topic);
        let msg: MeasurementMsg = serde_json::from_slice(data).map_err(|e| {
            input_err(format!(
                "{}: not a valid {MEASUREMENT_SCHEMA_NAME}: {e}",
                at()
            ))
        })?;
        if msg.node != node {
            return Err(input_err(format!(
                "{}: the message says node {}, the topic says node {node}",
                at(),
                msg.node
            )));
        }
        let z = match msg.z {
            None => None,
            Some(v) if v.len() == m && v.iter().all(|x| x.is_finite()) => Some(v),
            Some(v) => {
                return Err(input_err(format!(
                    "{}: z = {v:?}; expected {m} finite numbers (the channel's m{}) or null",
                    at(),
                    if m == M {
                        ", 3 when the channel does not say"
                    } else {
                        ""
                    }
                )))
            }
        };
        let trig = msg.triggered && z.is_some();
        rows.push((meta.log_time, node, z, trig));
        Ok(())
    })?;
    let Some(max_node) = max_node else {
        return Err(input_err(format!(
            "no `/node{{i}}/measurement` channel with schema `{MEASUREMENT_SCHEMA_NAME}` \
             (for ROS 2 messages, name the topics: see `read_ros2`)"
        )));
    };
    let k = max_node + 1;
    let meas_dims: Vec<usize> = (0..k).map(|i| dims.get(&i).copied().unwrap_or(M)).collect();
    let mut rep = assemble(rows, meas_dims, summary.truncated)?;
    rep.metadata = summary.metadata;
    Ok(rep)
}

/// The `m` of a measurement channel's metadata ([`META_M`]; 3 without it).
fn channel_m(meta: &BTreeMap<String, String>) -> std::result::Result<usize, String> {
    match meta.get(META_M) {
        None => Ok(M),
        Some(v) => match v.trim().parse::<usize>() {
            Ok(m) if (1..=MAX_M).contains(&m) => Ok(m),
            _ => Err(format!(
                "the channel's metadata `{META_M}` is {v:?}; expected the node's measurement \
                 dimension, 1 to {MAX_M}"
            )),
        },
    }
}

fn assemble(
    rows: Vec<(u64, usize, Option<Vec<f64>>, bool)>,
    meas_dims: Vec<usize>,
    truncated: Option<String>,
) -> Result<McapReplay> {
    let k = meas_dims.len();
    let offsets: Vec<usize> = meas_dims
        .iter()
        .scan(0, |o, m| {
            *o += m;
            Some(*o - m)
        })
        .collect();
    let total: usize = meas_dims.iter().sum();
    let mut times: Vec<u64> = rows.iter().map(|r| r.0).collect();
    times.sort_unstable();
    times.dedup();
    let t_len = times.len();
    let mut z = vec![f64::NAN; t_len * total];
    let mut triggered = vec![false; t_len * k];
    let mut seen = vec![false; t_len * k];
    for (time, node, zi, trig) in rows {
        let t = times.binary_search(&time).unwrap_or(0);
        let cell = t * k + node;
        if seen[cell] {
            return Err(input_err(format!(
                "two measurements of node {node} at log time {time} ns (topic `{}`)",
                measurement_topic(node)
            )));
        }
        seen[cell] = true;
        if let Some(v) = zi {
            let at = t * total + offsets[node];
            z[at..at + v.len()].copy_from_slice(&v);
        }
        triggered[cell] = trig;
    }
    Ok(McapReplay {
        steps: t_len,
        nodes: k,
        t_ns: times,
        meas_dims,
        z,
        triggered,
        truncated,
        metadata: BTreeMap::new(),
    })
}

/// [`read_measurements`] of a file; errors also name the file.
pub fn read_measurements_file(path: impl AsRef<Path>) -> Result<McapReplay> {
    read_measurements_file_watched(path, &crate::watch::Unwatched)
}

/// [`read_measurements_watched`] of a file; errors also name the file.
pub fn read_measurements_file_watched(
    path: impl AsRef<Path>,
    watch: &dyn crate::watch::Watch,
) -> Result<McapReplay> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    watch.check()?;
    read_measurements_watched(&bytes, watch).map_err(|e| name_file(e, path))
}
