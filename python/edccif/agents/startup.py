"""The swarm's clock: a process marks itself ready, waits for the common start and sleeps to each step."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Dict

from .common import AgentError


def _wait_start(spec: Dict[str, Any], role: str, node: int) -> int:
    """Marks this process ready and returns the start time (ns since the epoch):
    the swarm file's ``start_ns``, or the run directory's ``start.json``."""
    run = Path(spec["run_dir"])
    (run / "ready").mkdir(parents=True, exist_ok=True)
    (run / "ready" / f"{role}{node}").write_text(str(os.getpid()))
    if spec.get("start_ns") is not None:
        return int(spec["start_ns"])
    until = time.monotonic() + float(spec["ready_timeout_s"])
    start = run / "start.json"
    while time.monotonic() < until:
        if start.exists():
            try:
                return int(json.loads(start.read_text())["start_ns"])
            except (ValueError, KeyError):
                pass
        time.sleep(0.005)
    raise AgentError(f"{role} {node}: no start.json in {run} after {spec['ready_timeout_s']} s")


def _sleep_until_ns(t_ns: int) -> None:
    d = (t_ns - time.time_ns()) / 1e9
    if d > 0:
        time.sleep(d)


def _ready_wait(cond: Any, timeout: float) -> None:
    until = time.monotonic() + timeout
    while not cond() and time.monotonic() < until:
        time.sleep(0.01)
