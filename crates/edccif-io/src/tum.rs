//! TUM trajectory files (Sturm et al., 2012), the format the paper converts every
//! raw trajectory to before pre-processing.
//!
//! One pose per line, whitespace-separated:
//!
//! ```text
//! # timestamp tx ty tz qx qy qz qw
//! 1700000000.000000 0.1 0.2 1.5 0 0 0 1
//! ```
//!
//! Lines that are empty or start with `#` are ignored. The timestamp is in seconds,
//! the translation in metres, the orientation a unit quaternion `(qx, qy, qz, qw)`.
//! Writing positions only stores the identity quaternion `0 0 0 1`.
//!
//! ```
//! use edccif_io::{format_tum, parse_tum, Track};
//! let tr = Track::from_flat(&[0.0, 0.5], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
//! let text = format_tum(&tr, None).unwrap();
//! let back = parse_tum(&text).unwrap();
//! assert_eq!(back.track, tr);
//! assert_eq!(back.orientations[0], [0.0, 0.0, 0.0, 1.0]);
//! let err = parse_tum("0 1 2 3 0 0 0 1\n1 1 2 x 0 0 0 1\n").unwrap_err();
//! assert!(err.to_string().contains("line 2"));
//! ```

use std::fmt::Write as _;
use std::path::Path;

use crate::error::{Error, Result};
use crate::Track;

/// The identity quaternion `(qx, qy, qz, qw)`.
pub const IDENTITY_QUATERNION: [f64; 4] = [0.0, 0.0, 0.0, 1.0];

/// A trajectory read from a TUM file: positions with their orientations.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TumTrajectory {
    /// Timestamps and positions.
    pub track: Track,
    /// Orientation quaternions `(qx, qy, qz, qw)`, one per sample.
    pub orientations: Vec<[f64; 4]>,
}

impl TumTrajectory {
    /// Orientations as a flat row-major `(M, 4)` array.
    pub fn orientations_flat(&self) -> Vec<f64> {
        self.orientations.iter().flatten().copied().collect()
    }
}

fn line_err(line: usize, problem: impl Into<String>) -> Error {
    Error::Value {
        what: format!("TUM line {line}"),
        problem: problem.into(),
    }
}

/// Parses TUM text. Errors name the (1-based) line and the problem.
pub fn parse_tum(text: &str) -> Result<TumTrajectory> {
    const NAMES: [&str; 8] = ["timestamp", "tx", "ty", "tz", "qx", "qy", "qz", "qw"];
    let mut out = TumTrajectory::default();
    for (idx, raw) in text.lines().enumerate() {
        let line_no = idx + 1;
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() != 8 {
            return Err(line_err(
                line_no,
                format!(
                    "expected 8 values (timestamp tx ty tz qx qy qz qw), found {}",
                    fields.len()
                ),
            ));
        }
        let mut v = [0.0; 8];
        for (c, f) in fields.iter().enumerate() {
            let x: f64 = f
                .parse()
                .map_err(|_| line_err(line_no, format!("{} = {f:?} is not a number", NAMES[c])))?;
            if !x.is_finite() {
                return Err(line_err(
                    line_no,
                    format!("{} = {f:?} is not finite", NAMES[c]),
                ));
            }
            v[c] = x;
        }
        let q = [v[4], v[5], v[6], v[7]];
        let norm = q.iter().map(|a| a * a).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > 1e-3 {
            return Err(line_err(
                line_no,
                format!("quaternion (qx, qy, qz, qw) = {q:?} has norm {norm:.6}, expected 1"),
            ));
        }
        out.track.t.push(v[0]);
        out.track.p.push([v[1], v[2], v[3]]);
        out.orientations.push(q);
    }
    Ok(out)
}

/// Reads a TUM file; errors name the file, the line and the problem.
pub fn read_tum(path: impl AsRef<Path>) -> Result<TumTrajectory> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::Io(format!("cannot read {}: {e}", path.display())))?;
    parse_tum(&text).map_err(|e| match e {
        Error::Value { what, problem } => Error::Value {
            what: format!("{}: {what}", path.display()),
            problem,
        },
        other => other,
    })
}

/// Formats a track as TUM text. `orientations` (one per sample) default to the
/// identity quaternion. Every number is written in the shortest decimal form that
/// reads back to the same `f64` (no exponent), so a write/read round trip is exact.
pub fn format_tum(track: &Track, orientations: Option<&[[f64; 4]]>) -> Result<String> {
    if let Some(q) = orientations {
        if q.len() != track.len() {
            return Err(Error::Shape {
                what: "orientations".into(),
                expected: format!("({}, 4)", track.len()),
                got: format!("({}, 4)", q.len()),
            });
        }
    }
    Track::new(track.t.clone(), track.p.clone())?;
    let mut s = String::with_capacity(64 * (track.len() + 1));
    s.push_str("# timestamp tx ty tz qx qy qz qw\n");
    for j in 0..track.len() {
        let p = track.p[j];
        let q = orientations.map_or(IDENTITY_QUATERNION, |o| o[j]);
        let _ = writeln!(
            s,
            "{} {} {} {} {} {} {} {}",
            track.t[j], p[0], p[1], p[2], q[0], q[1], q[2], q[3]
        );
    }
    Ok(s)
}

/// Writes a track as a TUM file (see [`format_tum`]).
pub fn write_tum(
    path: impl AsRef<Path>,
    track: &Track,
    orientations: Option<&[[f64; 4]]>,
) -> Result<()> {
    let path = path.as_ref();
    let text = format_tum(track, orientations)?;
    std::fs::write(path, text)
        .map_err(|e| Error::Io(format!("cannot write {}: {e}", path.display())))
}
