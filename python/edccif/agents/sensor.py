"""A sensor as its own process (``edccif sensor``): its measurements, through its event trigger, published."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any, Dict

import numpy as np

from .. import _edccif
from .common import AgentError
from .inbox import _Sender
from .startup import _ready_wait, _sleep_until_ns, _wait_start
from .swarm_file import load_swarm, swarm_key
from .transport import _port, _zenoh, tcp_bytes, zenoh_config


def node_columns(sc: _edccif.Scenario, z: np.ndarray, node: int) -> np.ndarray:
    """Node ``node``'s measurements (T, m_i) of ``z`` as ``Scenario.simulate``
    gives it: (T, N, m) when the nodes share ``m``, else (T, Σ m_i) in node order."""
    z = np.asarray(z)
    if z.ndim == 3:
        return z[:, node]
    dims = sc.meas_dims
    start = sum(dims[:node])
    return z[:, start:start + dims[node]]


def sensor_measurements(spec: Dict[str, Any], sc: _edccif.Scenario, node: int) -> np.ndarray:
    """Sensor ``node``'s measurements (T, 3): simulated from the scenario and seed,
    or replayed from the swarm's ``source`` (an MCAP file's ``/node{i}/measurement``,
    or TUM files — one per node, positions as the measurement of a position sensor).
    Rows of NaN: no measurement."""
    src = spec["source"]
    if src["kind"] == "simulate":
        return node_columns(sc, sc.simulate(seed=int(spec["seed"]))[1], node)
    if src["kind"] == "mcap":
        _, z, _ = _edccif.read_mcap_measurements(src["path"])
        # (T, N, 3), or (T, Σ m_i) for nodes of different sizes
        if z.ndim == 2 and z.shape[1] != sum(sc.meas_dims):
            raise AgentError(f"source {src['path']}: the recording holds {z.shape[1]} values per step, the "
                             f"scenario's nodes measure {sc.meas_dims} (record the swarm's own scenario)")
        if node >= (z.shape[1] if z.ndim == 3 else sc.nodes):
            raise AgentError(f"source {src['path']}: no measurements of node {node}")
        return np.asarray(node_columns(sc, z, node))
    paths = src.get("paths", [])
    if node >= len(paths):
        raise AgentError(f"source.paths: expected a TUM file for node {node}, got {len(paths)} files")
    _, p, _ = _edccif.read_tum(paths[node])
    return np.asarray(p)


def run_sensor(path: os.PathLike[str] | str, node: int) -> Dict[str, Any]:
    """Runs sensor ``node`` of the swarm file ``path``: at each step's start, its
    measurement through its event trigger; only triggered measurements are
    published. Writes ``sensor{node}.json`` and returns the summary."""
    spec, sc = load_swarm(path)
    k, swarm = sc.nodes, int(spec["swarm"])
    if not 0 <= node < k:
        raise AgentError(f"node: expected an index in 0..{k}, got {node}")
    z = sensor_measurements(spec, sc, node)
    steps = min(sc.steps, z.shape[0])
    trigger = _edccif.SensorTrigger(sc, spec["algorithm"], node=node, **spec["options"])
    period = float(spec["period_s"])
    agents = spec["agents"]
    faults = spec["faults"]
    zenoh = _zenoh()
    session = zenoh.open(zenoh_config([], [agents[node]["sensor_listen"]],
                                      agents[node].get("sensor_zenoh_config", spec["zenoh_config"])))
    try:
        seed = int(faults.get("loss_seed", 0)) * 100_003 + 2 * node + 1
        tx = _Sender(session, swarm, node, ["measurement"], float(faults.get("loss", 0.0)), seed,
                     tag_key=swarm_key(spec))
        _ready_wait(tx.matched, float(spec["ready_timeout_s"]))
        start_ns = _wait_start(spec, "sensor", node)
        for t in range(steps):
            t_ns = start_ns + int(round(t * period * 1e9))
            _sleep_until_ns(t_ns)
            if trigger.decide(z[t]):
                tx.send("measurement", z[t], None, t, 0, t_ns)
        time.sleep(0.05)
        wire = tcp_bytes([_port(a["sensor_listen"]) for a in agents], [_port(a["listen"]) for a in agents])
        time.sleep(float(spec["linger_s"]))
    finally:
        session.close()
    summary = {"role": "sensor", "node": node, "steps": steps, "measured": trigger.measured,
               "triggered": trigger.sent, "sent": tx.counts, "wire": wire}
    (Path(spec["run_dir"]) / f"sensor{node}.json").write_text(json.dumps(summary, indent=1))
    return summary
