//! Watching a long computation: its caller counts the work units done and may
//! stop it.
//!
//! A [`Watch`] is handed to the long functions of this crate (e.g.
//! [`run_pipeline_watched`](crate::preprocess::run_pipeline_watched)); they
//! declare their work with [`add_total`](Watch::add_total) once it is known,
//! count it with [`advance`](Watch::advance), and look at
//! [`is_cancelled`](Watch::is_cancelled) often enough (every unit, and inside
//! any loop that can run long) to return [`Error::Interrupted`](crate::Error)
//! soon after a cancel. `edccif_sim::control::Control` is one; [`Unwatched`]
//! counts nothing and never stops.
//!
//! ```
//! use std::sync::atomic::{AtomicU64, Ordering};
//! use edccif_io::watch::Watch;
//! struct Count(AtomicU64, AtomicU64);
//! impl Watch for Count {
//!     fn add_total(&self, n: u64) { self.1.fetch_add(n, Ordering::Relaxed); }
//!     fn advance(&self, n: u64) { self.0.fetch_add(n, Ordering::Relaxed); }
//!     fn is_cancelled(&self) -> bool { false }
//! }
//! let c = Count(AtomicU64::new(0), AtomicU64::new(0));
//! c.add_total(3);
//! c.advance(3);
//! assert_eq!(c.0.load(Ordering::Relaxed), c.1.load(Ordering::Relaxed));
//! ```

use crate::{Error, Result};

/// Counts a long computation's work and may stop it; see the module
/// documentation.
pub trait Watch: Sync {
    /// Adds `n` units to the work expected.
    fn add_total(&self, n: u64);
    /// Counts `n` units of work as done.
    fn advance(&self, n: u64);
    /// Whether the computation should stop.
    fn is_cancelled(&self) -> bool;
    /// `Err(Error::Interrupted)` once cancelled.
    fn check(&self) -> Result<()> {
        if self.is_cancelled() {
            Err(Error::Interrupted)
        } else {
            Ok(())
        }
    }
}

/// The watch that counts nothing and never stops.
#[derive(Debug, Clone, Copy, Default)]
pub struct Unwatched;

impl Watch for Unwatched {
    fn add_total(&self, _: u64) {}
    fn advance(&self, _: u64) {}
    fn is_cancelled(&self) -> bool {
        false
    }
}
