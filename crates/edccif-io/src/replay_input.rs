//! A ROS 2 recording made ready for a replay: every source in one frame, the
//! measurement noise of each step, the rows, and a report of what was done.
//!
//! [`prepare`] takes what [`read_ros2`](crate::ros2::read_ros2) read and
//!
//! 1. **frames**: brings every measurement and the truth into one target frame
//!    ([`InputOptions::frame`]; default: the frame of the first measurement
//!    source's first message) through the recording's `/tf` and `/tf_static`
//!    transforms ([`crate::frames`]), each message at its own stamp; a
//!    position `p` becomes `R p + t` and its covariance `R Σ Rᵀ`. The
//!    orientation of a pose message is not used: a pose's position enters
//!    the replay only through this chain of transforms. A message whose stamp
//!    is outside the span of a `/tf` transform on its way is dropped and
//!    counted; a source whose frame no transform connects to the target is
//!    refused with an error naming both frames and the missing link;
//! 2. **noise** ([`NoiseChoice`]): `message` (the default) takes the position
//!    block of each message's covariance, where it has one
//!    (`PoseWithCovarianceStamped`, `Odometry`), as that step's measurement
//!    noise `R`; where a message says its covariance is unknown (all zero, all
//!    −1), or carries none, the sensor model's `R` is used, and the report
//!    counts the fallbacks per topic. A covariance that is neither unknown nor
//!    symmetric positive definite is an error. `model` (also spelt
//!    `scenario`) always uses the sensor model's `R`; a number `σ > 0` uses
//!    `σ² I` (metres) for every measurement;
//! 3. **rows**: on the messages' own stamps, or resampled at
//!    [`InputOptions::rate_hz`] (see [`Ros2Recording::on_stamps`] and
//!    [`Ros2Recording::resampled`]). No clock offset is applied: each message
//!    is placed at its header stamp.
//!
//! ```
//! use edccif_io::ros2::{encode_cdr, Header, Point, PointStamped, Source, Time};
//! use edccif_io::replay_input::{prepare, InputOptions};
//! # use edccif_io::ros2::read_ros2;
//! // Two PointStamped topics in frame `world`: nothing to transform.
//! let mut cur = std::io::Cursor::new(Vec::new());
//! let mut w = mcap::Writer::new(&mut cur).unwrap();
//! let schema = w.add_schema("geometry_msgs/msg/PointStamped", "ros2msg", b"").unwrap();
//! for (i, topic) in ["/a", "/b"].iter().enumerate() {
//!     let ch = w.add_channel(schema, topic, "cdr", &Default::default()).unwrap();
//!     for k in 0..3u32 {
//!         let msg = PointStamped { header: Header { stamp: Time { sec: 1, nanosec: k * 100_000_000 },
//!                                                   frame_id: "world".into() },
//!                                  point: Point { x: k as f64, y: i as f64, z: 0.0 } };
//!         let h = mcap::records::MessageHeader { channel_id: ch, sequence: k, log_time: 0, publish_time: 0 };
//!         w.write_to_known_channel(&h, &encode_cdr(&msg)).unwrap();
//!     }
//! }
//! w.finish().unwrap();
//! drop(w);
//! let rec = read_ros2(&cur.into_inner(), &[Source::parse("/a")?, Source::parse("/b")?], None)?;
//! let input = prepare(&rec, &InputOptions::default(), &[true, true])?;
//! assert_eq!(input.rows.steps, 3);
//! assert_eq!(input.report.frame, "world");
//! assert!(input.noise.is_none()); // PointStamped carries no covariance: the model's R
//! # Ok::<(), edccif_io::Error>(())
//! ```

use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::ros2::{Ros2Recording, Ros2Rows, SourceFrames};

/// Where each step's measurement noise comes from.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseChoice {
    /// The message's covariance where it has a usable one, else the sensor model's.
    #[default]
    Message,
    /// The sensor model's (or scenario's) `R`.
    Model,
    /// `σ² I` with this `σ` (m) for every measurement.
    Sigma(f64),
}

impl FromStr for NoiseChoice {
    type Err = Error;
    /// `message`, `model` (or `scenario`), or a standard deviation `σ > 0` in metres.
    ///
    /// ```
    /// use edccif_io::replay_input::NoiseChoice;
    /// assert_eq!("message".parse::<NoiseChoice>()?, NoiseChoice::Message);
    /// assert_eq!("scenario".parse::<NoiseChoice>()?, NoiseChoice::Model);
    /// assert_eq!("0.05".parse::<NoiseChoice>()?, NoiseChoice::Sigma(0.05));
    /// assert!("-1".parse::<NoiseChoice>().is_err() && "loud".parse::<NoiseChoice>().is_err());
    /// # Ok::<(), edccif_io::Error>(())
    /// ```
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "message" => Ok(NoiseChoice::Message),
            "model" | "scenario" => Ok(NoiseChoice::Model),
            other => match other.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(NoiseChoice::Sigma(v)),
                _ => Err(Error::Value {
                    what: format!("noise {s:?}"),
                    problem: "expected `message`, `scenario` (the sensor model's noise) or a \
                              standard deviation > 0 in metres"
                        .into(),
                }),
            },
        }
    }
}

/// What [`prepare`] does (see the module documentation).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct InputOptions {
    /// The target frame; `None`: the frame of the first measurement source's
    /// first message.
    pub frame: Option<String>,
    /// Pairs of frames declared the same (an identity transform), for
    /// recordings that name one frame twice.
    pub same_frames: Vec<(String, String)>,
    /// Resample at this rate (Hz) instead of running on the stamps.
    pub rate_hz: Option<f64>,
    /// Longest gap bridged when resampling (s); default 3 periods.
    pub max_gap_s: Option<f64>,
    /// The measurement noise of each step.
    pub noise: NoiseChoice,
}

/// The noise one measurement source's steps got.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseUse {
    /// `TOPIC` or `TOPIC#FRAME`.
    pub source: String,
    /// `message`, `model` or `sigma`.
    pub noise: String,
    /// In words, e.g. "the messages' covariance (rotated into `map`)".
    pub detail: String,
    /// Messages whose own covariance was used.
    pub from_messages: usize,
    /// Messages whose covariance was unknown (all zero or −1), given the
    /// sensor model's `R` instead.
    pub unknown_fallbacks: usize,
    /// A warning to show once for this source (the fallbacks), if any.
    pub warning: Option<String>,
}

/// The truth and how it was compared.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthUse {
    /// `TOPIC` or `TOPIC#FRAME`.
    pub source: String,
    /// The frames its messages were in.
    pub frames: Vec<String>,
    /// The frame it was compared in (the target frame).
    pub compared_in: String,
    /// Whether the estimates and the truth were compared in one frame (always,
    /// when a truth is read from a ROS 2 recording: an unreachable truth is refused).
    pub same_frame: bool,
}

/// What [`prepare`] did, for the replay's report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputReport {
    /// The target frame.
    pub frame: String,
    /// Why that frame: `--frame` or the first measurement.
    pub frame_chosen_by: String,
    /// Per source: its frames and the transforms applied, messages dropped.
    pub sources: Vec<SourceFrames>,
    /// Per measurement source: the noise of its steps.
    pub noise: Vec<NoiseUse>,
    /// Messages dropped in all (outside a `/tf` transform's span).
    pub dropped: usize,
    /// `stamps` or `resampled`.
    pub timing: String,
    /// The grid's rate when resampled.
    pub rate_hz: Option<f64>,
    /// Time offsets applied to the streams.
    pub offsets: String,
    /// The truth, if one was read.
    pub truth: Option<TruthUse>,
}

/// A recording ready to replay.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayInput {
    /// The rows (in the target frame).
    pub rows: Ros2Rows,
    /// Per-step measurement noise `(T, N, 3, 3)`: NaN where the sensor model's
    /// `R` holds; `None` when it holds everywhere.
    pub noise: Option<Vec<f64>>,
    /// What was done.
    pub report: InputReport,
}

/// Makes a recording ready to replay (see the module documentation).
/// `position[i]` says whether node `i`'s sensor measures a position (the
/// values are then transformed and may take the messages' covariance);
/// other sensors' messages must already be in the target frame, and take
/// their model's noise.
pub fn prepare(rec: &Ros2Recording, opt: &InputOptions, position: &[bool]) -> Result<ReplayInput> {
    let k = rec.measurements.len();
    if position.len() != k {
        return Err(Error::Shape {
            what: "position flags".into(),
            expected: format!("({k},), one per measurement source"),
            got: format!("({},)", position.len()),
        });
    }
    let mut rec = rec.clone();
    for (a, b) in &opt.same_frames {
        rec.transforms.declare_same(a, b)?;
    }
    rec.transforms.finish()?;
    let (target, chosen_by) = match &opt.frame {
        Some(f) => (f.clone(), "--frame (frame=)".to_string()),
        None => {
            let f = rec.measurements[0]
                .frame
                .first()
                .cloned()
                .unwrap_or_default();
            (
                f,
                format!("the first measurement (`{}`)", rec.sources[0].name()),
            )
        }
    };
    let (framed, sources) = rec.in_frame(&target, position)?;
    let rows = match opt.rate_hz {
        None => framed.on_stamps()?,
        Some(r) => framed.resampled(r, opt.max_gap_s.unwrap_or(3.0 / r))?,
    };
    let (noise, noise_use) = step_noise(&framed, &rows, opt.noise, position, &target)?;
    let truth = framed.truth.as_ref().map(|(src, _)| {
        let frames = sources
            .iter()
            .find(|s| s.role == "truth")
            .map(|s| s.frames.iter().map(|u| u.frame.clone()).collect())
            .unwrap_or_default();
        TruthUse {
            source: src.name(),
            frames,
            compared_in: target.clone(),
            same_frame: true,
        }
    });
    let report = InputReport {
        frame: target,
        frame_chosen_by: chosen_by,
        dropped: sources.iter().map(|s| s.dropped).sum(),
        sources,
        noise: noise_use,
        timing: if opt.rate_hz.is_some() { "resampled" } else { "stamps" }.into(),
        rate_hz: opt.rate_hz,
        offsets: match opt.rate_hz {
            None => "none: each message at its header stamp".into(),
            Some(r) => format!(
                "none: each message at its header stamp, then interpolated linearly onto a {r} Hz grid"
            ),
        },
        truth,
    };
    Ok(ReplayInput {
        rows,
        noise,
        report,
    })
}

fn step_noise(
    rec: &Ros2Recording,
    rows: &Ros2Rows,
    choice: NoiseChoice,
    position: &[bool],
    target: &str,
) -> Result<(Option<Vec<f64>>, Vec<NoiseUse>)> {
    let k = rows.nodes;
    let mut out = vec![f64::NAN; rows.steps * k * 9];
    let mut any = false;
    let mut uses = Vec::with_capacity(k);
    for (i, (src, s)) in rec.sources.iter().zip(&rec.measurements).enumerate() {
        let name = src.name();
        let cells = (0..rows.steps).map(|t| t * k + i);
        let measured = |c: usize| rows.z[c * 3].is_finite();
        let use_ = match choice {
            NoiseChoice::Sigma(sigma) => {
                if !position[i] {
                    return Err(Error::Value {
                        what: format!("noise {sigma}"),
                        problem: format!(
                            "node {i} (source `{name}`) does not measure a position, so a noise in \
                             metres does not apply to it; use `message` or `scenario`"
                        ),
                    });
                }
                let v = sigma * sigma;
                for c in cells.filter(|&c| measured(c)) {
                    out[c * 9..c * 9 + 9].copy_from_slice(&[v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v]);
                    any = true;
                }
                NoiseUse {
                    source: name,
                    noise: "sigma".into(),
                    detail: format!("σ = {sigma} m on each axis (noise=VALUE)"),
                    from_messages: 0,
                    unknown_fallbacks: 0,
                    warning: None,
                }
            }
            NoiseChoice::Model => NoiseUse {
                source: name,
                noise: "model".into(),
                detail: "the sensor model's R (noise=scenario)".into(),
                from_messages: 0,
                unknown_fallbacks: 0,
                warning: None,
            },
            NoiseChoice::Message if !s.has_covariance() => NoiseUse {
                source: name,
                noise: "model".into(),
                detail: format!("the sensor model's R ({} carries no covariance)", s.schema),
                from_messages: 0,
                unknown_fallbacks: 0,
                warning: None,
            },
            NoiseChoice::Message if !position[i] => NoiseUse {
                source: name,
                noise: "model".into(),
                detail: "the sensor model's R (the sensor does not measure a position, so the \
                         messages' position covariance does not apply)"
                    .into(),
                from_messages: 0,
                unknown_fallbacks: 0,
                warning: None,
            },
            NoiseChoice::Message => {
                if let Some(why) = &s.invalid_covariance {
                    return Err(Error::Value {
                        what: format!("measurement source `{name}`"),
                        problem: format!(
                            "{why}; expected a symmetric positive definite position block, or an \
                             unknown one (all zero or -1); pass noise=scenario (CLI --noise scenario) \
                             to use the sensor model's noise instead"
                        ),
                    });
                }
                let mut from = 0;
                for c in cells.filter(|&c| measured(c)) {
                    if rows.cov[c * 9].is_finite() {
                        out[c * 9..c * 9 + 9].copy_from_slice(&rows.cov[c * 9..c * 9 + 9]);
                        from += 1;
                        any = true;
                    }
                }
                let n = s.unknown_covariances;
                NoiseUse {
                    source: name.clone(),
                    noise: "message".into(),
                    detail: format!("the messages' position covariance, in frame `{target}`"),
                    from_messages: from,
                    unknown_fallbacks: n,
                    warning: (n > 0).then(|| {
                        format!(
                            "{n} message(s) of `{name}` give an unknown covariance (all zero or -1); \
                             the sensor model's noise is used for them"
                        )
                    }),
                }
            }
        };
        uses.push(use_);
    }
    Ok((any.then_some(out), uses))
}
