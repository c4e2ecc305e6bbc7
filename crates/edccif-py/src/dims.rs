//! The one place that maps a runtime state dimension `n` and measurement
//! dimension `m` to the const generics of the core (`N`, `M`).
//!
//! Every binding that builds const-generic core code from Python-sized models goes
//! through [`with_n!`](crate::with_n) or [`with_dims!`](crate::with_dims): the body
//! is compiled once per supported size and the matching copy runs. An unsupported
//! size is a `ParameterError` that names the supported ranges.
//!
//! ```ignore
//! let out: PyResult<usize> = with_dims!(n, m, |N, M| Ok(N * M));
//! ```

use pyo3::PyErr;

use crate::errors::ParameterError;

/// Largest supported state dimension (`n` in `1..=MAX_N`).
pub const MAX_N: usize = 12;
/// Largest supported measurement dimension (`m` in `1..=MAX_M`).
pub const MAX_M: usize = 6;

/// The supported sizes, as error messages name them.
pub const SUPPORTED: &str = "state dimension n in 1..=12 and measurement dimension m in 1..=6";

/// Whether `(n, m)` is a compiled size.
pub fn supported(n: usize, m: usize) -> bool {
    (1..=MAX_N).contains(&n) && (1..=MAX_M).contains(&m)
}

/// The error for an unsupported state dimension.
pub fn unsupported_n(n: usize) -> PyErr {
    ParameterError::new_err(format!(
        "state dimension n = {n} is not supported; supported: {SUPPORTED}"
    ))
}

/// The error for an unsupported measurement dimension.
pub fn unsupported_m(m: usize) -> PyErr {
    ParameterError::new_err(format!(
        "measurement dimension m = {m} is not supported; supported: {SUPPORTED}"
    ))
}

/// `Ok(())` for a supported state dimension, the named error otherwise.
pub fn check_n(n: usize) -> pyo3::PyResult<()> {
    if (1..=MAX_N).contains(&n) {
        Ok(())
    } else {
        Err(unsupported_n(n))
    }
}

/// `Ok(())` for a supported measurement dimension, the named error otherwise.
pub fn check_m(m: usize) -> pyo3::PyResult<()> {
    if (1..=MAX_M).contains(&m) {
        Ok(())
    } else {
        Err(unsupported_m(m))
    }
}

/// Runs `body` with the const `N` equal to the runtime state dimension `n`
/// (`1..=12`); the body must evaluate to a `PyResult`. Other sizes give
/// [`unsupported_n`].
#[macro_export]
macro_rules! with_n {
    ($n:expr, |$N:ident| $body:expr) => {{
        match $n {
            1 => {
                const $N: usize = 1;
                $body
            }
            2 => {
                const $N: usize = 2;
                $body
            }
            3 => {
                const $N: usize = 3;
                $body
            }
            4 => {
                const $N: usize = 4;
                $body
            }
            5 => {
                const $N: usize = 5;
                $body
            }
            6 => {
                const $N: usize = 6;
                $body
            }
            7 => {
                const $N: usize = 7;
                $body
            }
            8 => {
                const $N: usize = 8;
                $body
            }
            9 => {
                const $N: usize = 9;
                $body
            }
            10 => {
                const $N: usize = 10;
                $body
            }
            11 => {
                const $N: usize = 11;
                $body
            }
            12 => {
                const $N: usize = 12;
                $body
            }
            other => Err($crate::dims::unsupported_n(other)),
        }
    }};
}

/// Runs `body` with the const `M` equal to the runtime measurement dimension
/// `m` (`1..=6`); other sizes give [`unsupported_m`].
#[macro_export]
macro_rules! with_m {
    ($m:expr, |$M:ident| $body:expr) => {{
        match $m {
            1 => {
                const $M: usize = 1;
                $body
            }
            2 => {
                const $M: usize = 2;
                $body
            }
            3 => {
                const $M: usize = 3;
                $body
            }
            4 => {
                const $M: usize = 4;
                $body
            }
            5 => {
                const $M: usize = 5;
                $body
            }
            6 => {
                const $M: usize = 6;
                $body
            }
            other => Err($crate::dims::unsupported_m(other)),
        }
    }};
}

/// Runs `body` with const `N`, `M` equal to the runtime `(n, m)`: the body is
/// compiled for every supported pair (12 × 6). The measurement dimension is
/// checked first only when the state dimension is supported, so the error names
/// the first unsupported one.
#[macro_export]
macro_rules! with_dims {
    ($n:expr, $m:expr, |$N:ident, $M:ident| $body:expr) => {{
        let (n_, m_): (usize, usize) = ($n, $m);
        $crate::dims::check_n(n_)
            .and_then(|()| $crate::dims::check_m(m_))
            .and_then(|()| $crate::with_n!(n_, |$N| $crate::with_m!(m_, |$M| $body)))
    }};
}
