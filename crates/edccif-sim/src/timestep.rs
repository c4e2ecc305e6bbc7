//! The check every entry point applies to a time step, in one place (the
//! networks, the runs, and the bindings' models and filters).
//!
//! ```
//! use edccif_sim::timestep::check_dt;
//! assert!(check_dt(0.1, "dt").is_ok());
//! let e = check_dt(0.0, format_args!("dt[{}]", 3)).unwrap_err().to_string();
//! assert_eq!(e, "dt[3]: expected a finite time step > 0, got 0");
//! assert!(check_dt(f64::NAN, "dt").is_err() && check_dt(f64::INFINITY, "dt").is_err());
//! ```

use std::fmt::Display;

use crate::error::{Error, Result};

/// Checks a time step: finite and `> 0`; the error
/// ([`Error::Value`]) names `what` (e.g. `dt`, `dt[3]`) and the value.
pub fn check_dt(dt: f64, what: impl Display) -> Result<()> {
    if dt.is_finite() && dt > 0.0 {
        Ok(())
    } else {
        Err(Error::Value {
            what: what.to_string(),
            problem: format!("expected a finite time step > 0, got {dt}"),
        })
    }
}
