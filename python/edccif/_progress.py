"""Progress of long calls (``progress=True``): a bar on a terminal, and a plain
line on stderr at most every few seconds when stderr is not a terminal (CI
logs, notebooks over ssh, job schedulers).

The extension calls a reporter as ``reporter(done, total)`` from the calling
thread while the work runs elsewhere, and ``reporter.close()`` when it ends.
A callable of one's own passed as ``progress=`` is called the same way
(without ``close``).
"""

from __future__ import annotations

import sys
import time
from typing import IO, Any, Optional

LINE_EVERY_S = 5.0
"""Seconds between two progress lines when stderr is not a terminal."""


def _fmt_s(s: float) -> str:
    s = int(round(s))
    if s < 60:
        return f"{s} s"
    m, s = divmod(s, 60)
    if m < 60:
        return f"{m} min {s:02d} s"
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min"


class Reporter:
    """``progress=True``: on a terminal a tqdm bar; otherwise one line
    ``what: done/total unit (p %), elapsed, ETA`` on ``stream`` (stderr) at
    most every ``every`` seconds, the first after ``every`` seconds (short
    calls print nothing), and a last line at the end if any was printed."""

    def __init__(self, what: str, unit: str, every: float = LINE_EVERY_S, stream: Optional[IO[str]] = None):
        self.what = what
        self.unit = unit
        self.every = every
        self.stream = stream if stream is not None else sys.stderr
        self.start = time.monotonic()
        self.last_line = self.start
        self.lines = 0
        self.done = 0
        self.total = 0
        self.bar: Any = None
        self.closed = False
        try:
            self.tty = bool(self.stream.isatty())
        except (AttributeError, ValueError):
            self.tty = False

    def __call__(self, done: int, total: int) -> None:
        self.done, self.total = int(done), int(total)
        if self.closed:
            return
        if self.tty:
            if self.bar is None:
                from tqdm import tqdm

                self.bar = tqdm(total=self.total, desc=self.what, unit=self.unit, file=self.stream, leave=False)
            if self.bar.total != self.total:
                self.bar.total = self.total
            self.bar.update(self.done - self.bar.n)
            return
        now = time.monotonic()
        if now - self.last_line >= self.every:
            self._line(now)

    def _line(self, now: float) -> None:
        elapsed = now - self.start
        if self.total > 0:
            frac = min(self.done / self.total, 1.0)
            eta = f", ETA {_fmt_s(elapsed * (1 - frac) / frac)}" if frac > 0 else ""
            body = f"{self.done}/{self.total} {self.unit} ({100 * frac:.0f} %)"
        else:
            eta = ""
            body = f"{self.done} {self.unit}"
        print(f"{self.what}: {body}, {_fmt_s(elapsed)} elapsed{eta}", file=self.stream, flush=True)
        self.last_line = now
        self.lines += 1

    def close(self) -> None:
        """Ends the bar, or prints the last line if any line was printed."""
        if self.closed:
            return
        self.closed = True
        if self.bar is not None:
            self.bar.close()
        elif self.lines:
            self._line(time.monotonic())
