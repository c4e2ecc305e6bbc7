//! ROS 2 recordings: positions from CDR-encoded messages in an MCAP file (a
//! `ros2 bag record` bag, zstd-compressed or not), and the CDR
//! `geometry_msgs/msg/PointStamped` messages [`crate::write_mcap`] writes.
//!
//! # Messages read
//!
//! | schema (`message_encoding = "cdr"`) | position taken | time |
//! |---|---|---|
//! | `geometry_msgs/msg/PointStamped` | `point` | `header.stamp` |
//! | `geometry_msgs/msg/PoseStamped` | `pose.position` | `header.stamp` |
//! | `geometry_msgs/msg/PoseWithCovarianceStamped` | `pose.pose.position` | `header.stamp` |
//! | `nav_msgs/msg/Odometry` | `pose.pose.position` | `header.stamp` |
//! | `tf2_msgs/msg/TFMessage` | `transforms[j].transform.translation` of each transform whose `child_frame_id` is the selected frame | that transform's `header.stamp` |
//!
//! A source is chosen by topic, optionally with a frame: `TOPIC` or
//! `TOPIC#FRAME` ([`Source::parse`]). For a `TFMessage` topic (`/tf`) the frame
//! is required and selects the transforms by `child_frame_id`; for the other
//! messages it keeps only those whose `header.frame_id` is `FRAME`.
//!
//! The payloads are decoded by the `cdr-encoding` crate (serde, from the
//! RustDDS / `ros2-client` project) into the message structs below; the 4-byte
//! encapsulation header (`CDR_LE` or `CDR_BE`) is checked first. Every message
//! of a selected topic must decode and carry finite values and a valid stamp;
//! an error names the record, topic and field.
//!
//! # Rows
//!
//! [`read_ros2`] returns each source's samples with their own stamps
//! ([`Ros2Recording`]); [`Ros2Recording::on_stamps`] puts them on the distinct
//! measurement stamps (a row per stamp, NaN where a sensor has no message then;
//! the steps are as long as the stamps are apart), [`Ros2Recording::resampled`]
//! on a uniform grid by linear interpolation (as the preprocessing pipeline
//! does). The truth is interpolated linearly at the row times (NaN outside its
//! span or across gaps longer than 3 of its median periods).
//!
//! ```
//! use edccif_io::ros2::{point_stamped_cdr, read_ros2, Source};
//! use edccif_io::mcap_io::{mcap_to_bytes, McapRunData, McapWriteOptions};
//! // A two-step, one-node run written with its ROS 2 topics, then read back.
//! let data = McapRunData {
//!     dt: 0.5, t0_ns: 1_000_000_000, steps: 2, nodes: 1, n: 3,
//!     truth: Some(vec![0.0, 0.0, 1.0, 0.5, 0.0, 1.0]),
//!     position_dim: None,
//!     sensors: vec![5.0, 0.0, 0.0],
//!     meas_dims: None,
//!     z: vec![0.1, 0.0, 1.0, 0.4, 0.1, 1.1],
//!     triggered: vec![true, true],
//!     local_estimates: None,
//!     fused_estimates: vec![0.0; 6],
//!     fused_covariances: None,
//!     node_ids: None,
//! };
//! let opt = McapWriteOptions { ros2: true, ..McapWriteOptions::default() };
//! let bytes = mcap_to_bytes(&data, &opt)?;
//! let rec = read_ros2(&bytes, &[Source::parse("/node0/point")?], Some(&Source::parse("/truth/point")?))?;
//! let rows = rec.on_stamps()?;
//! assert_eq!(rows.t_ns, vec![1_000_000_000, 1_500_000_000]);
//! assert_eq!(rows.z, data.z);
//! assert_eq!(rows.truth.unwrap(), data.truth.unwrap());
//! assert_eq!(point_stamped_cdr(1, 2, "world", [1.0, 2.0, 3.0]).len(), 4 + 8 + 12 + 4 + 24);
//! # Ok::<(), edccif_io::Error>(())
//! ```

use std::collections::HashMap;
use std::path::Path;

use byteorder::{BigEndian, LittleEndian};
use serde::de::{DeserializeOwned, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::error::{Error, Result};
use crate::frames::{EdgeInfo, FramePath, FrameTree};
use crate::mcap_read::{check_magic, name_file, read_file};
use crate::mcap_read::{for_each_message, input_err, MessageMeta};
use crate::preprocess::{interpolate, median_dt};
use crate::Track;

// ---------------------------------------------------------------- messages

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, `< 10⁹`.
    pub nanosec: u32,
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Time of the data.
    pub stamp: Time,
    /// Frame the data is in.
    pub frame_id: String,
}

/// `geometry_msgs/msg/Point` (also the layout of `Vector3`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/msg/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

/// `geometry_msgs/msg/PointStamped`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The point.
    pub point: Point,
}

/// `geometry_msgs/msg/Pose`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/msg/PoseStamped`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose.
    pub pose: Pose,
}

/// A `float64[36]` (6 × 6 row-major covariance): CDR writes the 36 values with
/// no length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Covariance6(pub [f64; 36]);

impl Serialize for Covariance6 {
    fn serialize<S: Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Covariance6 {
    fn deserialize<D: Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Covariance6;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("36 float64 values")
            }
            fn visit_seq<A: SeqAccess<'de>>(
                self,
                mut s: A,
            ) -> std::result::Result<Self::Value, A::Error> {
                let mut out = [0.0; 36];
                for (j, v) in out.iter_mut().enumerate() {
                    *v = s
                        .next_element()?
                        .ok_or_else(|| serde::de::Error::invalid_length(j, &self))?;
                }
                Ok(Covariance6(out))
            }
        }
        d.deserialize_tuple(36, V)
    }
}

/// `geometry_msgs/msg/PoseWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// The pose.
    pub pose: Pose,
    /// Its covariance.
    pub covariance: Covariance6,
}

/// `geometry_msgs/msg/PoseWithCovarianceStamped`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose with its covariance.
    pub pose: PoseWithCovariance,
}

/// `geometry_msgs/msg/Transform`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation (`geometry_msgs/msg/Vector3`).
    pub translation: Point,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/msg/TransformStamped`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The frame this transform places.
    pub child_frame_id: String,
    /// The transform.
    pub transform: Transform,
}

/// `tf2_msgs/msg/TFMessage`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `geometry_msgs/msg/Twist`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity (`Vector3`).
    pub linear: Point,
    /// Angular velocity (`Vector3`).
    pub angular: Point,
}

/// `geometry_msgs/msg/TwistWithCovariance`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// The twist.
    pub twist: Twist,
    /// Its covariance.
    pub covariance: Covariance6,
}

/// `nav_msgs/msg/Odometry`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    /// Stamp and frame of the pose.
    pub header: Header,
    /// Frame of the twist.
    pub child_frame_id: String,
    /// The pose.
    pub pose: PoseWithCovariance,
    /// The twist.
    pub twist: TwistWithCovariance,
}

/// The message types read, by schema name.
pub const SUPPORTED_SCHEMAS: [&str; 5] = [
    "geometry_msgs/msg/PointStamped",
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
    "tf2_msgs/msg/TFMessage",
];

/// Schema name of `tf2_msgs/msg/TFMessage`.
const TF_MESSAGE: &str = "tf2_msgs/msg/TFMessage";

/// Decodes a CDR payload (with its 4-byte encapsulation header) into `T`.
///
/// ```
/// use edccif_io::ros2::{decode_cdr, point_stamped_cdr, PointStamped};
/// let bytes = point_stamped_cdr(3, 500, "map", [1.0, 2.0, 3.0]);
/// let m: PointStamped = decode_cdr(&bytes)?;
/// assert_eq!((m.header.stamp.sec, m.header.frame_id.as_str(), m.point.z), (3, "map", 3.0));
/// assert!(decode_cdr::<PointStamped>(&bytes[..20]).is_err());
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn decode_cdr<T: DeserializeOwned>(data: &[u8]) -> Result<T> {
    let bad = |problem: String| Error::Value {
        what: "CDR message".into(),
        problem,
    };
    if data.len() < 4 {
        return Err(bad(format!(
            "{} bytes, shorter than the 4-byte encapsulation header",
            data.len()
        )));
    }
    let body = &data[4..];
    let r = match (data[0], data[1]) {
        (0, 1) => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        (0, 0) => cdr_encoding::from_bytes::<T, BigEndian>(body),
        (a, b) => {
            return Err(bad(format!(
            "encapsulation {a:#04x} {b:#04x}; expected CDR_LE (0x00 0x01) or CDR_BE (0x00 0x00) \
                 (XCDR2 and parameter lists are not read)"
        )))
        }
    };
    r.map(|(v, _)| v)
        .map_err(|e| bad(format!("does not decode: {e}")))
}

/// Encodes `msg` as CDR (little-endian) with its 4-byte encapsulation header
/// (`CDR_LE`), as `ros2 bag record` stores it.
///
/// ```
/// use edccif_io::ros2::{decode_cdr, encode_cdr, Header, Odometry, Time};
/// # use edccif_io::ros2::{Point, Pose, PoseWithCovariance, Quaternion, Covariance6, Twist, TwistWithCovariance};
/// let zero = Point { x: 0.0, y: 0.0, z: 0.0 };
/// let odom = Odometry {
///     header: Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "odom".into() },
///     child_frame_id: "base_link".into(),
///     pose: PoseWithCovariance {
///         pose: Pose { position: Point { x: 1.0, y: 2.0, z: 3.0 },
///                      orientation: Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 } },
///         covariance: Covariance6([0.0; 36]),
///     },
///     twist: TwistWithCovariance { twist: Twist { linear: zero, angular: zero },
///                                  covariance: Covariance6([0.0; 36]) },
/// };
/// let bytes = encode_cdr(&odom);
/// assert_eq!(&bytes[..4], &[0, 1, 0, 0]);
/// assert_eq!(decode_cdr::<Odometry>(&bytes)?, odom);
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn encode_cdr<T: Serialize>(msg: &T) -> Vec<u8> {
    let mut out = vec![0x00, 0x01, 0x00, 0x00];
    // The message structs here hold numbers, strings and sequences, which CDR
    // always encodes; an error cannot occur for them.
    out.extend(cdr_encoding::to_vec::<_, LittleEndian>(msg).unwrap_or_default());
    out
}

/// A `geometry_msgs/msg/PointStamped` as CDR ([`encode_cdr`]).
pub fn point_stamped_cdr(sec: i32, nanosec: u32, frame_id: &str, p: [f64; 3]) -> Vec<u8> {
    encode_cdr(&PointStamped {
        header: Header {
            stamp: Time { sec, nanosec },
            frame_id: frame_id.to_string(),
        },
        point: Point {
            x: p[0],
            y: p[1],
            z: p[2],
        },
    })
}

/// The `ros2msg` schema text of `geometry_msgs/msg/PointStamped` (with its
/// dependencies, as rosbag2 writes it).
pub fn point_stamped_schema() -> &'static str {
    "# A Point with reference coordinate frame and timestamp\n\
     std_msgs/Header header\n\
     Point point\n\
     ================================================================================\n\
     MSG: std_msgs/Header\n\
     builtin_interfaces/Time stamp\n\
     string frame_id\n\
     ================================================================================\n\
     MSG: builtin_interfaces/Time\n\
     int32 sec\n\
     uint32 nanosec\n\
     ================================================================================\n\
     MSG: geometry_msgs/Point\n\
     float64 x\n\
     float64 y\n\
     float64 z\n"
}

/// Schema name of [`point_stamped_schema`].
pub const POINT_STAMPED: &str = "geometry_msgs/msg/PointStamped";

// ---------------------------------------------------------------- selection

/// A source of positions: a topic, and optionally a frame (see the module docs).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Source {
    /// Topic name.
    pub topic: String,
    /// `child_frame_id` for `TFMessage` topics (required there); else a filter
    /// on `header.frame_id`.
    pub frame: Option<String>,
}

impl Source {
    /// Parses `TOPIC` or `TOPIC#FRAME`.
    ///
    /// ```
    /// use edccif_io::ros2::Source;
    /// let s = Source::parse("/tf#drone1/base_link")?;
    /// assert_eq!((s.topic.as_str(), s.frame.as_deref()), ("/tf", Some("drone1/base_link")));
    /// assert_eq!(Source::parse("/vicon/target")?.frame, None);
    /// assert!(Source::parse("#frame").is_err());
    /// # Ok::<(), edccif_io::Error>(())
    /// ```
    pub fn parse(spec: &str) -> Result<Self> {
        let (topic, frame) = match spec.split_once('#') {
            Some((t, f)) => (t, Some(f)),
            None => (spec, None),
        };
        if topic.is_empty() || frame.is_some_and(str::is_empty) {
            return Err(Error::Value {
                what: format!("source {spec:?}"),
                problem: "expected TOPIC or TOPIC#FRAME, both non-empty".into(),
            });
        }
        Ok(Self {
            topic: topic.into(),
            frame: frame.map(Into::into),
        })
    }

    /// `TOPIC` or `TOPIC#FRAME`.
    pub fn name(&self) -> String {
        match &self.frame {
            Some(f) => format!("{}#{f}", self.topic),
            None => self.topic.clone(),
        }
    }
}

// ---------------------------------------------------------------- reading

/// One source's samples, in stamp order: stamps (ns since the epoch),
/// positions, each sample's frame and, where the message carries a usable one,
/// the position block of its covariance.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Samples {
    /// `header.stamp` of each sample (ns).
    pub t_ns: Vec<u64>,
    /// Positions.
    pub p: Vec<[f64; 3]>,
    /// The frame each position is in: `header.frame_id`; for a `TFMessage`
    /// source the transform's parent frame (its `header.frame_id`).
    pub frame: Vec<String>,
    /// Each sample's position covariance (row-major 3 × 3: the rows and columns
    /// x, y, z of the message's 6 × 6 pose covariance), `None` when the message
    /// carries none or says it is unknown (see [`classify_covariance`]).
    pub cov: Vec<Option<[f64; 9]>>,
    /// The schema of the source's topic.
    pub schema: String,
    /// Messages whose covariance is ROS's "unknown" ([`classify_covariance`]).
    pub unknown_covariances: usize,
    /// The first message whose covariance is neither unknown nor symmetric
    /// positive definite: where, and why (an error when the message noise is used).
    pub invalid_covariance: Option<String>,
}

impl Samples {
    /// Whether the source's messages carry a covariance (`PoseWithCovarianceStamped`, `Odometry`).
    pub fn has_covariance(&self) -> bool {
        schema_has_covariance(&self.schema)
    }

    fn keep(&self, keep: &[bool]) -> Samples {
        let pick = |j: usize| keep[j];
        Samples {
            t_ns: (0..self.t_ns.len())
                .filter(|&j| pick(j))
                .map(|j| self.t_ns[j])
                .collect(),
            p: (0..self.p.len())
                .filter(|&j| pick(j))
                .map(|j| self.p[j])
                .collect(),
            frame: (0..self.frame.len())
                .filter(|&j| pick(j))
                .map(|j| self.frame[j].clone())
                .collect(),
            cov: (0..self.cov.len())
                .filter(|&j| pick(j))
                .map(|j| self.cov[j])
                .collect(),
            ..self.clone()
        }
    }
}

/// Whether messages of `schema` carry a pose covariance.
pub fn schema_has_covariance(schema: &str) -> bool {
    matches!(
        schema,
        "geometry_msgs/msg/PoseWithCovarianceStamped" | "nav_msgs/msg/Odometry"
    )
}

/// What a message's pose covariance says about its position.
#[derive(Debug, Clone, PartialEq)]
pub enum CovarianceKind {
    /// A symmetric positive definite position block (row-major 3 × 3).
    Known([f64; 9]),
    /// ROS's "unknown": the position block all zero or all −1, or its first
    /// element −1 (the `sensor_msgs` convention).
    Unknown,
    /// Neither: why.
    Invalid(String),
}

/// Classifies the position block (rows and columns 0–2) of a row-major 6 × 6
/// pose covariance: unknown (all zero, all −1, or element 0 equal to −1),
/// known (finite, symmetric to 1e-9 of its largest entry, positive definite),
/// or invalid.
///
/// ```
/// use edccif_io::ros2::{classify_covariance, CovarianceKind};
/// let mut c = [0.0; 36];
/// assert_eq!(classify_covariance(&c), CovarianceKind::Unknown);
/// c[0] = 0.04; c[7] = 0.04; c[14] = 0.09;
/// assert!(matches!(classify_covariance(&c), CovarianceKind::Known(b) if b[8] == 0.09));
/// c[14] = -1.0;
/// assert!(matches!(classify_covariance(&c), CovarianceKind::Invalid(_)));
/// assert_eq!(classify_covariance(&[-1.0; 36]), CovarianceKind::Unknown);
/// ```
pub fn classify_covariance(c: &[f64; 36]) -> CovarianceKind {
    let b = [c[0], c[1], c[2], c[6], c[7], c[8], c[12], c[13], c[14]];
    if b.iter().all(|v| *v == 0.0) || b.iter().all(|v| *v == -1.0) || b[0] == -1.0 {
        return CovarianceKind::Unknown;
    }
    if !b.iter().all(|v| v.is_finite()) {
        return CovarianceKind::Invalid(format!("position covariance {b:?} is not finite"));
    }
    let m = nalgebra::Matrix3::from_row_slice(&b);
    let scale = b.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    if (m - m.transpose()).abs().max() > 1e-9 * scale {
        return CovarianceKind::Invalid(format!("position covariance {b:?} is not symmetric"));
    }
    if m.cholesky().is_none() {
        return CovarianceKind::Invalid(format!(
            "position covariance {b:?} is not positive definite"
        ));
    }
    CovarianceKind::Known(b)
}

/// What [`read_ros2`] found: each measurement source's samples, the truth's,
/// and the recording's transforms.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2Recording {
    /// The measurement sources, in the order given (node `i` = source `i`).
    pub sources: Vec<Source>,
    /// Their samples.
    pub measurements: Vec<Samples>,
    /// The truth source and its samples, if one was given.
    pub truth: Option<(Source, Samples)>,
    /// The transforms of the recording's `/tf` and `/tf_static` topics.
    pub transforms: FrameTree,
    /// `Some(where)` when the file's tail is missing (see [`crate::McapReplay::truncated`]).
    pub truncated: Option<String>,
}

/// Measurements (and truth) on common rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2Rows {
    /// `T`.
    pub steps: usize,
    /// `N`: one node per measurement source.
    pub nodes: usize,
    /// Time of each row (ns since the epoch), increasing.
    pub t_ns: Vec<u64>,
    /// Measurements `(T, N, 3)`; NaN where a node has none.
    pub z: Vec<f64>,
    /// The messages' position covariances `(T, N, 3, 3)`; NaN where a node has
    /// no measurement or its message no usable covariance. Resampled rows take
    /// the covariance of the sample nearest in time.
    pub cov: Vec<f64>,
    /// Truth positions `(T, 3)` at the row times (NaN where unknown), if a truth
    /// source was given.
    pub truth: Option<Vec<f64>>,
    /// See [`Ros2Recording::truncated`].
    pub truncated: Option<String>,
    /// `Some(rate)` when the rows are a uniform grid at `rate` Hz
    /// ([`Ros2Recording::resampled`]); `None` on the messages' own stamps
    /// ([`Ros2Recording::on_stamps`]).
    pub rate_hz: Option<f64>,
}

impl Ros2Rows {
    /// The step lengths (s) to run a filter on these rows with: on a uniform
    /// grid `1 / rate` at every step; on the stamps `dt[0] = first` (from the
    /// initial estimate to the first row) and `dt[j] = (t[j] − t[j−1]) · 10⁻⁹`
    /// (the stamps' difference in ns, as `f64`, times `1e-9`).
    ///
    /// ```
    /// # use edccif_io::ros2::Ros2Rows;
    /// let rows = Ros2Rows { steps: 3, nodes: 1, t_ns: vec![5_000, 40_005_000, 50_005_000],
    ///                       z: vec![0.0; 9], cov: vec![f64::NAN; 27], truth: None,
    ///                       truncated: None, rate_hz: None };
    /// let dt = rows.run_dt(0.1);
    /// assert_eq!(dt[0], 0.1);
    /// assert!((dt[1] - 0.04).abs() < 1e-15 && (dt[2] - 0.01).abs() < 1e-15);
    /// let uniform = Ros2Rows { rate_hz: Some(20.0), ..rows };
    /// assert_eq!(uniform.run_dt(0.1), vec![0.05; 3]);
    /// ```
    pub fn run_dt(&self, first: f64) -> Vec<f64> {
        match self.rate_hz {
            Some(r) => vec![1.0 / r; self.steps],
            None => {
                let mut d = self.dt_s();
                if let Some(d0) = d.first_mut() {
                    *d0 = first;
                }
                d
            }
        }
    }

    /// The nominal step (s): `1 / rate` on a grid, else the median of the
    /// stamps' differences (`None` with fewer than two rows).
    pub fn nominal_dt(&self) -> Option<f64> {
        if let Some(r) = self.rate_hz {
            return Some(1.0 / r);
        }
        let mut d: Vec<f64> = self.dt_s().into_iter().skip(1).collect();
        if d.is_empty() {
            return None;
        }
        d.sort_by(f64::total_cmp);
        let m = d.len() / 2;
        Some(if d.len() % 2 == 1 {
            d[m]
        } else {
            0.5 * (d[m - 1] + d[m])
        })
    }

    /// Step lengths (s): `dt[0]` is 0 (the first row), `dt[j] = t[j] − t[j−1]`.
    pub fn dt_s(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.steps);
        for j in 0..self.steps {
            out.push(if j == 0 {
                0.0
            } else {
                (self.t_ns[j] - self.t_ns[j - 1]) as f64 * 1e-9
            });
        }
        out
    }
}

/// One position a selected message gave.
struct Read {
    stamp: Time,
    p: [f64; 3],
    field: String,
    frame: String,
    cov: Option<[f64; 36]>,
}

/// What a selected message gave: stamp and position, or nothing (filtered out).
fn positions_of(schema: &str, data: &[u8], frame: Option<&str>, out: &mut Vec<Read>) -> Result<()> {
    fn keep(h: &Header, frame: Option<&str>) -> bool {
        frame.is_none_or(|f| h.frame_id == f)
    }
    fn pt(p: &Point) -> [f64; 3] {
        [p.x, p.y, p.z]
    }
    fn one<T: DeserializeOwned>(data: &[u8]) -> Result<T> {
        decode_cdr(data)
    }
    let read = |h: &Header, p: &Point, field: &str, cov: Option<[f64; 36]>| Read {
        stamp: h.stamp,
        p: pt(p),
        field: field.into(),
        frame: h.frame_id.clone(),
        cov,
    };
    match schema {
        "geometry_msgs/msg/PointStamped" => {
            let m: PointStamped = one(data)?;
            if keep(&m.header, frame) {
                out.push(read(&m.header, &m.point, "point", None));
            }
        }
        "geometry_msgs/msg/PoseStamped" => {
            let m: PoseStamped = one(data)?;
            if keep(&m.header, frame) {
                out.push(read(&m.header, &m.pose.position, "pose.position", None));
            }
        }
        "geometry_msgs/msg/PoseWithCovarianceStamped" => {
            let m: PoseWithCovarianceStamped = one(data)?;
            if keep(&m.header, frame) {
                let c = Some(m.pose.covariance.0);
                out.push(read(
                    &m.header,
                    &m.pose.pose.position,
                    "pose.pose.position",
                    c,
                ));
            }
        }
        "nav_msgs/msg/Odometry" => {
            let m: Odometry = one(data)?;
            if keep(&m.header, frame) {
                let c = Some(m.pose.covariance.0);
                out.push(read(
                    &m.header,
                    &m.pose.pose.position,
                    "pose.pose.position",
                    c,
                ));
            }
        }
        TF_MESSAGE => {
            let m: TfMessage = one(data)?;
            for (j, t) in m.transforms.iter().enumerate() {
                if Some(t.child_frame_id.as_str()) == frame {
                    out.push(read(
                        &t.header,
                        &t.transform.translation,
                        &format!("transforms[{j}].transform.translation"),
                        None,
                    ));
                }
            }
        }
        _ => {}
    }
    Ok(())
}

/// The topics whose `TFMessage`s make the frame tree.
pub const TF_TOPICS: [&str; 2] = ["/tf", "/tf_static"];

/// A stamp in ns, or an error unless `sec >= 0` and `nanosec < 10⁹`.
fn stamp_ns(stamp: Time, at: &dyn Fn() -> String) -> Result<u64> {
    if stamp.sec < 0 || stamp.nanosec >= 1_000_000_000 {
        return Err(input_err(format!(
            "{}: header.stamp = ({}, {}) is not a valid time \
             (expected sec >= 0 and nanosec < 10^9)",
            at(),
            stamp.sec,
            stamp.nanosec
        )));
    }
    Ok(stamp.sec as u64 * 1_000_000_000 + u64::from(stamp.nanosec))
}

/// Adds every transform of a `/tf` or `/tf_static` message to the tree.
fn add_transforms(
    tree: &mut FrameTree,
    topic: &str,
    data: &[u8],
    at: &dyn Fn() -> String,
) -> Result<()> {
    let m: TfMessage =
        decode_cdr(data).map_err(|e| input_err(format!("{}: {TF_MESSAGE} {e}", at())))?;
    let fixed = topic == "/tf_static";
    for (j, t) in m.transforms.iter().enumerate() {
        let ns = stamp_ns(t.header.stamp, at)?;
        let tr = &t.transform;
        let what = format!(
            "{}: transforms[{j}] (`{}` → `{}`)",
            at(),
            t.header.frame_id,
            t.child_frame_id
        );
        let iso = crate::frames::isometry(
            [tr.translation.x, tr.translation.y, tr.translation.z],
            [tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w],
            &what,
        )?;
        tree.add(topic, fixed, &t.header.frame_id, &t.child_frame_id, ns, iso)
            .map_err(|e| input_err(format!("{}: {e}", at())))?;
    }
    Ok(())
}

/// Reads the positions of the `measurements` sources (one node each, in order),
/// of the optional `truth` source, and the transforms of `/tf` and
/// `/tf_static` from an MCAP file in memory (see the module docs). Every
/// source must name a topic of the file with a supported CDR schema and give
/// at least one sample.
pub fn read_ros2(
    bytes: &[u8],
    measurements: &[Source],
    truth: Option<&Source>,
) -> Result<Ros2Recording> {
    check_magic(bytes)?;
    if measurements.is_empty() {
        return Err(Error::Value {
            what: "measurement sources".into(),
            problem: "name at least one topic".into(),
        });
    }
    let all: Vec<&Source> = measurements.iter().chain(truth).collect();
    // topic -> indices into `all`
    let mut by_topic: HashMap<&str, Vec<usize>> = HashMap::new();
    for (j, s) in all.iter().enumerate() {
        by_topic.entry(s.topic.as_str()).or_default().push(j);
    }
    struct Raw {
        ns: u64,
        p: [f64; 3],
        frame: String,
        cov: Option<[f64; 36]>,
        meta: MessageMeta,
    }
    let mut samples: Vec<Vec<Raw>> = (0..all.len()).map(|_| Vec::new()).collect();
    let mut topic_seen: HashMap<String, String> = HashMap::new();
    let mut tree = FrameTree::default();
    let mut scratch = Vec::new();
    let summary = for_each_message(bytes, |ch, meta, data| {
        let at = || meta.describe(&ch.topic);
        if TF_TOPICS.contains(&ch.topic.as_str())
            && ch.schema_name == TF_MESSAGE
            && ch.message_encoding == "cdr"
        {
            add_transforms(&mut tree, &ch.topic, data, &at)?;
        }
        let Some(idx) = by_topic.get(ch.topic.as_str()) else {
            return Ok(());
        };
        if !topic_seen.contains_key(&ch.topic) {
            if ch.message_encoding != "cdr" {
                return Err(input_err(format!(
                    "{}: the channel has message encoding `{}`, expected `cdr` (ROS 2)",
                    at(),
                    ch.message_encoding
                )));
            }
            if !SUPPORTED_SCHEMAS.contains(&ch.schema_name.as_str()) {
                return Err(input_err(format!(
                    "{}: the channel has schema `{}`, expected one of {}",
                    at(),
                    ch.schema_name,
                    SUPPORTED_SCHEMAS.join(", ")
                )));
            }
            if ch.schema_name == TF_MESSAGE {
                if let Some(j) = idx.iter().find(|&&j| all[j].frame.is_none()) {
                    return Err(input_err(format!(
                        "{}: source `{}` is a {TF_MESSAGE} topic; name the transform's child \
                         frame: `{}#CHILD_FRAME_ID`",
                        at(),
                        all[*j].name(),
                        ch.topic
                    )));
                }
            }
            topic_seen.insert(ch.topic.clone(), ch.schema_name.clone());
        }
        for &j in idx {
            scratch.clear();
            let frame = all[j].frame.as_deref();
            positions_of(&ch.schema_name, data, frame, &mut scratch)
                .map_err(|e| input_err(format!("{}: {} {e}", at(), ch.schema_name)))?;
            for r in scratch.drain(..) {
                let ns = stamp_ns(r.stamp, &at)?;
                if !r.p.iter().all(|v| v.is_finite()) {
                    return Err(input_err(format!(
                        "{}: {} = {:?}; expected finite values",
                        at(),
                        r.field,
                        r.p
                    )));
                }
                samples[j].push(Raw {
                    ns,
                    p: r.p,
                    frame: r.frame,
                    cov: r.cov,
                    meta,
                });
            }
        }
        Ok(())
    })?;
    tree.finish().map_err(|e| input_err(e.to_string()))?;
    let mut tracks = Vec::with_capacity(all.len());
    for (j, mut v) in samples.into_iter().enumerate() {
        let s = all[j];
        let Some(schema) = topic_seen.get(&s.topic) else {
            return Err(input_err(format!(
                "no message on topic `{}` (source `{}`)",
                s.topic,
                s.name()
            )));
        };
        if v.is_empty() {
            return Err(input_err(format!(
                "source `{}`: the topic's messages have no {} `{}`",
                s.name(),
                if schema == TF_MESSAGE {
                    "transform with child_frame_id"
                } else {
                    "header.frame_id"
                },
                s.frame.as_deref().unwrap_or("")
            )));
        }
        v.sort_by_key(|x| x.ns);
        for w in v.windows(2) {
            if w[0].ns == w[1].ns {
                return Err(input_err(format!(
                    "source `{}`: two samples with the stamp {} ns ({} and {})",
                    s.name(),
                    w[0].ns,
                    w[0].meta.describe(&s.topic),
                    w[1].meta.describe(&s.topic)
                )));
            }
        }
        let mut out = Samples {
            schema: schema.clone(),
            ..Samples::default()
        };
        for r in v {
            let cov = match r.cov.as_ref().map(classify_covariance) {
                None => None,
                Some(CovarianceKind::Known(b)) => Some(b),
                Some(CovarianceKind::Unknown) => {
                    out.unknown_covariances += 1;
                    None
                }
                Some(CovarianceKind::Invalid(why)) => {
                    out.invalid_covariance
                        .get_or_insert_with(|| format!("{}: {why}", r.meta.describe(&s.topic)));
                    None
                }
            };
            out.t_ns.push(r.ns);
            out.p.push(r.p);
            out.frame.push(r.frame);
            out.cov.push(cov);
        }
        tracks.push(out);
    }
    let truth_samples = truth.map(|t| (t.clone(), tracks.pop().unwrap_or_default()));
    Ok(Ros2Recording {
        sources: measurements.to_vec(),
        measurements: tracks,
        truth: truth_samples,
        transforms: tree,
        truncated: summary.truncated,
    })
}

/// [`read_ros2`] of a file; errors also name the file.
pub fn read_ros2_file(
    path: impl AsRef<Path>,
    measurements: &[Source],
    truth: Option<&Source>,
) -> Result<Ros2Recording> {
    let path = path.as_ref();
    let bytes = read_file(path)?;
    read_ros2(&bytes, measurements, truth).map_err(|e| name_file(e, path))
}

/// Seconds since `t0` of stamps in ns.
fn secs(t_ns: &[u64], t0: u64) -> Vec<f64> {
    t_ns.iter()
        .map(|&t| t.wrapping_sub(t0) as i64 as f64 * 1e-9)
        .collect()
}

impl Ros2Recording {
    fn t0(&self) -> u64 {
        self.measurements
            .iter()
            .filter_map(|s| s.t_ns.first().copied())
            .min()
            .unwrap_or(0)
    }

    fn truth_at(&self, rows_ns: &[u64]) -> Result<Option<Vec<f64>>> {
        let Some((_, s)) = &self.truth else {
            return Ok(None);
        };
        let t0 = self.t0();
        let tr = Track::new(secs(&s.t_ns, t0), s.p.clone())?;
        let max_gap = 3.0 * median_dt(&tr).unwrap_or(f64::INFINITY);
        let (p, _) = interpolate(&tr, &secs(rows_ns, t0), max_gap)?;
        Ok(Some(p.into_iter().flatten().collect()))
    }

    /// Rows at `t_ns` with measurements `z` `(T, N, 3)`, the truth at those times.
    fn rows(
        &self,
        t_ns: Vec<u64>,
        z: Vec<f64>,
        cov: Vec<f64>,
        rate_hz: Option<f64>,
    ) -> Result<Ros2Rows> {
        Ok(Ros2Rows {
            steps: t_ns.len(),
            nodes: self.measurements.len(),
            truth: self.truth_at(&t_ns)?,
            t_ns,
            z,
            cov,
            truncated: self.truncated.clone(),
            rate_hz,
        })
    }

    /// One row per distinct measurement stamp: node `i` has its sample where its
    /// stamp equals the row's, NaN elsewhere; the truth interpolated at the rows.
    pub fn on_stamps(&self) -> Result<Ros2Rows> {
        let k = self.measurements.len();
        let mut t_ns: Vec<u64> = self
            .measurements
            .iter()
            .flat_map(|s| s.t_ns.iter().copied())
            .collect();
        t_ns.sort_unstable();
        t_ns.dedup();
        let mut z = vec![f64::NAN; t_ns.len() * k * 3];
        let mut cov = vec![f64::NAN; t_ns.len() * k * 9];
        for (i, s) in self.measurements.iter().enumerate() {
            for (j, (t, p)) in s.t_ns.iter().zip(&s.p).enumerate() {
                if let Ok(row) = t_ns.binary_search(t) {
                    let c = row * k + i;
                    z[c * 3..c * 3 + 3].copy_from_slice(p);
                    if let Some(Some(b)) = s.cov.get(j) {
                        cov[c * 9..c * 9 + 9].copy_from_slice(b);
                    }
                }
            }
        }
        self.rows(t_ns, z, cov, None)
    }

    /// Rows on the grid `t₀ + j / rate_hz` from the first to the last measurement
    /// stamp; each node's samples linearly interpolated onto it (NaN outside its
    /// span and across gaps longer than `max_gap_s`), as the preprocessing
    /// pipeline does; each interpolated sample has the covariance of the sample
    /// nearest in time.
    pub fn resampled(&self, rate_hz: f64, max_gap_s: f64) -> Result<Ros2Rows> {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return Err(Error::Value {
                what: "rate_hz".into(),
                problem: format!("must be finite and > 0, got {rate_hz}"),
            });
        }
        let t0 = self.t0();
        let t_end = self
            .measurements
            .iter()
            .filter_map(|s| s.t_ns.last().copied())
            .max()
            .unwrap_or(t0);
        let span = (t_end - t0) as f64 * 1e-9;
        let count = (span * rate_hz + 1e-9).floor() as u64 + 1;
        if count > 10_000_000 {
            return Err(Error::Value {
                what: "rate_hz".into(),
                problem: format!("{rate_hz} Hz over {span} s gives more than 10^7 rows"),
            });
        }
        let t_ns: Vec<u64> = (0..count)
            .map(|j| t0 + (j as f64 * 1e9 / rate_hz).round() as u64)
            .collect();
        let grid = secs(&t_ns, t0);
        let k = self.measurements.len();
        let mut z = vec![f64::NAN; t_ns.len() * k * 3];
        let mut cov = vec![f64::NAN; t_ns.len() * k * 9];
        for (i, s) in self.measurements.iter().enumerate() {
            let tr = Track::new(secs(&s.t_ns, t0), s.p.clone())?;
            let (p, _) = interpolate(&tr, &grid, max_gap_s)?;
            for (row, v) in p.iter().enumerate() {
                let c = row * k + i;
                z[c * 3..c * 3 + 3].copy_from_slice(v);
                if !v[0].is_finite() {
                    continue;
                }
                let at = t_ns[row];
                let j = match s.t_ns.binary_search(&at) {
                    Ok(j) => j,
                    Err(0) => 0,
                    Err(j) if j >= s.t_ns.len() => s.t_ns.len() - 1,
                    Err(j) => {
                        if at - s.t_ns[j - 1] <= s.t_ns[j] - at {
                            j - 1
                        } else {
                            j
                        }
                    }
                };
                if let Some(Some(b)) = s.cov.get(j) {
                    cov[c * 9..c * 9 + 9].copy_from_slice(b);
                }
            }
        }
        self.rows(t_ns, z, cov, Some(rate_hz))
    }

    /// The recording with every measurement (and the truth) in frame `target`.
    /// See [`crate::replay_input`] for what is applied and reported; this is
    /// its frame step, with `position[i]` saying whether node `i`'s values are
    /// a position (which is transformed) or not (then its frame must already
    /// be `target`).
    // Index loops: a sample's stamp, position, frame and covariance are parallel arrays.
    #[allow(clippy::needless_range_loop)]
    pub fn in_frame(
        &self,
        target: &str,
        position: &[bool],
    ) -> Result<(Ros2Recording, Vec<SourceFrames>)> {
        let tree = &self.transforms;
        let mut report = Vec::new();
        let mut convert = |source: &Source,
                           s: &Samples,
                           role: &str,
                           pos: bool|
         -> Result<Samples> {
            let mut keep = vec![true; s.t_ns.len()];
            let mut out = s.clone();
            let mut frames: Vec<FrameUse> = Vec::new();
            let mut dropped = 0usize;
            for j in 0..s.t_ns.len() {
                let f = s.frame[j].as_str();
                let idx = match frames.iter().position(|u| u.frame == f) {
                    Some(i) => i,
                    None => {
                        let path = tree.path(f, target).map_err(|e| {
                            input_err(format!("{role} source `{}`: {}", source.name(), strip(&e)))
                        })?;
                        if !pos && !path.is_identity() {
                            return Err(input_err(format!(
                                "{role} source `{}`: its messages are in frame `{f}`, the target frame is \
                                 `{target}`, and its sensor does not measure a position, so its values \
                                 cannot be transformed; use a position sensor, or choose `{f}` as the target frame",
                                source.name()
                            )));
                        }
                        frames.push(FrameUse {
                            frame: f.to_string(),
                            samples: 0,
                            transforms: tree.edges_of(&path),
                            path,
                        });
                        frames.len() - 1
                    }
                };
                let u = &mut frames[idx];
                if u.path.is_identity() {
                    u.samples += 1;
                    out.frame[j] = target.to_string();
                    continue;
                }
                match tree.transform(&u.path, s.t_ns[j])? {
                    None => {
                        keep[j] = false;
                        dropped += 1;
                    }
                    Some(iso) => {
                        u.samples += 1;
                        let p = iso * nalgebra::Point3::from(s.p[j]);
                        if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
                            return Err(input_err(format!(
                                "{role} source `{}`: the message at {} ns, {:?} in frame `{f}`, is not \
                                 finite in frame `{target}`",
                                source.name(),
                                s.t_ns[j],
                                s.p[j]
                            )));
                        }
                        out.p[j] = [p.x, p.y, p.z];
                        out.frame[j] = target.to_string();
                        if let Some(b) = s.cov[j] {
                            let r = iso.rotation.to_rotation_matrix();
                            let c = nalgebra::Matrix3::from_row_slice(&b);
                            let rc = r.matrix() * c * r.matrix().transpose();
                            let sym = (rc + rc.transpose()) * 0.5;
                            out.cov[j] = Some(std::array::from_fn(|k| sym[(k / 3, k % 3)]));
                        }
                    }
                }
            }
            let kept = out.keep(&keep);
            if kept.t_ns.is_empty() {
                return Err(input_err(format!(
                    "{role} source `{}`: none of its {} messages is within the span of the /tf \
                     transforms into frame `{target}` (a /tf transform is interpolated between its \
                     samples, never extrapolated)",
                    source.name(),
                    s.t_ns.len()
                )));
            }
            report.push(SourceFrames {
                source: source.name(),
                role: role.to_string(),
                frames,
                dropped,
            });
            Ok(kept)
        };
        let mut measurements = Vec::with_capacity(self.measurements.len());
        for (i, (src, s)) in self.sources.iter().zip(&self.measurements).enumerate() {
            measurements.push(convert(
                src,
                s,
                "measurement",
                position.get(i).copied().unwrap_or(true),
            )?);
        }
        let truth = match &self.truth {
            Some((src, s)) => Some((src.clone(), convert(src, s, "truth", true)?)),
            None => None,
        };
        Ok((
            Ros2Recording {
                sources: self.sources.clone(),
                measurements,
                truth,
                transforms: self.transforms.clone(),
                truncated: self.truncated.clone(),
            },
            report,
        ))
    }
}

/// The problem of a `Value` error without its `what` (to re-prefix it).
fn strip(e: &Error) -> String {
    match e {
        Error::Value { problem, .. } => problem.clone(),
        other => other.to_string(),
    }
}

/// How one source's messages were brought into the target frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceFrames {
    /// `TOPIC` or `TOPIC#FRAME`.
    pub source: String,
    /// `measurement` or `truth`.
    pub role: String,
    /// Each frame its messages were in.
    pub frames: Vec<FrameUse>,
    /// Messages dropped: their stamp was outside the span of a `/tf`
    /// transform on the way to the target frame.
    pub dropped: usize,
}

/// The messages of one source in one frame and the transforms that brought
/// them into the target frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameUse {
    /// The messages' frame.
    pub frame: String,
    /// Messages transformed (or kept, when `frame` is the target).
    pub samples: usize,
    /// The transforms applied, from `frame` to the target (empty: none needed).
    pub transforms: Vec<EdgeInfo>,
    /// The path through the tree.
    #[serde(skip)]
    pub path: FramePath,
}
