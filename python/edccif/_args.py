"""Argument types and output-path checks shared by the ``edccif`` subcommands.

Every value is checked by argparse (or, for what depends on two arguments, right
after parsing) so that a bad one ends the command with a one-line message and exit
code 2 before any process or thread starts. Output files are never replaced
silently: see :func:`check_output_file`.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import time
from pathlib import Path
from typing import Callable, NoReturn, Optional, Sequence, Tuple

from . import _edccif

THREADS_PER_CORE = 4
"""Thread, worker and job counts are bounded by ``THREADS_PER_CORE`` × the cores of
the machine (``os.cpu_count()``): more only adds contention, and a typo such as
``--threads 100000`` would otherwise start that many threads."""

U64_MAX = 2**64 - 1


def max_threads() -> int:
    """The largest thread/worker/job count the command line accepts."""
    return THREADS_PER_CORE * (os.cpu_count() or 1)


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line on stderr, exit code 2
    (argparse's usage block is left to ``--help``)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _int(text: str, what: str) -> int:
    try:
        return int(text, 10)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def integer(lo: int, hi: Optional[int] = None, meaning: str = "") -> Callable[[str], int]:
    """An argparse type: an integer in ``lo..=hi`` (no upper bound with ``hi=None``)."""
    what = f"an integer >= {lo}" if hi is None else f"an integer >= {lo} and <= {hi}"
    if meaning:
        what += f" ({meaning})"

    def parse(text: str) -> int:
        n = _int(text.strip(), what)
        if n < lo or (hi is not None and n > hi):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return n

    parse.__name__ = "integer"
    return parse


count = integer(1)
"""An integer >= 1 (runs, steps, node counts, repetitions)."""
seed = integer(0, U64_MAX, "a seed")
"""A seed: an integer in 0..=2**64-1."""
node_index = integer(0, 0xFFFF, "a node index")
"""A node index (the wire format's sender is a u16)."""


def threads(meaning: str) -> Callable[[str], int]:
    """An argparse type: a thread/worker count in ``1..=max_threads()``."""
    limit = max_threads()
    return integer(1, limit, f"{meaning}; at most {THREADS_PER_CORE} x {os.cpu_count() or 1} cores")


def real(lo: float, hi: float = math.inf, *, lo_open: bool = False, hi_open: bool = False,
         meaning: str = "") -> Callable[[str], float]:
    """An argparse type: a finite number in the interval given (open ends with
    ``lo_open``/``hi_open``)."""
    a = "(" if lo_open else "["
    b = ")" if hi_open or math.isinf(hi) else "]"
    what = f"a finite number in {a}{lo:g}, {hi:g}{b}" if not math.isinf(hi) else (
        f"a finite number {'>' if lo_open else '>='} {lo:g}")
    if meaning:
        what += f" ({meaning})"

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        ok = math.isfinite(v) and (v > lo if lo_open else v >= lo) and (v < hi if hi_open else v <= hi)
        if not ok:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return v

    parse.__name__ = "number"
    return parse


positive = real(0.0, lo_open=True)
"""A finite number > 0 (periods, deadlines, seconds)."""


def algorithm(text: str) -> str:
    """An argparse type: an algorithm name in any spelling the library accepts
    (``EDC-CIF``, ``edc_cif``, ``edc-cif``), returned as ``edccif.ALGORITHMS``
    spells it (the library's one parser, ``_edccif.algorithm_name``)."""
    try:
        return _edccif.algorithm_name(text)
    except _edccif.UnknownAlgorithmError:
        raise argparse.ArgumentTypeError(
            f"unknown algorithm {text!r}, expected one of {', '.join(_edccif.algorithms())} (any case)"
        ) from None


algorithm.__name__ = "algorithm"


def trigger(text: str) -> str:
    """An argparse type: a trigger name in any spelling the library accepts,
    returned as ``edccif.TRIGGERS`` spells it."""
    try:
        return _edccif.trigger_name(text)
    except _edccif.UnknownOptionError:
        raise argparse.ArgumentTypeError(
            f"unknown trigger {text!r}, expected one of {', '.join(_edccif.triggers())} (any case)"
        ) from None


def delay(text: str) -> Tuple[int, int, float]:
    """``FROM:TO:SECONDS`` → (from, to, seconds): node indices >= 0, seconds a finite number >= 0."""
    parts = text.split(":")
    what = f"FROM:TO:SECONDS (two node indices and a delay in seconds >= 0), got {text!r}"
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected {what}")
    try:
        a, b, s = int(parts[0]), int(parts[1]), float(parts[2])
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}") from None
    if a < 0 or b < 0 or not (math.isfinite(s) and s >= 0):
        raise argparse.ArgumentTypeError(f"expected {what}")
    return a, b, s


_KILL = re.compile(r"^(\d+)@(\d+)(?:\+(.+))?$")


def kill(text: str) -> Tuple[int, int, float]:
    """``NODE@STEP[+DOWN_S]`` → (node, step, down seconds; default 1)."""
    m = _KILL.match(text.strip())
    what = f"NODE@STEP[+DOWN_S] (e.g. 1@30+0.5), got {text!r}"
    if not m:
        raise argparse.ArgumentTypeError(f"expected {what}")
    try:
        down = float(m.group(3)) if m.group(3) is not None else 1.0
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}") from None
    if not (math.isfinite(down) and down >= 0):
        raise argparse.ArgumentTypeError(f"expected {what} with DOWN_S >= 0")
    return int(m.group(1)), int(m.group(2)), down


_ADDRESS = re.compile(r"^(?:(tcp|tls|ws|wss|ucx)://)?\[?[A-Za-z0-9_.:-]+\]?:(\d{1,5})$")


def scheduler_address(text: str) -> str:
    """A Dask scheduler address, ``[tcp|tls|ws|wss|ucx://]HOST:PORT`` (port 1..=65535)."""
    m = _ADDRESS.match(text.strip())
    if not m or not 1 <= int(m.group(2)) <= 65535:
        raise argparse.ArgumentTypeError(
            f"expected a scheduler address [tcp://]HOST:PORT (e.g. tcp://10.0.0.5:8786), got {text!r}")
    return text.strip()


# ----------------------------------------------------------------------------- output paths


def output_path(text: str) -> Path:
    """An argparse type for an output file: not a directory, in a directory that
    exists. Whether it may be replaced is decided with ``--force`` by
    :func:`check_output_file`."""
    if not text:
        raise argparse.ArgumentTypeError("expected a file name, got ''")
    p = Path(text)
    if p.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory; expected a file name")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: the directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise argparse.ArgumentTypeError(f"{text}: the directory {parent} is not writable")
    return p


def output_dir(text: str) -> Path:
    """An argparse type for an output directory: a directory or a new name in a
    directory that exists."""
    if not text:
        raise argparse.ArgumentTypeError("expected a directory name, got ''")
    p = Path(text)
    if p.exists() and not p.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a file; expected a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not p.exists() and not parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: the directory {parent} does not exist")
    return p


def check_output_file(path: Optional[Path], force: bool, what: str) -> None:
    """Refuses (``ParameterError``) to replace an existing file without ``force``."""
    if path is not None and path.exists() and not force:
        raise _edccif.ParameterError(
            f"{what}: {path} already exists; choose another name or pass --force to replace it")


def check_output_files(paths: Sequence[Tuple[Optional[Path], str]], force: bool) -> None:
    """:func:`check_output_file` on each ``(path, what)``; also refuses one file
    named for two outputs."""
    seen = {}
    for p, what in paths:
        if p is None:
            continue
        key = os.path.abspath(p)
        if key in seen:
            raise _edccif.ParameterError(f"{what}: {p} is also the {seen[key]}; expected distinct files")
        seen[key] = what
        check_output_file(p, force, what)


# ----------------------------------------------------------------------------- progress


class Progress:
    """Progress lines on stderr for long commands, terminal or not: one line at most
    every ``every_s`` seconds when the count moved (and the last one), e.g.
    ``sweep: 3/12 cells (25 %), 41 s elapsed, about 2 min left``."""

    def __init__(self, what: str, total: int, unit: str, *, enabled: bool = True, every_s: float = 5.0,
                 done: int = 0) -> None:
        self.what, self.total, self.unit, self.enabled, self.every_s = what, total, unit, enabled, every_s
        self.done = self.start_done = done
        self.t0 = time.monotonic()
        self.last = self.t0
        self.printed: Optional[int] = None

    def line(self) -> str:
        elapsed = time.monotonic() - self.t0
        s = f"{self.what}: {self.done}/{self.total} {self.unit}"
        if self.total > 0:
            s += f" ({100.0 * self.done / self.total:.0f} %)"
        s += f", {_duration(elapsed)} elapsed"
        new = self.done - self.start_done
        if 0 < new and self.done < self.total:
            s += f", about {_duration(elapsed / new * (self.total - self.done))} left"
        return s

    def update(self, done: int, *, force: bool = False) -> None:
        """Sets the count done; prints a line when ``every_s`` passed since the last
        one (or with ``force``)."""
        self.done = done
        now = time.monotonic()
        if self.enabled and (force or (now - self.last >= self.every_s and done != self.printed)):
            self.last, self.printed = now, done
            print(self.line(), file=sys.stderr, flush=True)

    def finish(self) -> None:
        """The last line (unless it was just printed)."""
        if self.printed != self.done:
            self.update(self.done, force=True)


def _duration(s: float) -> str:
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


def readable_file(text: str) -> Path:
    """An argparse type: a file that exists and can be read."""
    path = Path(text)
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text!r} is not a file")
    try:
        with path.open("rb"):
            pass
    except OSError as e:
        raise argparse.ArgumentTypeError(f"cannot read {text!r}: {e.strerror}") from None
    return path


def stream_offset(text: str) -> Tuple[str, float]:
    """`--offset STREAM=SECONDS`: an observer (its index or file stem) and a
    finite number of seconds."""
    stream, sep, secs = text.rpartition("=")
    try:
        v = float(secs)
    except ValueError:
        v = float("nan")
    if not sep or not stream or not math.isfinite(v):
        raise argparse.ArgumentTypeError(
            f"expected STREAM=SECONDS (an observer's index or file stem, and its clock offset in s), got {text!r}"
        )
    return (stream, v)
