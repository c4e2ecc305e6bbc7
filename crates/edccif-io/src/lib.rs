//! # edccif-io
//!
//! Log input/output and the real-world data pipeline of edccif: file formats
//! and data preparation only, no estimation (the runner, scenarios and the
//! experiments that use these live in `edccif-sim`, which depends on this crate).
//!
//! - [`tum`]: TUM trajectory files (`timestamp tx ty tz qx qy qz qw`).
//! - [`mcap_io`]: a run as an MCAP file that Foxglove opens (truth, measurements,
//!   local and fused estimates, a 3-D scene with covariance ellipsoids), and the
//!   replay of measurements from such a file.
//! - [`ros2`]: positions from ROS 2 recordings (CDR `PointStamped`,
//!   `PoseStamped`, `PoseWithCovarianceStamped`, `TFMessage`, `Odometry` in an
//!   MCAP bag), chosen by topic and frame, with their own stamps, frames and
//!   covariances.
//! - [`frames`]: the tree of a recording's `/tf` and `/tf_static` transforms,
//!   interpolated at any stamp (nalgebra `Isometry3`).
//! - [`replay_input`]: a ROS 2 recording made ready for a replay: one target
//!   frame, each step's measurement noise, rows, and a report of what was done.
//! - [`preprocess`]: the paper's data pre-processing pipeline (Sec. "Data
//!   Pre-processing"): abnormal time gaps, origin outliers, common start/end,
//!   Umeyama spatial alignment, ground-truth downsampling, interpolation to a
//!   common frame rate. Every step returns what it removed or changed.
//! - [`realworld`]: a seeded generator of real-world-like recordings (three
//!   RGB-D observers and a motion-capture truth), on generated paths or
//!   following a recorded trajectory. The Table IV analog that runs
//!   generator → pipeline → every event-triggered row is `edccif_sim::realworld`.
//! - [`watch`]: how a caller counts a long computation's work and stops it.
//! - [`flights`]: real flights of public datasets (EuRoC V1_02, TUM
//!   freiburg1_xyz) read from a data directory, as targets.
//!
//! The file formats and topics are documented in `docs/formats.md`.
//!
//! Arrays crossing this module's API are flat and row-major with their shapes
//! stated, so that bindings can pass NumPy arrays straight through.

mod error;

pub use error::{Error, Result};

pub mod flights;
pub mod frames;
pub mod mcap_io;
mod mcap_read;
pub mod preprocess;
pub mod realworld;
pub mod replay_input;
pub mod ros2;
pub mod tum;
pub mod watch;

pub use flights::Flight;
pub use mcap_io::{
    read_measurements, read_measurements_file, write_mcap, write_mcap_file, McapReplay,
    McapRunData, McapWriteOptions,
};
pub use preprocess::{run_pipeline, AlignedData, PipelineOptions, PipelineReport};
pub use realworld::{
    generate, generate_following, ObserverPose, PathKind, RawRecording, RealWorldConfig,
};
pub use tum::{format_tum, parse_tum, read_tum, write_tum, TumTrajectory};

/// A timestamped 3-D track: `t[j]` (s) and the position `p[j]` (m).
///
/// ```
/// use edccif_io::Track;
/// let tr = Track::from_flat(&[0.0, 0.1], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
/// assert_eq!(tr.p[1], [4.0, 5.0, 6.0]);
/// assert_eq!(tr.positions_flat(), vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
/// assert!(Track::from_flat(&[0.0], &[1.0, 2.0]).is_err());
/// ```
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Track {
    /// Timestamps (s).
    pub t: Vec<f64>,
    /// Positions (m), one per timestamp.
    pub p: Vec<[f64; 3]>,
}

impl Track {
    /// A track from timestamps and positions of equal length (all values finite).
    pub fn new(t: Vec<f64>, p: Vec<[f64; 3]>) -> Result<Self> {
        if t.len() != p.len() {
            return Err(Error::Shape {
                what: "track positions".into(),
                expected: format!("({}, 3)", t.len()),
                got: format!("({}, 3)", p.len()),
            });
        }
        if let Some(j) = t.iter().position(|v| !v.is_finite()) {
            return Err(Error::Value {
                what: format!("track timestamp [{j}]"),
                problem: format!("must be finite, got {}", t[j]),
            });
        }
        if let Some(j) = p.iter().position(|q| q.iter().any(|v| !v.is_finite())) {
            return Err(Error::Value {
                what: format!("track position [{j}]"),
                problem: format!("must be finite, got {:?}", p[j]),
            });
        }
        Ok(Self { t, p })
    }

    /// A track from flat arrays: `t` of shape `(M,)`, `p` row-major `(M, 3)`.
    pub fn from_flat(t: &[f64], p: &[f64]) -> Result<Self> {
        if p.len() != 3 * t.len() {
            return Err(Error::Shape {
                what: "track positions".into(),
                expected: format!("({}, 3)", t.len()),
                got: format!("{} values", p.len()),
            });
        }
        Self::new(
            t.to_vec(),
            p.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        )
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether the track has no sample.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Positions as a flat row-major `(M, 3)` array.
    pub fn positions_flat(&self) -> Vec<f64> {
        self.p.iter().flatten().copied().collect()
    }

    /// The samples whose `keep` flag is set.
    pub(crate) fn select(&self, keep: &[bool]) -> Track {
        let mut out = Track::default();
        for (j, k) in keep.iter().enumerate() {
            if *k {
                out.t.push(self.t[j]);
                out.p.push(self.p[j]);
            }
        }
        out
    }

    /// Errors unless the timestamps are strictly increasing; `what` names the track.
    pub fn check_increasing(&self, what: &str) -> Result<()> {
        for j in 1..self.t.len() {
            if self.t[j] <= self.t[j - 1] {
                return Err(Error::Value {
                    what: what.to_string(),
                    problem: format!(
                        "timestamps must be strictly increasing, but t[{j}] = {} follows t[{}] = {} \
                         (remove abnormal gaps first)",
                        self.t[j],
                        j - 1,
                        self.t[j - 1]
                    ),
                });
            }
        }
        Ok(())
    }
}
