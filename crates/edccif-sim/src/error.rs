//! Errors of the simulation/runner crate.

use std::fmt;

/// Everything that can go wrong outside the numerical core.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Error {
    /// A step of the numerical core failed.
    Core(edccif_core::Error),
    /// A scenario value is invalid: which field, and what is expected.
    Scenario {
        /// The field, e.g. `"sensors[2]"`.
        field: String,
        /// What was wrong and what is expected.
        problem: String,
    },
    /// A scenario file could not be parsed (message includes line and column).
    Parse(String),
    /// An array has the wrong shape.
    Shape {
        /// The argument.
        what: String,
        /// The expected shape, e.g. `"(200, 4, 3)"`.
        expected: String,
        /// The received shape.
        got: String,
    },
    /// A value is out of range (NaN, negative, …).
    Value {
        /// The argument.
        what: String,
        /// What was wrong and what is expected.
        problem: String,
    },
    /// An algorithm name that is not one of the rows.
    UnknownAlgorithm(String),
    /// An option name or value that is not known.
    UnknownOption {
        /// The option.
        name: String,
        /// What is accepted.
        expected: String,
    },
    /// File input/output failed.
    Io(String),
    /// The communication graph or its combination weights are malformed.
    Graph {
        /// The entry, e.g. `"weights[0][2]"`.
        what: String,
        /// What was wrong and what is expected.
        problem: String,
    },
    /// A core step failed at a given time step of a run.
    AtStep {
        /// Zero-based step index.
        step: usize,
        /// The core error.
        source: edccif_core::Error,
    },
    /// The computation was cancelled through its [`Control`](crate::control::Control).
    Interrupted,
    /// What a call would allocate does not fit in the memory available
    /// ([`limits::check_memory`](crate::limits::check_memory)).
    TooLarge {
        /// What needs the memory, with its size.
        what: String,
        /// Bytes needed.
        needed: u128,
        /// Bytes available.
        limit: u64,
    },
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Core(e) => write!(f, "{e}"),
            Error::Scenario { field, problem } => write!(f, "scenario field `{field}`: {problem}"),
            Error::Parse(m) => write!(f, "cannot parse scenario: {m}"),
            Error::Shape {
                what,
                expected,
                got,
            } => write!(f, "{what} has shape {got}, expected {expected}"),
            Error::Value { what, problem } => write!(f, "{what}: {problem}"),
            Error::UnknownAlgorithm(name) => write!(
                f,
                "unknown algorithm {name:?}; expected one of {}",
                crate::names::ALGORITHMS.join(", ")
            ),
            Error::UnknownOption { name, expected } => {
                write!(f, "unknown option {name:?}; expected {expected}")
            }
            Error::Io(m) => write!(f, "{m}"),
            Error::AtStep { step, source } => write!(f, "at step {step}: {source}"),
            Error::Graph { what, problem } => write!(f, "{what}: {problem}"),
            Error::Interrupted => write!(f, "interrupted"),
            Error::TooLarge {
                what,
                needed,
                limit,
            } => write!(
                f,
                "{what} needs {} of memory, more than the {} available (the limit: MemAvailable, a cgroup's limit, or EDCCIF_MEMORY_LIMIT); use fewer steps, nodes, runs or rows",
                fmt_bytes(*needed),
                fmt_bytes(u128::from(*limit))
            ),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Core(e) | Error::AtStep { source: e, .. } => Some(e),
            _ => None,
        }
    }
}

impl From<edccif_core::Error> for Error {
    fn from(e: edccif_core::Error) -> Self {
        Error::Core(e)
    }
}

impl From<edccif_io::Error> for Error {
    fn from(e: edccif_io::Error) -> Self {
        match e {
            edccif_io::Error::Shape {
                what,
                expected,
                got,
            } => Error::Shape {
                what,
                expected,
                got,
            },
            edccif_io::Error::Value { what, problem } => Error::Value { what, problem },
            edccif_io::Error::UnknownOption { name, expected } => {
                Error::UnknownOption { name, expected }
            }
            edccif_io::Error::Io(m) => Error::Io(m),
            edccif_io::Error::Interrupted => Error::Interrupted,
            other => Error::Io(other.to_string()),
        }
    }
}

impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Self {
        Error::Io(e.to_string())
    }
}

/// Bytes in a human unit, e.g. `"80.0 GB"` (powers of 1000).
///
/// ```
/// use edccif_sim::limits::fmt_bytes;
/// assert_eq!(fmt_bytes(512), "512 B");
/// assert_eq!(fmt_bytes(80_000_000_000), "80.0 GB");
/// ```
pub fn fmt_bytes(b: u128) -> String {
    const UNITS: [&str; 7] = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut v = b as f64;
    let mut u = 0;
    while v >= 1000.0 && u + 1 < UNITS.len() {
        v /= 1000.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

/// `Result` with this crate's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

pub(crate) fn scenario_err(field: impl Into<String>, problem: impl Into<String>) -> Error {
    Error::Scenario {
        field: field.into(),
        problem: problem.into(),
    }
}
