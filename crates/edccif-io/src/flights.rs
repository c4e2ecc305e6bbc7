//! Real flights: motion-capture trajectories of public datasets, read as
//! [`Track`]s to serve as the *true* motion of a target
//! ([`crate::realworld::generate_following`] simulates observers around them).
//!
//! | [`Flight`] | file | what | source |
//! |---|---|---|---|
//! | `euroc-v102` | `V102_groundtruth.csv` | EuRoC MAV, Vicon Room 1 02: a micro aerial vehicle flight, Vicon ground truth at 200 Hz, 83.5 s | M. Burri et al., "The EuRoC micro aerial vehicle datasets", IJRR 35(10), 2016 |
//! | `tum-fr1-xyz` | `freiburg1_xyz-groundtruth.txt` | TUM RGB-D, freiburg1_xyz: a hand-held RGB-D camera, motion-capture ground truth at 100 Hz, 30.1 s | J. Sturm et al., "A benchmark for the evaluation of RGB-D SLAM systems", IROS 2012 (CC BY 4.0) |
//!
//! The files are not part of the repository: they are read at run time from a
//! data directory (in this project `../shared/data` beside the repository
//! root), and a missing file is an error that names the path and the option
//! to point elsewhere.
//!
//! EuRoC ground-truth CSV: a `#` header line, then
//! `timestamp_ns, px, py, pz, qw, qx, qy, qz, vx, vy, vz, bwx, bwy, bwz, bax, bay, baz`
//! per line; only the time (converted to seconds) and the position are read.
//! TUM: see [`crate::tum`].

use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::Track;

/// A real flight of a public dataset (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Flight {
    /// EuRoC MAV dataset, Vicon Room 1 02 ("medium"), Vicon ground truth.
    EurocV102,
    /// TUM RGB-D dataset, freiburg1_xyz, motion-capture ground truth.
    TumFr1Xyz,
}

impl Flight {
    /// Both flights, in table order.
    pub const ALL: [Flight; 2] = [Flight::EurocV102, Flight::TumFr1Xyz];

    /// Short name (`euroc-v102`, `tum-fr1-xyz`).
    pub fn name(self) -> &'static str {
        match self {
            Flight::EurocV102 => "euroc-v102",
            Flight::TumFr1Xyz => "tum-fr1-xyz",
        }
    }

    /// The ground-truth file's name in the data directory.
    pub fn file_name(self) -> &'static str {
        match self {
            Flight::EurocV102 => "V102_groundtruth.csv",
            Flight::TumFr1Xyz => "freiburg1_xyz-groundtruth.txt",
        }
    }

    /// A heading for reports.
    pub fn title(self) -> &'static str {
        match self {
            Flight::EurocV102 => "EuRoC MAV V1_02 (Vicon Room 1, medium): a real MAV flight",
            Flight::TumFr1Xyz => "TUM RGB-D freiburg1_xyz: a hand-held camera's trajectory",
        }
    }

    /// The dataset's citation.
    pub fn citation(self) -> &'static str {
        match self {
            Flight::EurocV102 => {
                "M. Burri, J. Nikolic, P. Gohl, T. Schneider, J. Rehder, S. Omari, M. W. Achtelik \
                 and R. Siegwart, \"The EuRoC micro aerial vehicle datasets\", The International \
                 Journal of Robotics Research 35(10), 2016 (ETH Zurich, ASL)"
            }
            Flight::TumFr1Xyz => {
                "J. Sturm, N. Engelhard, F. Endres, W. Burgard and D. Cremers, \"A benchmark for \
                 the evaluation of RGB-D SLAM systems\", IROS 2012 (TU Munich; CC BY 4.0)"
            }
        }
    }

    /// Reads the flight's ground truth from `data_dir` (times in s, positions in m).
    pub fn load(self, data_dir: impl AsRef<Path>) -> Result<Track> {
        let path = data_dir.as_ref().join(self.file_name());
        let text = std::fs::read_to_string(&path).map_err(|e| {
            Error::Io(format!(
                "cannot read the {} ground truth {}: {e} (the real flights are read from a data \
                 directory holding {}; by default ../shared/data beside the repository root, \
                 elsewhere with --data-dir DIR)",
                self.name(),
                path.display(),
                self.file_name()
            ))
        })?;
        let track = match self {
            Flight::EurocV102 => parse_euroc_groundtruth(&text),
            Flight::TumFr1Xyz => crate::tum::parse_tum(&text).map(|t| t.track),
        }
        .map_err(|e| match e {
            Error::Value { what, problem } => Error::Value {
                what: format!("{what} ({})", path.display()),
                problem,
            },
            other => other,
        })?;
        track.check_increasing(&format!("{} ({})", self.name(), path.display()))?;
        Ok(track)
    }
}

impl FromStr for Flight {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Flight::ALL
            .into_iter()
            .find(|f| f.name() == s.trim().to_ascii_lowercase())
            .ok_or_else(|| Error::UnknownOption {
                name: format!("flight={s}"),
                expected: "one of euroc-v102, tum-fr1-xyz".into(),
            })
    }
}

/// Parses a EuRoC ground-truth CSV (see the module docs): time (ns → s) and
/// position of each line; `#` lines and blank lines are skipped.
///
/// ```
/// use edccif_io::flights::parse_euroc_groundtruth;
/// let text = "#timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z\n\
///             1403715524907143168,0.5,2.0,0.97,1,0,0,0\n\
///             1403715524912143104,0.6,2.1,0.98,1,0,0,0\n";
/// let tr = parse_euroc_groundtruth(text)?;
/// assert_eq!(tr.p[1], [0.6, 2.1, 0.98]);
/// assert!((tr.t[1] - tr.t[0] - 0.005).abs() < 1e-6);
/// assert!(parse_euroc_groundtruth("1,2,3\n").is_err());
/// # Ok::<(), edccif_io::Error>(())
/// ```
pub fn parse_euroc_groundtruth(text: &str) -> Result<Track> {
    let mut t = Vec::new();
    let mut p = Vec::new();
    for (j, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |problem: String| Error::Value {
            what: format!("EuRoC ground truth line {}", j + 1),
            problem,
        };
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() < 4 {
            return Err(bad(format!(
                "{} comma-separated fields; expected at least 4 (timestamp_ns, px, py, pz, ...)",
                f.len()
            )));
        }
        let ns: u64 = f[0]
            .parse()
            .map_err(|_| bad(format!("timestamp {:?} is not an integer of ns", f[0])))?;
        let mut q = [0.0; 3];
        for c in 0..3 {
            q[c] = f[c + 1]
                .parse()
                .map_err(|_| bad(format!("position field {:?} is not a number", f[c + 1])))?;
        }
        t.push(ns as f64 * 1e-9);
        p.push(q);
    }
    if t.is_empty() {
        return Err(Error::Value {
            what: "EuRoC ground truth".into(),
            problem: "holds no sample".into(),
        });
    }
    Track::new(t, p)
}
