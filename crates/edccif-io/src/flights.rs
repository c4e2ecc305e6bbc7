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
//! Any other motion-capture ground truth in one of these two formats is a
//! [`FlightFile`] too (`edccif reproduce --flight FILE`); its format is told
//! from its first data line.
//!
//! EuRoC ground-truth CSV: a `#` header line, then
//! `timestamp_ns, px, py, pz, qw, qx, qy, qz, vx, vy, vz, bwx, bwy, bwz, bax, bay, baz`
//! per line; only the time (converted to seconds) and the position are read.
//! TUM: see [`crate::tum`].

use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::preprocess::{
    check_duplicate_stamps, drop_duplicate_stamps, DuplicateReport, DuplicateStamps,
};
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

/// The two ground-truth formats a [`FlightFile`] is read in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TruthFormat {
    /// EuRoC ground-truth CSV (`timestamp_ns, px, py, pz, ...`).
    Euroc,
    /// TUM trajectory (`timestamp tx ty tz qx qy qz qw`).
    Tum,
}

impl TruthFormat {
    /// The format of a ground-truth text, from its first line that is neither
    /// empty nor a `#` comment: commas make it EuRoC, else TUM. `None` for a text
    /// without data.
    ///
    /// ```
    /// use edccif_io::flights::TruthFormat;
    /// assert_eq!(TruthFormat::detect("#t,x\n1403715524907143168,0.5,2,1\n"), Some(TruthFormat::Euroc));
    /// assert_eq!(TruthFormat::detect("# t x\n1305031102.175 1 2 3 0 0 0 1\n"), Some(TruthFormat::Tum));
    /// assert_eq!(TruthFormat::detect("# nothing\n"), None);
    /// ```
    pub fn detect(text: &str) -> Option<Self> {
        let line = text
            .lines()
            .map(str::trim)
            .find(|l| !l.is_empty() && !l.starts_with('#'))?;
        Some(if line.contains(',') {
            TruthFormat::Euroc
        } else {
            TruthFormat::Tum
        })
    }

    /// Parses a ground-truth text in this format.
    pub fn parse(self, text: &str) -> Result<Track> {
        match self {
            TruthFormat::Euroc => parse_euroc_groundtruth(text),
            TruthFormat::Tum => crate::tum::parse_tum(text).map(|t| t.track),
        }
    }
}

/// A real flight's ground-truth file: one of the known datasets ([`Flight`]) or
/// any TUM or EuRoC ground-truth file (a target trajectory for the real-flight
/// section; `edccif reproduce --flight FILE`).
///
/// ```
/// use edccif_io::flights::{Flight, FlightFile};
/// let known = FlightFile::new("/data/V102_groundtruth.csv");
/// assert_eq!((known.known, known.name()), (Some(Flight::EurocV102), "euroc-v102".to_string()));
/// let mine = FlightFile::new("/tmp/lab_run3.txt");
/// assert_eq!((mine.known, mine.name()), (None, "lab_run3".to_string()));
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FlightFile {
    /// The file.
    pub path: PathBuf,
    /// The known dataset it is (by its file name), if any: its name, title and
    /// citation in reports.
    pub known: Option<Flight>,
}

impl FlightFile {
    /// A known flight's file in `data_dir`.
    pub fn known(flight: Flight, data_dir: impl AsRef<Path>) -> Self {
        Self {
            path: data_dir.as_ref().join(flight.file_name()),
            known: Some(flight),
        }
    }

    /// Any ground-truth file; a known dataset's file name makes it that dataset.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        let path = path.into();
        let known = path
            .file_name()
            .and_then(|n| Flight::ALL.into_iter().find(|f| n == f.file_name()));
        Self { path, known }
    }

    /// Short name: the dataset's (`euroc-v102`), else the file's stem.
    pub fn name(&self) -> String {
        match self.known {
            Some(f) => f.name().into(),
            None => self.path.file_stem().map_or_else(
                || self.path.display().to_string(),
                |s| s.to_string_lossy().into_owned(),
            ),
        }
    }

    /// The file's name.
    pub fn file_name(&self) -> String {
        self.path.file_name().map_or_else(
            || self.path.display().to_string(),
            |s| s.to_string_lossy().into_owned(),
        )
    }

    /// A heading for reports.
    pub fn title(&self) -> String {
        match self.known {
            Some(f) => f.title().into(),
            None => format!(
                "{}: a recorded ground truth ({})",
                self.name(),
                self.path.display()
            ),
        }
    }

    /// The dataset's citation, or where the file came from.
    pub fn citation(&self) -> String {
        match self.known {
            Some(f) => f.citation().into(),
            None => format!("the file {} (given with --flight)", self.path.display()),
        }
    }

    /// Reads the ground truth (times in s, positions in m): the known dataset's
    /// format, else the one [`TruthFormat::detect`] finds. Repeated stamps are
    /// dropped and counted (`duplicates`: [`DuplicateStamps::Refuse`] refuses
    /// them, naming the file and the sample); any other disorder is refused.
    pub fn load(&self, duplicates: DuplicateStamps) -> Result<(Track, DuplicateReport)> {
        let path = &self.path;
        let text = std::fs::read_to_string(path).map_err(|e| {
            Error::Io(match self.known {
                Some(f) => format!(
                    "cannot read the {} ground truth {}: {e} (the real flights are read from a \
                     data directory holding {}; by default ../shared/data beside the repository \
                     root, elsewhere with --data-dir DIR)",
                    f.name(),
                    path.display(),
                    f.file_name()
                ),
                None => format!("cannot read the ground-truth file {}: {e}", path.display()),
            })
        })?;
        let format = match self.known {
            Some(Flight::EurocV102) => TruthFormat::Euroc,
            Some(Flight::TumFr1Xyz) => TruthFormat::Tum,
            None => TruthFormat::detect(&text).ok_or_else(|| Error::Value {
                what: format!("ground truth {}", path.display()),
                problem: "holds no data line; expected a TUM trajectory (timestamp tx ty tz qx qy \
                          qz qw) or a EuRoC ground-truth CSV (timestamp_ns, px, py, pz, ...)"
                    .into(),
            })?,
        };
        let what = format!("{} ({})", self.name(), path.display());
        let track = format.parse(&text).map_err(|e| match e {
            Error::Value { what, problem } => Error::Value {
                what: format!("{what} ({})", path.display()),
                problem: format!(
                    "{problem} (read as {})",
                    match format {
                        TruthFormat::Euroc => "a EuRoC ground-truth CSV",
                        TruthFormat::Tum => "a TUM trajectory",
                    }
                ),
            },
            other => other,
        })?;
        let (track, rep) = match duplicates {
            DuplicateStamps::Drop => drop_duplicate_stamps(&track),
            DuplicateStamps::Refuse => {
                check_duplicate_stamps(&track, &what)?;
                (track, DuplicateReport::default())
            }
        };
        track.check_increasing(&what)?;
        Ok((track, rep))
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
