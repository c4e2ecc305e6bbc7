//! The one error type of the core.

use core::fmt;

/// Everything that can go wrong in a step of the core.
///
/// Every fallible function returns [`Result`]; a failed step never changes the
/// state it was given (the caller's node, trigger and buffers stay as they were).
///
/// ```
/// use edccif_core::Error;
/// let e = Error::NotPositiveDefinite { what: "prior covariance P⁻" };
/// assert_eq!(e.to_string(), "prior covariance P⁻ is not symmetric positive definite");
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum Error {
    /// A matrix that must be symmetric positive definite is not (its Cholesky
    /// factorisation failed). `what` names the matrix.
    NotPositiveDefinite {
        /// The quantity that failed, e.g. `"prior covariance P⁻"`.
        what: &'static str,
    },
    /// An input or an intermediate result holds NaN or ±∞.
    NonFinite {
        /// The quantity that was not finite.
        what: &'static str,
    },
    /// A matrix that must be symmetric is not (beyond a relative tolerance).
    NotSymmetric {
        /// The quantity that was not symmetric.
        what: &'static str,
    },
    /// A slice or buffer has the wrong length.
    Dimension {
        /// The argument with the wrong length.
        what: &'static str,
        /// The length that was expected.
        expected: usize,
        /// The length that was received.
        got: usize,
    },
    /// The communication graph is not connected.
    DisconnectedGraph {
        /// A node that cannot be reached from node 0.
        unreachable: usize,
    },
    /// The adjacency matrix is malformed (self-loop or asymmetric entry).
    InvalidGraph {
        /// What is wrong: `"self-loop"` or `"asymmetric edge"`.
        what: &'static str,
        /// Row of the offending entry.
        row: usize,
        /// Column of the offending entry.
        col: usize,
    },
    /// A parameter is outside its valid range.
    InvalidParameter {
        /// The parameter, e.g. `"delta"`.
        what: &'static str,
        /// What it must be, e.g. `"finite and > 0"`.
        expected: &'static str,
    },
    /// The caller's watch function asked a long computation to stop (e.g.
    /// [`ci_fuse_optimal_with`](crate::fusion::ci_fuse_optimal_with)); nothing
    /// was written.
    Interrupted,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::NotPositiveDefinite { what } => {
                write!(f, "{what} is not symmetric positive definite")
            }
            Error::NonFinite { what } => write!(f, "{what} contains NaN or infinity"),
            Error::NotSymmetric { what } => write!(f, "{what} is not symmetric"),
            Error::Dimension {
                what,
                expected,
                got,
            } => write!(f, "{what} has length {got}, expected {expected}"),
            Error::DisconnectedGraph { unreachable } => write!(
                f,
                "the communication graph is disconnected: node {unreachable} cannot be reached from node 0"
            ),
            Error::InvalidGraph { what, row, col } => {
                write!(f, "invalid adjacency matrix: {what} at ({row}, {col})")
            }
            Error::InvalidParameter { what, expected } => {
                write!(f, "invalid parameter {what}: expected {expected}")
            }
            Error::Interrupted => write!(f, "interrupted by the caller"),
        }
    }
}

impl core::error::Error for Error {}

/// `Result` with the core's [`Error`].
pub type Result<T> = core::result::Result<T, Error>;

/// `let_ok!(pattern = expr);` is `let pattern = &expr?;` without moving the
/// value out of its `Result`: the `Result` stays where the callee wrote it and
/// `pattern` borrows the `Ok` value (an error returns from the caller, as `?`
/// does for the core's [`Error`]). Used where a plain `?` copies a large value
/// (a prior, a factor, a step's result: 0.4–1.3 kB): those copies cost 3–5 %
/// of a local step's instructions (measured with callgrind on the ET-CIF and
/// EKF steps).
macro_rules! let_ok {
    ($p:pat = $e:expr) => {
        let result = $e;
        let $p = match &result {
            Ok(v) => v,
            Err(e) => return Err(*e),
        };
    };
}
pub(crate) use let_ok;
