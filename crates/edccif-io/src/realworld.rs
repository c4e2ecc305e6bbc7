//! A seeded generator of recordings like the paper's real-world experiment (three
//! observer UAVs with RGB-D cameras, a motion-capture ground truth). The Table IV
//! analog that pre-processes them and runs every event-triggered row is
//! `edccif_sim::realworld`.
//!
//! # Generator
//!
//! - Target paths ([`PathKind`]): `manual`, an irregular manually-flown-like path
//!   (hover, initial ascent, slight descent, then quasi-rectilinear legs along two
//!   rectangular zones, stopping at the corners, with a human-like wobble); and
//!   `circle`, a programmed compound circle of mean radius 0.7 m made of concentric
//!   loops of radius 0.55, 0.7, 0.85, 0.7 m (smooth transitions).
//! - Motion capture: 120 Hz, 0.3 mm noise, its own clock offset, rare `(0, 0, 0)`
//!   samples (tracking loss).
//! - Observers: three hovering cameras about 3 m from the flight area, looking at
//!   its centre. Each measures the target's 3-D position in its camera frame
//!   (x right, y down, z along the optical axis) at 30 Hz with depth noise
//!   `σ_d = σ0 + c·d²` and lateral noise `σ_l = c_l·d` (`d` the depth), its own
//!   clock offset and timestamp jitter, dropped frames, stalls (a run of lost
//!   frames followed by a stale frame), duplicated frames, clock glitches, origin
//!   outliers `(0, 0, 0)` and depth outliers. The first and last frames of a
//!   recording are clean (the recordings are started and stopped together, which
//!   is what the pipeline's clock alignment relies on).

use std::f64::consts::PI;
use std::str::FromStr;

use nalgebra::{Matrix3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::Track;

/// The two target paths of the paper's real-world experiment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PathKind {
    /// Irregular, manually-flown-like path.
    Manual,
    /// Programmed compound circle (mean radius 0.7 m, concentric loops).
    Circle,
}

impl PathKind {
    /// Both paths, in table order.
    pub const ALL: [PathKind; 2] = [PathKind::Manual, PathKind::Circle];

    /// Lower-case name (`manual`, `circle`).
    pub fn name(self) -> &'static str {
        match self {
            PathKind::Manual => "manual",
            PathKind::Circle => "circle",
        }
    }

    /// A heading for reports.
    pub fn title(self) -> &'static str {
        match self {
            PathKind::Manual => "Manually controlled (irregular) path",
            PathKind::Circle => "Programmed compound circle (mean radius 0.7 m)",
        }
    }
}

impl FromStr for PathKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "manual" => Ok(PathKind::Manual),
            "circle" => Ok(PathKind::Circle),
            _ => Err(Error::UnknownOption {
                name: format!("path={s}"),
                expected: "one of manual, circle".into(),
            }),
        }
    }
}

/// Parameters of one generated recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RealWorldConfig {
    /// Target path.
    pub path: PathKind,
    /// Seed of everything random (path details, placement, noise, events).
    pub seed: u64,
    /// Recording length (s).
    pub duration_s: f64,
    /// Camera frame rate (Hz).
    pub camera_rate_hz: f64,
    /// Motion-capture rate (Hz).
    pub mocap_rate_hz: f64,
    /// `σ0` of the depth noise (m).
    pub depth_sigma0: f64,
    /// `c` of the depth noise `σ0 + c·d²` (1/m).
    pub depth_sigma_quad: f64,
    /// `c_l` of the lateral noise `c_l·d` (m per m of depth).
    pub lateral_sigma_per_m: f64,
    /// Motion-capture noise per axis (m).
    pub mocap_sigma: f64,
    /// Standard deviation of the camera timestamp jitter (s).
    pub jitter_s: f64,
    /// Probability that a camera frame is dropped.
    pub drop_prob: f64,
    /// Probability that a stall (6–15 frames lost, then a stale frame) starts at a frame.
    pub stall_prob: f64,
    /// Probability that a frame is delivered twice (0.5–3 ms apart).
    pub duplicate_prob: f64,
    /// Probability that a frame's timestamp jumps by 0.3–1 s (either way).
    pub glitch_prob: f64,
    /// Probability that a frame is `(0, 0, 0)`.
    pub origin_outlier_prob: f64,
    /// Probability that a frame's depth is wrong by 3–8 %.
    pub depth_outlier_prob: f64,
    /// Probability that a motion-capture sample is `(0, 0, 0)`.
    pub mocap_loss_prob: f64,
    /// Seconds the observers start recording after the motion capture (default
    /// 0: the recordings start together, as the paper's pipeline assumes; a
    /// test of the clock-offset estimate sets it).
    #[serde(default)]
    pub observer_delay_s: f64,
}

impl RealWorldConfig {
    /// The defaults for a path and seed (40 s manual path, 36 s circle).
    pub fn new(path: PathKind, seed: u64) -> Self {
        Self {
            path,
            seed,
            duration_s: match path {
                PathKind::Manual => 40.0,
                PathKind::Circle => 36.0,
            },
            camera_rate_hz: 30.0,
            mocap_rate_hz: 120.0,
            depth_sigma0: 0.002,
            depth_sigma_quad: 0.001,
            lateral_sigma_per_m: 0.0015,
            mocap_sigma: 0.0003,
            jitter_s: 0.001,
            drop_prob: 0.03,
            stall_prob: 0.004,
            duplicate_prob: 0.01,
            glitch_prob: 0.003,
            origin_outlier_prob: 0.01,
            depth_outlier_prob: 0.002,
            mocap_loss_prob: 0.002,
            observer_delay_s: 0.0,
        }
    }

    fn validate(&self) -> Result<()> {
        let pos = |v: f64, what: &str| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::Value {
                    what: what.into(),
                    problem: format!("must be finite and > 0, got {v}"),
                })
            }
        };
        pos(self.duration_s, "duration_s")?;
        pos(self.camera_rate_hz, "camera_rate_hz")?;
        pos(self.mocap_rate_hz, "mocap_rate_hz")?;
        for (v, what) in [
            (self.depth_sigma0, "depth_sigma0"),
            (self.depth_sigma_quad, "depth_sigma_quad"),
            (self.lateral_sigma_per_m, "lateral_sigma_per_m"),
            (self.mocap_sigma, "mocap_sigma"),
            (self.jitter_s, "jitter_s"),
            (self.observer_delay_s, "observer_delay_s"),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::Value {
                    what: what.into(),
                    problem: format!("must be finite and >= 0, got {v}"),
                });
            }
        }
        for (v, what) in [
            (self.drop_prob, "drop_prob"),
            (self.stall_prob, "stall_prob"),
            (self.duplicate_prob, "duplicate_prob"),
            (self.glitch_prob, "glitch_prob"),
            (self.origin_outlier_prob, "origin_outlier_prob"),
            (self.depth_outlier_prob, "depth_outlier_prob"),
            (self.mocap_loss_prob, "mocap_loss_prob"),
        ] {
            if !(0.0..=0.5).contains(&v) {
                return Err(Error::Value {
                    what: what.into(),
                    problem: format!("must be in [0, 0.5], got {v}"),
                });
            }
        }
        if self.camera_rate_hz * (self.duration_s - self.observer_delay_s) < 20.0 {
            return Err(Error::Value {
                what: "duration_s".into(),
                problem: "gives fewer than 20 camera frames".into(),
            });
        }
        Ok(())
    }
}

/// Where an observer is and how its clock runs (the generator's truth).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ObserverPose {
    /// Camera centre in the world (motion-capture) frame.
    pub position: [f64; 3],
    /// Camera-to-world rotation, row-major (columns: camera x, y, z axes in world).
    pub rotation: [[f64; 3]; 3],
    /// Clock offset: recorded time = true time + offset (s).
    pub clock_offset_s: f64,
}

/// One generated recording, as the devices would have logged it.
#[derive(Debug, Clone, PartialEq)]
pub struct RawRecording {
    /// Motion-capture track (world frame, motion-capture clock), in logging order.
    pub truth: Track,
    /// Each observer's measurements (its camera frame, its clock), in logging order
    /// (timestamps may go backwards at clock glitches).
    pub observers: Vec<Track>,
    /// The observers' true poses and clock offsets.
    pub poses: Vec<ObserverPose>,
    /// The motion-capture clock offset (s).
    pub mocap_clock_offset_s: f64,
}

// ---------------------------------------------------------------- target paths

/// Quintic minimum-jerk profile on [0, 1].
fn min_jerk(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
}

enum Path {
    Manual {
        /// (start time, start point, end point, duration)
        legs: Vec<(f64, Vector3<f64>, Vector3<f64>, f64)>,
        start: Vector3<f64>,
        wobble: Vec<(Vector3<f64>, f64, Vector3<f64>)>,
    },
    Circle {
        centre: Vector3<f64>,
        omega: f64,
        tau: f64,
        radii: [f64; 4],
        phase: f64,
    },
    /// A recorded trajectory: times (s, from 0, increasing) and positions,
    /// linearly interpolated, held at its ends.
    Recorded { t: Vec<f64>, p: Vec<Vector3<f64>> },
}

impl Path {
    fn new(kind: PathKind, rng: &mut ChaCha8Rng) -> Self {
        match kind {
            PathKind::Manual => {
                let base: [[f64; 3]; 11] = [
                    [-1.5, -1.0, 0.3],
                    [-1.45, -0.95, 1.6],
                    [-1.3, -0.85, 1.35],
                    [0.6, -0.9, 1.4],
                    [0.6, 0.7, 1.42],
                    [-1.2, 0.7, 1.38],
                    [-1.2, -0.8, 1.4],
                    [0.0, -0.2, 1.35],
                    [1.3, -0.2, 1.33],
                    [1.3, 1.2, 1.37],
                    [0.0, 1.2, 1.35],
                ];
                let pts: Vec<Vector3<f64>> = base
                    .iter()
                    .enumerate()
                    .map(|(i, p)| {
                        let j = if i == 0 { 0.0 } else { 1.0 };
                        Vector3::new(
                            p[0] + j * rng.random_range(-0.1..0.1),
                            p[1] + j * rng.random_range(-0.1..0.1),
                            p[2] + j * rng.random_range(-0.05..0.05),
                        )
                    })
                    .collect();
                let mut legs = Vec::new();
                let mut t = 1.5; // hover before take-off
                for w in pts.windows(2) {
                    let len = (w[1] - w[0]).norm();
                    let v_peak = rng.random_range(0.5..0.8);
                    let d = (1.875 * len / v_peak).max(1.0);
                    legs.push((t, w[0], w[1], d));
                    t += d + rng.random_range(0.0..0.6); // short pause at corners
                }
                let wobble = (0..4)
                    .map(|_| {
                        let amp = Vector3::new(
                            rng.random_range(0.004..0.012),
                            rng.random_range(0.004..0.012),
                            rng.random_range(0.002..0.006),
                        );
                        let f = rng.random_range(0.15..0.9);
                        let ph = Vector3::new(
                            rng.random_range(0.0..2.0 * PI),
                            rng.random_range(0.0..2.0 * PI),
                            rng.random_range(0.0..2.0 * PI),
                        );
                        (amp, f, ph)
                    })
                    .collect();
                Path::Manual {
                    legs,
                    start: pts[0],
                    wobble,
                }
            }
            PathKind::Circle => Path::Circle {
                centre: Vector3::new(
                    rng.random_range(-0.1..0.1),
                    rng.random_range(-0.1..0.1),
                    1.2 + rng.random_range(-0.05..0.05),
                ),
                omega: rng.random_range(0.45..0.55) / 0.7,
                tau: 1.0,
                radii: [0.55, 0.7, 0.85, 0.7],
                phase: rng.random_range(0.0..2.0 * PI),
            },
        }
    }

    /// Position at true time `t` (s).
    fn at(&self, t: f64) -> Vector3<f64> {
        match self {
            Path::Manual {
                legs,
                start,
                wobble,
            } => {
                let mut p = *start;
                for (t0, a, b, d) in legs {
                    if t <= *t0 {
                        break;
                    }
                    p = a + (b - a) * min_jerk((t - t0) / d);
                }
                // The wobble fades in after take-off (a drone on the ground does not wobble).
                let on = min_jerk((t - 1.5) / 2.0);
                for (amp, f, ph) in wobble {
                    for c in 0..3 {
                        p[c] += on * amp[c] * (2.0 * PI * f * t + ph[c]).sin();
                    }
                }
                p
            }
            Path::Circle {
                centre,
                omega,
                tau,
                radii,
                phase,
            } => {
                let t = t.max(0.0);
                // Angular speed ramps up from 0 with time constant tau.
                let theta = omega * (t - tau * (1.0 - (-t / tau).exp()));
                let loops = theta / (2.0 * PI);
                let j = loops.floor() as usize;
                let frac = loops - loops.floor();
                let (r0, r1) = (radii[j % 4], radii[(j + 1) % 4]);
                let r = r0 + (r1 - r0) * min_jerk((frac - 0.75) / 0.25);
                let a = theta + phase;
                centre + Vector3::new(r * a.cos(), r * a.sin(), 0.04 * (2.0 * theta).sin())
            }
            Path::Recorded { t: ts, p } => {
                let j = ts.partition_point(|&v| v <= t);
                if j == 0 {
                    return p[0];
                }
                if j == ts.len() {
                    return p[j - 1];
                }
                let u = (t - ts[j - 1]) / (ts[j] - ts[j - 1]);
                p[j - 1] + (p[j] - p[j - 1]) * u
            }
        }
    }
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    StandardNormal.sample(rng)
}

/// Generates one recording (seeded: the same config gives the same recording).
///
/// ```
/// use edccif_io::realworld::{generate, PathKind, RealWorldConfig};
/// let mut cfg = RealWorldConfig::new(PathKind::Circle, 1);
/// cfg.duration_s = 5.0;
/// let rec = generate(&cfg).unwrap();
/// assert_eq!(rec.observers.len(), 3);
/// assert!(rec.truth.len() > 3 * rec.observers[0].len());
/// assert_eq!(rec, generate(&cfg).unwrap());
/// ```
pub fn generate(cfg: &RealWorldConfig) -> Result<RawRecording> {
    cfg.validate()?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x005E_ED0F_0B5E_12E5);
    let path = Path::new(cfg.path, &mut rng);
    let stage = Stage {
        look_at: Vector3::new(0.0, 0.0, 1.2),
        radius: (2.8, 3.4),
        height: (1.0, 1.6),
    };
    record(cfg, &path, &stage, None, rng)
}

/// Generates a recording whose target follows a recorded trajectory `target`
/// (a motion-capture track: times in s, positions in m, e.g. a EuRoC or TUM
/// ground truth): the observers (as in [`generate`]: three RGB-D cameras with
/// the same noise, clock and frame-loss model) stand 2.8–3.4 m beyond the
/// trajectory's horizontal extent around its centroid, at its mean height −0.2
/// to +0.4 m, looking at the centroid, and measure the target's position
/// interpolated linearly between the track's samples; the motion-capture truth
/// is `target` itself (its own samples and rate, on a clock offset like
/// [`generate`]'s), with no noise or losses added. The recording lasts as long
/// as the track (`cfg.duration_s` and `cfg.path` are not used; `cfg.seed` and
/// the noise settings are).
///
/// ```
/// use edccif_io::realworld::{generate_following, PathKind, RealWorldConfig};
/// use edccif_io::Track;
/// let t: Vec<f64> = (0..=500).map(|j| j as f64 * 0.01).collect();
/// let p = t.iter().map(|&s| [s.cos(), s.sin(), 1.0 + 0.1 * s]).collect();
/// let target = Track::new(t, p)?;
/// let rec = generate_following(&RealWorldConfig::new(PathKind::Manual, 3), &target)?;
/// assert_eq!(rec.truth.p, target.p);
/// assert_eq!(rec.observers.len(), 3);
/// assert!(rec.observers[0].len() > 140);
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn generate_following(cfg: &RealWorldConfig, target: &Track) -> Result<RawRecording> {
    if target.len() < 2 {
        return Err(Error::Value {
            what: "target track".into(),
            problem: format!("needs at least 2 samples, got {}", target.len()),
        });
    }
    target.check_increasing("target track")?;
    let t0 = target.t[0];
    let span = target.t[target.len() - 1] - t0;
    let cfg = RealWorldConfig {
        duration_s: span,
        ..cfg.clone()
    };
    cfg.validate()?;
    let p: Vec<Vector3<f64>> = target.p.iter().map(|q| Vector3::from(*q)).collect();
    let centroid = p.iter().sum::<Vector3<f64>>() / p.len() as f64;
    let extent = p
        .iter()
        .map(|q| (q.xy() - centroid.xy()).norm())
        .fold(0.0, f64::max);
    let path = Path::Recorded {
        t: target.t.iter().map(|v| v - t0).collect(),
        p,
    };
    let stage = Stage {
        look_at: centroid,
        radius: (2.8 + extent, 3.4 + extent),
        height: (centroid.z - 0.2, centroid.z + 0.4),
    };
    let rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x005E_ED0F_0B5E_12E5);
    record(&cfg, &path, &stage, Some(target), rng)
}

/// Where the observers stand: around `look_at`, at a horizontal distance drawn
/// from `radius` and a height drawn from `height`.
struct Stage {
    look_at: Vector3<f64>,
    radius: (f64, f64),
    height: (f64, f64),
}

/// The observers' and the motion capture's recordings of the target on `path`
/// (`truth`: a recorded track used as the motion capture's samples instead of
/// simulated ones).
fn record(
    cfg: &RealWorldConfig,
    path: &Path,
    stage: &Stage,
    truth: Option<&Track>,
    mut rng: ChaCha8Rng,
) -> Result<RawRecording> {
    let look_at = stage.look_at;
    // Observers: about 3 m from the flight area, 120° apart.
    let mut poses = Vec::new();
    for i in 0..3 {
        let a = 2.0 * PI * i as f64 / 3.0 + PI / 2.0 + rng.random_range(-0.2..0.2);
        let r = rng.random_range(stage.radius.0..stage.radius.1);
        let c = Vector3::new(
            look_at.x + r * a.cos(),
            look_at.y + r * a.sin(),
            rng.random_range(stage.height.0..stage.height.1),
        );
        let aim = look_at
            + Vector3::new(
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.1..0.1),
            );
        let f = (aim - c).normalize();
        let right = f.cross(&Vector3::z()).normalize();
        let down = f.cross(&right);
        let rot = Matrix3::from_columns(&[right, down, f]);
        poses.push(ObserverPose {
            position: [c[0], c[1], c[2]],
            rotation: [0, 1, 2].map(|i| [0, 1, 2].map(|j| rot[(i, j)])),
            clock_offset_s: 1.7e9 + rng.random_range(-5.0..5.0),
        });
    }
    let mocap_clock_offset_s = rng.random_range(100.0..200.0);
    // Motion capture.
    let mut truth_track = Track::default();
    if let Some(rec) = truth {
        let t0 = rec.t.first().copied().unwrap_or(0.0);
        truth_track.t = rec
            .t
            .iter()
            .map(|t| t - t0 + mocap_clock_offset_s)
            .collect();
        truth_track.p = rec.p.clone();
    } else {
        let truth = &mut truth_track;
        let start = rng.random_range(0.0..0.003);
        let end = cfg.duration_s + rng.random_range(0.3..1.0);
        let period = 1.0 / cfg.mocap_rate_hz;
        let count = ((end - start) / period).floor() as usize;
        for j in 0..=count {
            let t = start + j as f64 * period;
            let stamp = t + mocap_clock_offset_s + 1e-4 * normal(&mut rng);
            let clean = j < 3 || j + 3 > count;
            let p = if !clean && rng.random::<f64>() < cfg.mocap_loss_prob {
                Vector3::zeros()
            } else {
                path.at(t) + Vector3::from_fn(|_, _| cfg.mocap_sigma * normal(&mut rng))
            };
            truth.t.push(stamp);
            truth.p.push([p[0], p[1], p[2]]);
        }
    }
    // Cameras.
    let mut observers = Vec::new();
    for pose in &poses {
        let c = Vector3::from(pose.position);
        let rot = Matrix3::from_fn(|i, j| pose.rotation[i][j]);
        let measure = |t: f64, rng: &mut ChaCha8Rng, depth_factor: f64| -> [f64; 3] {
            let pc = rot.transpose() * (path.at(t) - c);
            let d = pc[2].max(0.1);
            let sd = cfg.depth_sigma0 + cfg.depth_sigma_quad * d * d;
            let sl = cfg.lateral_sigma_per_m * d;
            let m = Vector3::new(
                pc[0] + sl * normal(rng),
                pc[1] + sl * normal(rng),
                pc[2] + sd * normal(rng),
            ) * depth_factor;
            [m[0], m[1], m[2]]
        };
        let start = rng.random_range(0.0..0.003) + cfg.observer_delay_s;
        let end = cfg.duration_s + rng.random_range(0.0..1.0);
        let period = 1.0 / cfg.camera_rate_hz;
        let count = ((end - start) / period).floor() as usize;
        let mut tr = Track::default();
        let mut j = 0;
        let mut stale: Option<[f64; 3]> = None;
        while j <= count {
            let t = start + j as f64 * period;
            let clean = j < 3 || j + 3 > count;
            let stamp = |rng: &mut ChaCha8Rng| t + pose.clock_offset_s + cfg.jitter_s * normal(rng);
            if clean {
                let m = measure(t, &mut rng, 1.0);
                let s = stamp(&mut rng);
                tr.t.push(s);
                tr.p.push(m);
                j += 1;
                continue;
            }
            let u: f64 = rng.random();
            if u < cfg.stall_prob {
                // The frame captured now is delivered, stale, after the stall.
                stale = Some(measure(t, &mut rng, 1.0));
                j += rng.random_range(6..=15);
                continue;
            }
            if let Some(m) = stale.take() {
                let s = stamp(&mut rng);
                tr.t.push(s);
                tr.p.push(m);
                j += 1;
                continue;
            }
            if rng.random::<f64>() < cfg.drop_prob {
                j += 1;
                continue;
            }
            let depth_factor = if rng.random::<f64>() < cfg.depth_outlier_prob {
                if rng.random::<bool>() {
                    rng.random_range(1.03..1.08)
                } else {
                    rng.random_range(0.92..0.97)
                }
            } else {
                1.0
            };
            let mut m = measure(t, &mut rng, depth_factor);
            if rng.random::<f64>() < cfg.origin_outlier_prob {
                m = [0.0; 3];
            }
            let mut s = stamp(&mut rng);
            if rng.random::<f64>() < cfg.glitch_prob {
                let jump = rng.random_range(0.3..1.0);
                s += if rng.random::<bool>() { jump } else { -jump };
            }
            tr.t.push(s);
            tr.p.push(m);
            if rng.random::<f64>() < cfg.duplicate_prob {
                tr.t.push(s + rng.random_range(0.0005..0.003));
                tr.p.push(m);
            }
            j += 1;
        }
        observers.push(tr);
    }
    Ok(RawRecording {
        truth: truth_track,
        observers,
        poses,
        mocap_clock_offset_s,
    })
}
