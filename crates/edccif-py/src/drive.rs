//! Long calls: interruptible with Ctrl-C, with the GIL released, reporting
//! progress.
//!
//! [`drive`] runs the work on a worker thread with a
//! [`Control`] while the calling thread (the
//! driver) releases the GIL and, every [`POLL`], takes it back briefly to run
//! `check_signals` (the interpreter's signal handlers, so Ctrl-C raises
//! `KeyboardInterrupt` here) and to report progress. A signal handler or a
//! progress callback that raises cancels the control; the work stops at its
//! next check and the driver returns the exception, the work's own result
//! (e.g. a partial Monte Carlo study) beside it.
//!
//! Work too small to need it runs on the calling thread with the GIL released
//! ([`drive_if`]), without a thread of its own.

use std::sync::mpsc::{channel, RecvTimeoutError};
use std::time::Duration;

use edccif_sim::control::Control;
use pyo3::prelude::*;
use pyo3::types::PyBool;

/// How often the driver checks for signals and reports progress.
pub const POLL: Duration = Duration::from_millis(50);

/// Where progress goes: nowhere, the package's reporter
/// (`edccif._progress.Reporter`: a bar on a terminal, a line at most every 5 s
/// otherwise), or a callable of the caller's, `progress(done, total)`.
pub enum Progress {
    /// No progress.
    Off,
    /// The package's reporter (`progress=True`).
    Default(Py<PyAny>),
    /// The caller's callable.
    Callback(Py<PyAny>),
}

impl Progress {
    /// Parses a `progress=` argument: `True`/`False`/`None` or a callable taking
    /// `(done, total)`; `what` names the work and `unit` its units in the
    /// package's reporter (e.g. `"monte_carlo"`, `"runs"`).
    pub fn from_arg(obj: Option<&Bound<'_, PyAny>>, what: &str, unit: &str) -> PyResult<Self> {
        let Some(obj) = obj.filter(|o| !o.is_none()) else {
            return Ok(Progress::Off);
        };
        if let Ok(b) = obj.downcast::<PyBool>() {
            if !b.is_true() {
                return Ok(Progress::Off);
            }
            let py = obj.py();
            let reporter = py
                .import("edccif._progress")?
                .getattr("Reporter")?
                .call1((what, unit))?;
            return Ok(Progress::Default(reporter.unbind()));
        }
        if obj.is_callable() {
            return Ok(Progress::Callback(obj.clone().unbind()));
        }
        Err(crate::errors::argument_type_error(
            obj.py(),
            format!(
                "progress: expected True, False, None or a callable progress(done, total), got {}",
                obj.get_type().name()?
            ),
        ))
    }

    /// [`from_arg`](Self::from_arg) where `None` (or no argument) means
    /// `True`: for the calls whose progress is on by default.
    pub fn from_arg_default_on(
        py: Python<'_>,
        obj: Option<&Bound<'_, PyAny>>,
        what: &str,
        unit: &str,
    ) -> PyResult<Self> {
        match obj.filter(|o| !o.is_none()) {
            Some(o) => Self::from_arg(Some(o), what, unit),
            None => Self::from_arg(Some(PyBool::new(py, true).as_any()), what, unit),
        }
    }

    /// Whether anything is reported.
    pub fn is_on(&self) -> bool {
        !matches!(self, Progress::Off)
    }

    /// Reports `(done, total)` now (for loops that hold the GIL).
    pub fn report_now(&self, py: Python<'_>, done: u64, total: u64) -> PyResult<()> {
        self.report(py, done, total)
    }

    fn report(&self, py: Python<'_>, done: u64, total: u64) -> PyResult<()> {
        match self {
            Progress::Off => Ok(()),
            Progress::Default(f) | Progress::Callback(f) => f.call1(py, (done, total)).map(|_| ()),
        }
    }

    /// Closes the package's reporter (a bar leaves the screen); nothing for a
    /// callable of the caller's.
    pub fn close(&self, py: Python<'_>) {
        if let Progress::Default(f) = self {
            // Best effort: a reporter that cannot close leaves a bar on screen.
            let _ = f.call_method0(py, "close");
        }
    }
}

/// The work's result and, when a signal handler or the progress callback
/// raised, that exception (the work was cancelled).
pub struct Outcome<T> {
    /// What the work returned (for a cancelled work, typically
    /// `Err(Interrupted)` or a partial result).
    pub value: T,
    /// The exception that cancelled the work.
    pub interrupt: Option<PyErr>,
}

impl<T> Outcome<T> {
    /// The value, or the exception that cancelled the work.
    pub fn into_result(self) -> PyResult<T> {
        match self.interrupt {
            Some(e) => Err(e),
            None => Ok(self.value),
        }
    }
}

/// Runs `work` on a worker thread under a live control while this thread
/// checks for signals every [`POLL`] with the GIL taken briefly, and reports
/// progress; see the module documentation.
pub fn drive<T, W>(py: Python<'_>, progress: &Progress, work: W) -> Outcome<T>
where
    T: Send,
    W: FnOnce(&Control) -> T + Send,
{
    let ctl = Control::new();
    let (tx, rx) = channel::<()>();
    let mut interrupt: Option<PyErr> = None;
    let mut last = (u64::MAX, u64::MAX);
    let joined = std::thread::scope(|s| {
        let ctl = &ctl;
        let handle = s.spawn(move || {
            let v = work(ctl);
            // The driver may have stopped waiting only if it panicked.
            let _ = tx.send(());
            v
        });
        let interrupt = &mut interrupt;
        let last = &mut last;
        py.allow_threads(move || loop {
            match rx.recv_timeout(POLL) {
                Ok(()) | Err(RecvTimeoutError::Disconnected) => break,
                Err(RecvTimeoutError::Timeout) => {
                    if interrupt.is_some() {
                        continue;
                    }
                    Python::with_gil(|py| {
                        let r = py.check_signals().and_then(|()| {
                            let now = ctl.progress();
                            if now != *last {
                                *last = now;
                                progress.report(py, now.0, now.1)
                            } else {
                                Ok(())
                            }
                        });
                        if let Err(e) = r {
                            ctl.cancel();
                            *interrupt = Some(e);
                        }
                    });
                }
            }
        });
        handle.join()
    });
    let value = match joined {
        Ok(v) => v,
        Err(payload) => std::panic::resume_unwind(payload),
    };
    if interrupt.is_none() {
        let (done, total) = ctl.progress();
        if progress.is_on() && (done, total) != last {
            if let Err(e) = progress.report(py, done, total) {
                interrupt = Some(e);
            }
        }
    }
    progress.close(py);
    Outcome { value, interrupt }
}

/// [`drive`] when `long` or when progress is asked for; otherwise `work` runs
/// here with the GIL released under [`Control::none`].
pub fn drive_if<T, W>(py: Python<'_>, long: bool, progress: &Progress, work: W) -> Outcome<T>
where
    T: Send,
    W: FnOnce(&Control) -> T + Send,
{
    if long || progress.is_on() {
        drive(py, progress, work)
    } else {
        Outcome {
            value: py.allow_threads(move || work(Control::none())),
            interrupt: None,
        }
    }
}

/// Work units (node-steps, counting each consensus round) from which a call
/// is driven on a worker thread (about 20 ms of stepping and more).
pub const LONG_WORK: u128 = 20_000;

/// Node-phases of `steps` steps of `nodes` nodes with `rounds` consensus rounds
/// per step (diffusion: `rounds = 0`, three phases).
pub fn network_work(steps: usize, nodes: usize, rounds: usize) -> u128 {
    (steps as u128)
        .saturating_mul(nodes as u128)
        .saturating_mul(rounds.saturating_add(3) as u128)
}
