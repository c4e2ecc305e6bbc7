//! Errors of the log I/O crate.

use std::fmt;

/// Everything that can go wrong reading, writing or preprocessing a log.
///
/// The messages name the argument (or the file, topic and record) and what was
/// expected, e.g. `track positions has shape (2, 3), expected (3, 3)`.
///
/// ```
/// use edccif_io::{Error, Track};
/// let e = Track::from_flat(&[0.0], &[1.0, 2.0]).unwrap_err();
/// assert!(matches!(e, Error::Shape { .. }));
/// assert_eq!(e.to_string(), "track positions has shape 2 values, expected (1, 3)");
/// ```
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub enum Error {
    /// An array has the wrong shape.
    Shape {
        /// The argument.
        what: String,
        /// The expected shape, e.g. `"(200, 4, 3)"`.
        expected: String,
        /// The received shape.
        got: String,
    },
    /// A value is out of range or malformed (NaN, a bad record, …).
    Value {
        /// The argument, file or record.
        what: String,
        /// What was wrong and what is expected.
        problem: String,
    },
    /// An option name or value that is not known.
    UnknownOption {
        /// The option.
        name: String,
        /// What is accepted.
        expected: String,
    },
    /// File input/output failed.
    Io(String),
    /// The caller cancelled the computation (see [`crate::watch`]).
    Interrupted,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Shape {
                what,
                expected,
                got,
            } => write!(f, "{what} has shape {got}, expected {expected}"),
            Error::Value { what, problem } => write!(f, "{what}: {problem}"),
            Error::UnknownOption { name, expected } => {
                write!(f, "unknown option {name:?}; expected {expected}")
            }
            Error::Io(m) => write!(f, "{m}"),
            Error::Interrupted => write!(f, "interrupted"),
        }
    }
}

impl std::error::Error for Error {}

impl From<std::io::Error> for Error {
    fn from(e: std::io::Error) -> Self {
        Error::Io(e.to_string())
    }
}

/// `Result` with this crate's [`Error`].
pub type Result<T> = std::result::Result<T, Error>;
