"""The swarm file: what every agent and sensor process of a swarm shares (written, read, checked)."""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path
from typing import Any, Dict, Optional, Sequence, Tuple

import numpy as np

from .. import _edccif
from .common import AgentError
from .transport import free_ports

DEFAULTS: Dict[str, Any] = {
    "swarm": 1,
    "algorithm": "edc-cif",
    "options": {},
    "seed": 0,
    "period_s": 0.05,
    "sensor_wait_s": 0.025,
    "deadline_s": 1.0,
    "start_margin_s": 0.5,
    "ready_timeout_s": 60.0,
    "linger_s": 0.3,
    "faults": {},
    "source": {"kind": "simulate"},
    "zenoh_config": None,
    "start_ns": None,
    "key": None,
    "step_window": 8,
}
"""Swarm-file defaults (every key may be overridden in the file). ``key``: the
packets' authentication key, hex (at least 16 bytes; :func:`write_swarm` draws 32
random bytes when none is given); ``step_window``: how many steps before or
after its own an agent accepts a packet for."""


def write_swarm(
    path: os.PathLike[str] | str,
    scenario: _edccif.Scenario,
    *,
    algorithm: str = "edc-cif",
    seed: int = 0,
    x0: Optional[Sequence[float]] = None,
    host: str = "127.0.0.1",
    ports: Optional[Sequence[int]] = None,
    run_dir: os.PathLike[str] | str | None = None,
    **settings: Any,
) -> Dict[str, Any]:
    """Writes a swarm file and returns its content.

    ``ports``: 2 per node (estimator links ``ports[2i]``, sensor link
    ``ports[2i+1]``; default: free loopback ports). ``settings`` override
    :data:`DEFAULTS` (``options``, ``period_s``, ``sensor_wait_s``, ``deadline_s``,
    ``faults`` {``loss``, ``loss_seed``, ``delay``: [[from, to, seconds], ...]},
    ``source`` {``kind``: "simulate" | "mcap" | "tum", ``path``/``paths``}, ...).
    """
    k = scenario.nodes
    ports = list(ports) if ports is not None else free_ports(2 * k)
    if len(ports) != 2 * k:
        raise AgentError(f"ports: expected {2 * k} ports (2 per node), got {len(ports)}")
    unknown = set(settings) - set(DEFAULTS)
    if unknown:
        raise _edccif.UnknownOptionError(
            f"unknown swarm setting(s) {sorted(unknown)}; expected some of {sorted(DEFAULTS)}"
        )
    if x0 is None:
        x0 = scenario.simulate(seed=seed)[2] if settings.get("source", DEFAULTS["source"])["kind"] == "simulate" \
            else scenario.x0
    path = Path(path)
    spec: Dict[str, Any] = dict(DEFAULTS)
    spec.update(settings)
    if spec["key"] is None:
        spec["key"] = secrets.token_hex(32)
    spec.update(
        {
            "algorithm": algorithm,
            "seed": seed,
            "scenario": _portable_scenario(scenario),
            "x0": [float(v) for v in np.asarray(x0, dtype=float)],
            "agents": [
                {
                    "node": i,
                    "listen": f"tcp/{host}:{ports[2 * i]}",
                    "sensor_listen": f"tcp/{host}:{ports[2 * i + 1]}",
                }
                for i in range(k)
            ],
            "run_dir": str(Path(run_dir) if run_dir is not None else path.parent / f"{path.stem}-run"),
        }
    )
    load_swarm_dict(spec)  # validate
    path.parent.mkdir(parents=True, exist_ok=True)
    # the file holds the swarm's key: readable by its owner only
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(json.dumps(spec, indent=1))
    return spec


def _portable_scenario(sc: _edccif.Scenario) -> Dict[str, Any]:
    """The scenario's dict for a swarm file, its ``python_path`` (the
    directories of its referenced Python models, relative to the scenario
    file) made absolute, so that every agent and sensor process imports the
    same modules wherever the swarm file is."""
    d = sc.to_dict()
    if d.get("python_path"):
        base = Path(sc.base_dir or os.getcwd())
        d["python_path"] = [str((base / p).resolve()) for p in d["python_path"]]
    return d


def swarm_key(spec: Dict[str, Any]) -> bytes:
    """The packets' authentication key of a (validated) swarm dict."""
    return bytes.fromhex(spec["key"])


def load_swarm_dict(spec: Dict[str, Any], base_dir: Optional[os.PathLike[str] | str] = None
                    ) -> Tuple[Dict[str, Any], _edccif.Scenario]:
    """Validates a swarm dict; returns it with defaults filled in, and its scenario.
    ``base_dir``: where a relative ``python_path`` of the scenario (the
    directories of its Python models named by reference) starts; default the
    working directory (:func:`load_swarm` passes the swarm file's directory)."""
    out = dict(DEFAULTS)
    out.update(spec)
    for name in ("scenario", "agents", "x0", "run_dir"):
        if name not in out:
            raise AgentError(f"swarm file: missing {name!r}")
    sc = _edccif.Scenario.from_dict(out["scenario"], base_dir=base_dir)
    if len(out["agents"]) != sc.nodes:
        raise AgentError(f"swarm file: expected {sc.nodes} agents (one per node), got {len(out['agents'])}")
    if not 0 <= int(out["swarm"]) <= 0xFFFFFFFF:
        raise AgentError(f"swarm: expected an id in 0..=4294967295, got {out['swarm']}")
    for name in ("period_s", "sensor_wait_s", "deadline_s"):
        v = float(out[name])
        if not (np.isfinite(v) and v > 0):
            raise _edccif.ParameterError(f"{name}: expected a finite number > 0, got {out[name]}")
    loss = float(out["faults"].get("loss", 0.0))
    if not 0.0 <= loss < 1.0:
        raise _edccif.ParameterError(f"faults.loss: expected a probability in [0, 1), got {loss}")
    for d in out["faults"].get("delay", []):
        if len(d) != 3 or not (0 <= int(d[0]) < sc.nodes and 0 <= int(d[1]) < sc.nodes) or float(d[2]) < 0:
            raise _edccif.ParameterError(f"faults.delay: expected [from, to, seconds >= 0] entries, got {d}")
    k = out.get("key")
    try:
        ok = isinstance(k, str) and len(bytes.fromhex(k)) >= 16
    except ValueError:
        ok = False
    if not ok:
        raise AgentError("swarm file: 'key' must be the packets' authentication key as hex, at least 16 bytes "
                         "(32 hex digits); write_swarm draws one")
    w = out["step_window"]
    if isinstance(w, bool) or not isinstance(w, int) or w < 1:
        raise _edccif.ParameterError(f"step_window: expected an integer >= 1, got {w!r}")
    if out["source"].get("kind") not in ("simulate", "mcap", "tum"):
        raise _edccif.ParameterError(
            f"source.kind: expected 'simulate', 'mcap' or 'tum', got {out['source'].get('kind')!r}"
        )
    return out, sc


def load_swarm(path: os.PathLike[str] | str) -> Tuple[Dict[str, Any], _edccif.Scenario]:
    """Reads and validates a swarm file (see :func:`write_swarm`)."""
    try:
        spec = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise AgentError(f"swarm file {path}: {e}") from e
    return load_swarm_dict(spec, base_dir=Path(path).resolve().parent)
