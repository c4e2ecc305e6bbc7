//! Stopping a long computation from outside, and watching its progress.
//!
//! A [`Control`] is shared between a long computation (a run, a Monte Carlo
//! study, the reproduction) and whoever drives it (the Python bindings' driver
//! thread, which checks for Ctrl-C): the computation calls
//! [`check`](Control::check) at every step (and every consensus round of a long
//! step) and [`advance`](Control::advance) as units of work finish; the driver
//! calls [`cancel`](Control::cancel) and reads [`progress`](Control::progress).
//! A cancelled computation returns [`Error::Interrupted`] at its next check and
//! leaves the objects it was given as they were before the call (a network step
//! commits nothing until its last phase).
//!
//! [`Control::none`] is never cancelled and counts nothing: what the functions
//! without a control argument use.
//!
//! ```
//! use edccif_sim::control::Control;
//! let ctl = Control::new();
//! ctl.add_total(10);
//! ctl.advance(3);
//! assert_eq!(ctl.progress(), (3, 10));
//! assert!(ctl.check().is_ok());
//! ctl.cancel();
//! assert!(ctl.check().unwrap_err().to_string().contains("interrupted"));
//! assert!(Control::none().check().is_ok());
//! ```

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use crate::error::{Error, Result};

/// Cancellation flag and progress counters of one long computation.
#[derive(Debug)]
pub struct Control {
    live: bool,
    cancelled: AtomicBool,
    done: AtomicU64,
    total: AtomicU64,
}

static NONE: Control = Control {
    live: false,
    cancelled: AtomicBool::new(false),
    done: AtomicU64::new(0),
    total: AtomicU64::new(0),
};

impl Default for Control {
    fn default() -> Self {
        Self::new()
    }
}

impl Control {
    /// A control that is not cancelled, with no work counted yet.
    pub const fn new() -> Self {
        Self {
            live: true,
            cancelled: AtomicBool::new(false),
            done: AtomicU64::new(0),
            total: AtomicU64::new(0),
        }
    }

    /// The control that is never cancelled and counts nothing.
    pub fn none() -> &'static Control {
        &NONE
    }

    /// Whether someone may cancel this control (false only for [`none`](Self::none)).
    pub fn is_live(&self) -> bool {
        self.live
    }

    /// Asks the computation to stop at its next [`check`](Self::check).
    pub fn cancel(&self) {
        if self.live {
            self.cancelled.store(true, Ordering::Relaxed);
        }
    }

    /// Whether [`cancel`](Self::cancel) was called.
    #[inline]
    pub fn is_cancelled(&self) -> bool {
        self.live && self.cancelled.load(Ordering::Relaxed)
    }

    /// `Err(Error::Interrupted)` once cancelled.
    #[inline]
    pub fn check(&self) -> Result<()> {
        if self.is_cancelled() {
            Err(Error::Interrupted)
        } else {
            Ok(())
        }
    }

    /// Adds `n` units to the work expected.
    pub fn add_total(&self, n: u64) {
        if self.live {
            self.total.fetch_add(n, Ordering::Relaxed);
        }
    }

    /// Counts `n` units of work as done.
    #[inline]
    pub fn advance(&self, n: u64) {
        if self.live {
            self.done.fetch_add(n, Ordering::Relaxed);
        }
    }

    /// `(done, total)` units of work so far.
    pub fn progress(&self) -> (u64, u64) {
        (
            self.done.load(Ordering::Relaxed),
            self.total.load(Ordering::Relaxed),
        )
    }
}

/// A control watches the long computations of `edccif-io` too (e.g. the
/// preprocessing pipeline): the same counts, the same cancel.
impl edccif_io::watch::Watch for Control {
    fn add_total(&self, n: u64) {
        Control::add_total(self, n);
    }
    fn advance(&self, n: u64) {
        Control::advance(self, n);
    }
    fn is_cancelled(&self) -> bool {
        Control::is_cancelled(self)
    }
}
